"""Estimators that do not fit the plant are refused by the wrappers (issue 18, item 6)."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym  # noqa: F401
from fir_gym.estimators import (
    ExtendedKalmanFilter,
    KalmanFilter,
    LinearModel,
    StateSpaceModel,
    UnscentedKalmanFilter,
    augment,
)
from fir_gym.wrappers import EstimatorObservation, VectorEstimatorObservation


def model_of(env_id):
    return gym.make(env_id).unwrapped.model


def test_an_estimator_built_for_another_plant_is_refused_naming_it_and_the_mismatch():
    """Issue 18: an EKF built for UncertainOscillator (n_x = 3) on Orbit (n_x = 2) used to
    fail at the first step with "operands could not be broadcast together"."""
    ekf = ExtendedKalmanFilter(model_of("fir_gym/UncertainOscillator-v0"))
    with pytest.raises(ValueError, match=r"estimator ExtendedKalmanFilter does not fit "
                                         r"fir_gym/Orbit-v0: .*n_x=3 where the plant has n_x=2"):
        EstimatorObservation(gym.make("fir_gym/Orbit-v0"), ekf)
    with pytest.raises(ValueError, match="n_x=3 where the plant has n_x=2"):
        gym.make("fir_gym/Orbit-v0", estimator=ekf)


def test_a_measurement_size_mismatch_is_refused():
    """Orbit measures one component; a model measuring both is refused (n_y)."""
    both = StateSpaceModel(f=lambda x, u: x, h=lambda x: x, Q=np.eye(2), R=np.eye(2), n_u=1)
    with pytest.raises(ValueError, match="n_y=2 where the plant has n_y=1"):
        EstimatorObservation(gym.make("fir_gym/Orbit-v0"), ExtendedKalmanFilter(both))


def test_an_input_size_mismatch_is_refused():
    """CarrierMotion's action is one input; a Kalman filter on a model without inputs
    would be fed one at every step (n_u)."""
    A = model_of("fir_gym/CarrierMotion-v0").A
    no_input = LinearModel(A=A, C=[[1.0, 0.0]], Q=np.eye(2), R=[[1.0]])
    with pytest.raises(ValueError, match="n_u=0 where the plant has n_u=1"):
        EstimatorObservation(gym.make("fir_gym/CarrierMotion-v0"), KalmanFilter(no_input))


def test_every_mismatch_is_listed():
    other = StateSpaceModel(f=lambda x, u: x, h=lambda x: x, Q=np.eye(3), R=np.eye(3))
    with pytest.raises(ValueError, match=r"n_x=3 .*; n_y=3 .*; n_u=0 where the plant has n_u=1"):
        EstimatorObservation(gym.make("fir_gym/Orbit-v0"), ExtendedKalmanFilter(other))


def test_a_batched_estimator_instance_is_refused():
    ekf = ExtendedKalmanFilter(model_of("fir_gym/Orbit-v0"), x0=np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"batch of 4 systems.*VectorEstimatorObservation"):
        EstimatorObservation(gym.make("fir_gym/Orbit-v0"), ekf)


def test_an_estimator_for_the_same_plant_is_accepted():
    env = gym.make("fir_gym/Orbit-v0")
    wrapped = EstimatorObservation(env, ExtendedKalmanFilter(env.unwrapped.model,
                                                             x0=[7.99, 1.99]))
    wrapped.reset(seed=0)
    obs, *_ = wrapped.step(np.zeros(1))
    assert obs.shape == (2,)


def test_an_augmented_estimator_fits_on_its_base_state():
    """Paper 003's joint estimation: a UKF on [x; μ, M0] fits the 4-state plant; the
    estimation error is that of the plant's state."""
    env = gym.make("fir_gym/PendulumSlider-v0")
    plant = env.unwrapped
    aug = augment(plant.model, ["mu", "M0"])
    ukf = UnscentedKalmanFilter(aug, x0=np.r_[plant.initial_state, 0.2, 0.2],
                                P0=np.diag([1e-4, 1e-4, 1e-2, 1e-4, 1e-2, 1e-2]))
    wrapped = EstimatorObservation(env, ukf)
    assert wrapped.observation_space.shape == (6,)
    wrapped.reset(seed=0)
    for _ in range(5):
        obs, _, _, _, info = wrapped.step(np.zeros(1))
    assert obs.shape == (6,) and info["estimation_error"].shape == (4,)
    np.testing.assert_allclose(info["estimation_error"], info["state"] - obs[:4])


def test_vector_wrapper_checks_the_estimator_it_builds():
    """A class is built from the plant's own model, so it fits; the check still runs on
    what it built (an option that swaps the model would be caught)."""
    venv = gym.make_vec("fir_gym/Orbit-v0", num_envs=2, vectorization_mode="vector_entry_point")
    wrapped = VectorEstimatorObservation(venv, "ekf")
    assert wrapped.estimator.model.n_x == 2

    class OtherModel(ExtendedKalmanFilter):
        def __init__(self, model, **options):
            super().__init__(model_of("fir_gym/UncertainOscillator-v0"))

    with pytest.raises(ValueError, match=r"does not fit.*n_x=3 where the plant has n_x=2"):
        VectorEstimatorObservation(venv, OtherModel)
