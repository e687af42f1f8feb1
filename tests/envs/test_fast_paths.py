"""Fast paths of the plants equal their general formulation."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import fir_gym  # noqa: F401
from fir_gym.envs._mujoco_rk4 import StageRK4
from fir_gym.estimators import compiled


def test_paper_friction_law_equals_mujoco_with_the_reference_force_applied():
    """The law's closed-form 2-DOF mass matrix turns MuJoCo's accelerations without the
    force into the accelerations MuJoCo computes with the force (from MuJoCo's own
    ``mj_rne`` + ``mj_solveM``) applied, at random states, inputs and applied forces."""
    env = gym.make("fir_gym/PendulumSlider-v0", friction="paper").unwrapped
    env.reset(seed=0)
    m, d, friction = env.mj_model, env.mj_data, env._friction_law
    rng = np.random.default_rng(0)
    for _ in range(200):
        d.qpos[:] = rng.uniform([-0.3, -np.pi], [0.3, np.pi])
        d.qvel[:] = rng.normal(scale=[1.0, 6.0])
        d.ctrl[0] = rng.uniform(-10, 10)
        applied = rng.normal(size=2)
        d.qfrc_applied[:] = applied
        mujoco.mj_forward(m, d)                           # accelerations without the force
        (x, th), (v, w) = d.qpos.tolist(), d.qvel.tolist()
        without = d.qacc.copy()
        law = friction.law(x, th, v, w, *without.tolist())
        force = friction.reference_force(m, d)
        d.qfrc_applied[friction.x_dof] += force
        mujoco.mj_forward(m, d)                           # MuJoCo with the force applied
        scale = max(1.0, float(np.max(np.abs(d.qacc))))
        np.testing.assert_allclose(law, d.qacc, rtol=0, atol=1e-12 * scale)
        assert np.max(np.abs(d.qacc - without)) > 1e-2    # the force is not negligible


def test_stage_rk4_with_a_law_that_adds_nothing_is_mj_step_bit_for_bit():
    """``StageRK4`` is MuJoCo's own RK4 step (stages, tableau, order of operations,
    checks): with an identity law it gives ``mj_step``'s numbers exactly, so the force
    law is the only thing it changes."""
    runs = []
    for ours in (True, False):
        env = gym.make("fir_gym/PendulumSlider-v0", friction="none").unwrapped
        env.reset(seed=0, options={"state": [0.02, 0.1, 0.7, -1.0]})
        m, d = env.mj_model, env.mj_data
        rk4 = StageRK4(m, d, lambda x, th, v, w, ax, aw: (ax, aw))
        trajectory = []
        for k in range(300):
            d.ctrl[0] = 3.0 * np.sin(0.01 * k)
            d.qfrc_applied[1] = 0.1 * np.cos(0.02 * k)
            if ours:
                rk4.step(2)
            else:
                mujoco.mj_step(m, d, 2)
            trajectory.append(np.concatenate([d.qpos, d.qvel, [d.time]]))
        runs.append(np.array(trajectory))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert mujoco.get_mjcb_passive() is None


def test_stage_rk4_refuses_models_it_does_not_reproduce():
    coulomb = gym.make("fir_gym/PendulumSlider-v0", friction="coulomb").unwrapped
    with pytest.raises(ValueError, match="nq = nv = 2"):
        StageRK4(coulomb.mj_model, coulomb.mj_data, lambda *z: z[4:])
    euler = mujoco.MjModel.from_xml_string(
        '<mujoco><option integrator="Euler"/><worldbody><body><joint type="slide"/>'
        '<joint type="hinge" axis="0 1 0"/><geom size="0.1"/></body></worldbody></mujoco>')
    with pytest.raises(ValueError, match="RK4"):
        StageRK4(euler, mujoco.MjData(euler), lambda *z: z[4:])


@pytest.mark.parametrize("value", [0.3, -0.7, 1.0, -1.0, 1.5, -3.0, 0.0, -0.0, 1e30])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_float_action_path_equals_the_general_check(value, dtype):
    env = gym.make("fir_gym/VanDerPol-v0").unwrapped
    fast = env._check_action(np.array([value], dtype=dtype))
    general = _general_check(env, value, dtype)
    assert fast[0].dtype == np.float64 and fast[0].shape == (1,)
    np.testing.assert_array_equal(fast[0], general[0])
    assert fast[1] == general[1]


def _general_check(env, value, dtype):
    """The general branch of ``_check_action`` (a list input takes it)."""
    a = np.asarray(np.array([value], dtype=dtype), dtype=np.float64)
    return env._check_action(a.tolist())


def test_float_action_path_rejects_nan():
    env = gym.make("fir_gym/VanDerPol-v0").unwrapped
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError, match="action must be finite"):
            env._check_action(np.array([bad], dtype=np.float32))


@pytest.mark.parametrize("jacobian", [False, True])
@pytest.mark.parametrize("noisy", [False, True])
def test_van_der_pol_small_batches_row_by_row_equal_the_batched_loop(monkeypatch, jacobian,
                                                                      noisy):
    """Batches of up to SMALL_BATCH rows run the float loop row by row: bit for bit the
    numpy loop over the whole batch (both without the compiled loop)."""
    from fir_gym.envs import van_der_pol
    monkeypatch.setattr(compiled, "ENABLED", False)
    dyn = van_der_pol.VanDerPolDynamics(1.0, 0.1, 100, 5.0)
    rng = np.random.default_rng(1)
    B = 5
    x, u = 2.0 * rng.normal(size=(B, 2)), rng.uniform(-1, 1, size=(B, 1))
    dW = 0.05 * rng.normal(size=(100, B)) if noisy else None
    rows = dyn.integrate(x, u, dW, jacobian)
    monkeypatch.setattr(van_der_pol, "SMALL_BATCH", 0)
    batched = dyn.integrate(x, u, dW, jacobian)
    for a, b in zip(rows, batched, strict=True):
        if a is not None:
            assert a.shape == b.shape and a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("jacobian", [False, True])
def test_orbit_small_batches_row_by_row_equal_the_batched_loop(monkeypatch, jacobian):
    from fir_gym.envs import orbit
    monkeypatch.setattr(compiled, "ENABLED", False)
    dyn = gym.make("fir_gym/Orbit-v0").unwrapped.model
    rng = np.random.default_rng(2)
    x = np.array([8.0, 2.0]) + 0.1 * rng.normal(size=(5, 2))
    u = rng.uniform(-1, 1, size=(5, 1))
    fn = dyn.F if jacobian else dyn.f
    rows = fn(x, u)
    monkeypatch.setattr(orbit, "SMALL_BATCH", 0)
    np.testing.assert_array_equal(rows, fn(x, u))


def test_pendulum_model_fused_linearize_equals_f_and_F():
    """The model's fused ``linearize`` (one RK4 pass with Jacobians) is ``f`` and ``F``."""
    model = gym.make("fir_gym/PendulumSlider-v0").unwrapped.model
    rng = np.random.default_rng(3)
    for x, u in ((rng.normal(size=4), rng.normal(size=1)),
                 (rng.normal(size=(6, 4)), rng.normal(size=(6, 1)))):
        fx, Fx = model.linearize(x, u)
        np.testing.assert_array_equal(fx, model.f(x, u))
        np.testing.assert_array_equal(Fx, model.F(x, u))
    clone = model.with_params(mu=0.3)
    x, u = rng.normal(size=4), rng.normal(size=1)
    np.testing.assert_array_equal(clone.linearize(x, u)[0], clone.f(x, u))


def test_pendulum_reward_in_floats_equals_the_numpy_scalar_formula():
    env = gym.make("fir_gym/PendulumSlider-v0").unwrapped
    rng = np.random.default_rng(4)
    for _ in range(500):
        x, a = rng.normal(scale=[0.1, 1.0, 2.0, 5.0]), rng.uniform(-1, 1, size=1)
        e = x[0] - env.x_rest
        cost = x[2] * x[2] + 0.1 * x[3] * x[3] + 100.0 * e * e + 0.01 * a[0] * a[0]
        ref = -float(np.minimum(cost, env.BRACKET_CAP)) * (env.params["frame_skip"] * 0.1)
        assert env._reward(x, a, x) == ref


def test_diagonal_measurement_noise_path_equals_the_matrix_product():
    from fir_gym.envs._base import _diagonal_of
    rng = np.random.default_rng(5)
    sqrt = np.diag([0.003, 0.03, 0.03, 0.3])
    diag = _diagonal_of(sqrt)
    for shape in ((4,), (64, 4)):
        noise = rng.standard_normal(shape)
        np.testing.assert_array_equal(noise * diag, noise @ sqrt.T)
    assert _diagonal_of(np.array([[1.0, 0.1], [0.1, 1.0]])) is None


def on_both_paths(monkeypatch, fn, *args):
    """``fn(*args)`` with the compiled kernels on, then off (their numpy/Python paths)."""
    out = []
    for enabled in (True, False):
        monkeypatch.setattr(compiled, "ENABLED", enabled)
        out.append(fn(*args))
    return out


def outputs_match(compiled, reference, check):
    """``check`` each output pair of two tuples (``None`` only where both are)."""
    for a, b in zip(compiled, reference, strict=True):
        if b is None:
            assert a is None
            continue
        check(a, b)


@pytest.mark.parametrize("shape", [(2,), (1, 2), (5, 2), (40, 2), (300, 2)])
@pytest.mark.parametrize("jacobian", [False, True])
@pytest.mark.parametrize("noisy", [False, True])
def test_van_der_pol_compiled_loop_equals_the_python_loop(monkeypatch, shape, jacobian, noisy):
    """The compiled Heun loop does the Python loop's operations in the same order: same bits,
    shapes and types, for one system, small batches (float rows) and large (numpy loop)."""
    pytest.importorskip("numba")
    from fir_gym.envs import van_der_pol
    dyn = van_der_pol.VanDerPolDynamics(1.0, 0.1, 100, 5.0)
    rng = np.random.default_rng(3)
    x = 2.0 * rng.normal(size=shape)
    u = rng.uniform(-1, 1, size=shape[:-1] + (1,))
    dW = 0.05 * rng.normal(size=(100,) + shape[:-1]) if noisy else None
    def same_bits(a, b):
        assert type(a) is type(b) and np.shape(a) == np.shape(b)
        np.testing.assert_array_equal(a, b)
    outputs_match(*on_both_paths(monkeypatch, dyn.integrate, x, u, dW, jacobian), same_bits)


def test_van_der_pol_rollout_is_the_same_with_and_without_the_compiled_loop(monkeypatch):
    pytest.importorskip("numba")
    runs = []
    for enabled in (True, False):
        monkeypatch.setattr(compiled, "ENABLED", enabled)
        env = gym.make("fir_gym/VanDerPol-v0")
        obs, _ = env.reset(seed=4)
        trace = [obs]
        for k in range(30):
            trace.append(env.step(np.array([np.sin(0.3 * k)], dtype=np.float32))[0])
        runs.append(np.array(trace))
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.parametrize("shape", [(2,), (1, 2), (5, 2), (300, 2)])
@pytest.mark.parametrize("jacobian", [False, True])
def test_orbit_compiled_loop_equals_the_python_loop(monkeypatch, shape, jacobian):
    pytest.importorskip("numba")
    dyn = gym.make("fir_gym/Orbit-v0").unwrapped.model
    rng = np.random.default_rng(4)
    x = np.array([8.0, 2.0]) + 0.1 * rng.normal(size=shape)
    u = rng.uniform(-1, 1, size=shape[:-1] + (1,))
    fn = dyn.F if jacobian else dyn.f
    compiled, python = on_both_paths(monkeypatch, fn, x, u)
    assert compiled.shape == python.shape
    np.testing.assert_array_equal(compiled, python)


@pytest.mark.parametrize(("friction", "coulomb_velocity"),
                         [("paper", 0.01), ("coulomb", 0.01), ("coulomb", 0.0), ("none", 0.01)])
@pytest.mark.parametrize("shape", [(4,), (1, 4), (9, 4), (50, 4)])
@pytest.mark.parametrize("jacobian", [False, True])
def test_pendulum_slider_compiled_rk4_equals_the_numpy_rk4(monkeypatch, friction,
                                                           coulomb_velocity, shape, jacobian):
    """The compiled RK4 step (and its stage-wise Jacobians in x and [μ, M0]) against the
    numpy one, with shared and per-system parameters; equal to round-off (the 4 x 4
    sensitivity products sum in another order)."""
    pytest.importorskip("numba")
    from fir_gym.envs.pendulum_slider_dynamics import PendulumSliderDynamics
    dyn = PendulumSliderDynamics(friction=friction, coulomb_velocity=coulomb_velocity,
                                 substeps=2, input_scale=5.0)
    rng = np.random.default_rng(5)
    x = rng.normal(size=shape) * [0.05, 0.3, 1.0, 2.0]
    u = rng.normal(size=shape[:-1] + (1,))
    theta = dyn.theta if shape[0] % 2 else 0.3 * np.abs(rng.normal(size=shape[:-1] + (2,)))
    def round_off(a, b):
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13 * np.abs(b).max())
    outputs_match(*on_both_paths(monkeypatch, dyn.propagate, x, u, theta, jacobian), round_off)
