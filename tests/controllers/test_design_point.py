"""The design point is the plant's own, public record (docs/architecture.md#design-point).

Every registered plant publishes ``plant.design_point()``, and the controllers design on
exactly that record (bit for bit); a plant the package has never seen gets a clear error
naming it and the method to implement when it has none and an LQG is asked for, and the
LQG baseline as soon as it implements it.
"""

import re
from dataclasses import fields

import gymnasium as gym
import numpy as np
import pytest

import fir_gym
from fir_gym.controllers import LQGController, PIDController, design_point, lqr_design
from fir_gym.envs import DesignPoint
from fir_gym.envs._base import PlantEnv, saturated_cost
from fir_gym.estimators import LinearModel
from fir_gym.wrappers import wrap_observation


def assert_same_point(a: DesignPoint, b: DesignPoint) -> None:
    """Every field equal, the arrays bit for bit (values, dtypes and shapes)."""
    assert type(a) is DesignPoint and type(b) is DesignPoint
    for f in fields(DesignPoint):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, np.ndarray) or isinstance(vb, np.ndarray):
            va, vb = np.asarray(va), np.asarray(vb)
            assert va.dtype == vb.dtype and va.shape == vb.shape, f.name
            assert np.array_equal(va, vb), f.name
        else:
            assert va == vb, f.name


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
def test_every_plant_publishes_the_design_point_the_controllers_use(env_id):
    env = wrap_observation(gym.make(env_id), "true")
    plant = env.unwrapped
    own = plant.design_point()
    assert isinstance(own, DesignPoint)
    assert_same_point(plant.design_point(), own)            # a fresh, identical record
    assert_same_point(design_point(plant), own)             # the controllers' entry point
    n = len(plant.state_names) + len(plant.action_names)
    assert own.x.shape == (len(plant.state_names),) and own.u.shape == (len(plant.action_names),)
    assert own.M.shape == (n, n)

    lqg = LQGController(env)                                # on the true state: as published
    assert_same_point(lqg.point, own)
    reference = lqr_design(plant.model, own)
    for name in ("A", "B", "Q", "R", "N", "K", "P", "closed_loop_poles"):
        assert np.array_equal(getattr(lqg.design, name), getattr(reference, name)), name

    on_estimate = LQGController(gym.make(env_id, estimator="ekf"))
    if own.estimate_input_weight is None:
        assert_same_point(on_estimate.point, own)
    else:                                                   # only the input weight differs
        n_x = len(own.x)
        M = own.M.copy()
        M[n_x:, n_x:] = own.estimate_input_weight * np.eye(n - n_x)
        assert np.array_equal(on_estimate.point.M, M)
        assert np.array_equal(on_estimate.point.x, own.x)
        assert np.array_equal(on_estimate.point.u, own.u)

    if own.output is not None:
        pid = PIDController(gym.make(env_id))
        assert pid.gains == {k: float(own.pid.get(k, 0.0)) for k in ("kp", "ki", "kd")}
        assert pid.output == own.output and pid.setpoint == own.setpoint
        assert pid.feedforward == float(own.u[0])


class _UnseenCart(PlantEnv):
    """A plant the package has never seen: an unstable cart (``ẍ = x + a``), Euler-sampled,
    its position measured; the reward holds it at 0."""

    state_names = ("position", "velocity")
    measurement_names = ("position_measured",)
    action_names = ("force",)
    cost_cap = 100.0
    _A = np.array([[1.0, 0.1], [0.1, 1.0]])
    _B = np.array([[0.0], [0.1]])

    def __init__(self, render_mode=None):
        super().__init__(params={"dt": 0.1}, nominal=None, default_nominal=None,
                         initial_state=(0.5, 0.0), initial_state_cov=None,
                         measurement_cov=[[0.01]], render_mode=render_mode)

    def _transition(self, x, a, k, rng):
        return x @ self._A.T + a @ self._B.T, {}

    def _noise_free_measurement(self, x, extra):
        return x[..., :1].copy()

    def _reward(self, x, a, x_next):
        p, u = x_next[..., 0], a[..., 0]
        return -saturated_cost(p * p + 0.01 * u * u, self.cost_cap)

    def _build_model(self, params):
        return LinearModel(A=self._A, B=self._B, C=np.array([[1.0, 0.0]]),
                           Q=1e-6 * np.eye(2), R=[[0.01]], dt=params["dt"])


class _UnseenCartWithPoint(_UnseenCart):
    def design_point(self) -> DesignPoint:
        return DesignPoint(x=np.zeros(2), u=np.zeros(1), M=np.diag([1.0, 0.0, 0.01]),
                           states=(0, 1), output=0, setpoint=0.0,
                           pid={"kp": 5.0, "ki": 0.0, "kd": 1.0}, note="the cart at rest")


def test_an_unseen_plant_without_a_design_point_is_told_what_to_implement():
    plant = _UnseenCart()
    message = re.escape("_UnseenCart") + r".*implement _UnseenCart\.design_point\(self\)"
    with pytest.raises(NotImplementedError, match=message):
        plant.design_point()
    with pytest.raises(NotImplementedError, match=message):
        LQGController(wrap_observation(_UnseenCart(), "true"))
    with pytest.raises(NotImplementedError, match=message):
        LQGController(wrap_observation(_UnseenCart(), "kf"))
    with pytest.raises(NotImplementedError, match=message):
        PIDController(_UnseenCart())


def test_an_unseen_plant_with_a_design_point_gets_the_lqg_baseline():
    env = wrap_observation(_UnseenCartWithPoint(), "true")
    lqg = LQGController(env)
    assert_same_point(lqg.point, env.unwrapped.design_point())
    assert np.max(np.abs(np.linalg.eigvals(_UnseenCart._A))) > 1.0          # unstable
    assert np.max(np.abs(lqg.design.closed_loop_poles)) < 1.0               # stabilised
    x, _ = env.reset(seed=0)
    for _ in range(100):
        x, _, terminated, _, _ = env.step(lqg.predict(x)[0])
        assert not terminated
    assert np.max(np.abs(x)) < 1e-3


def test_a_non_plant_is_refused_by_the_controllers_entry_point():
    with pytest.raises(TypeError, match="not a fir-gym plant"):
        design_point(object())
