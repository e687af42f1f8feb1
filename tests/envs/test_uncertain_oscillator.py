"""UncertainOscillator-v0: paper 000 simulation 2 facts and both readings of eq (29)."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym  # noqa: F401


def paper_step(x, delta, reading, u=0.0, dt=0.01):
    """Eq (29) written out by hand, noise-free."""
    rate = np.array([x[1], -25 * x[0] - 10 * x[1] * x[2] + 12 + u, 0.0])
    D = np.array([1 + delta, 1 + delta, 1.0])
    return D * x + rate * dt if reading == "state" else x + D * rate * dt


@pytest.mark.parametrize("reading", ["state", "rate"])
def test_noise_free_plant_follows_eq_29(reading):
    env = gym.make("fir_gym/UncertainOscillator-v0", Q=0.0, uncertainty=reading,
                   delta_schedule=((3, 6, 0.15), (5, 8, 0.05))).unwrapped
    _, info = env.reset(seed=0)
    x = info["state"]
    for k in range(12):
        a = 0.1 * (k % 3 - 1)
        _, _, _, _, info = env.step(np.array([a]))
        delta = 0.15 * (3 <= k <= 6) + 0.05 * (5 <= k <= 8)
        assert info["delta"] == pytest.approx(delta)
        x = paper_step(x, delta, reading, u=a * 25.0)
        np.testing.assert_allclose(info["state"], x, rtol=1e-14, atol=1e-14)


def test_noise_free_without_uncertainty_settles_at_0_48():
    env = gym.make("fir_gym/UncertainOscillator-v0", Q=0.0, delta_schedule=()).unwrapped
    env.reset(seed=0)
    for _ in range(1000):
        _, _, _, _, info = env.step(np.zeros(1))
    np.testing.assert_allclose(info["state"], [0.48, 0.0, 0.5], atol=1e-9)


def test_printed_reading_grows_about_12_6_percent_per_step():
    """Under the printed reading the truth grows ~12.6 %/step while δ = 0.15
    (docs/papers.md#000-eq-29-readings).

    The homogeneous map is ``1.15 I + Δ [[0, 1], [-25, -5]]`` with eigenvalues
    ``1.125 ± 0.0433i``, modulus 1.1258. The norm of a rotating, non-normal state
    oscillates within a period (2π/0.0385 ≈ 163 steps), so the rate is fitted
    over two whole periods of a long uncertainty window.
    """
    env = gym.make("fir_gym/UncertainOscillator-v0", Q=0.0, delta_schedule=((0, 400, 0.15),),
                   state_bound=1e300).unwrapped
    env.reset(seed=0)
    log_norms = [np.log(np.linalg.norm(env.step(np.zeros(1))[4]["state"][:2]))
                 for _ in range(400)]
    k = np.arange(400)
    window = slice(60, 60 + 326)
    slope = np.polyfit(k[window], np.array(log_norms)[window], 1)[0]
    assert np.exp(slope) == pytest.approx(np.hypot(1.125, 0.25 * np.sqrt(3) / 10), abs=2e-3)
    assert np.exp(slope) == pytest.approx(1.126, abs=2e-3)


def test_papers_window_reaches_the_reported_size_inside_the_domain():
    env = gym.make("fir_gym/UncertainOscillator-v0", Q=0.0).unwrapped
    env.reset(seed=0)
    for _ in range(401):
        _, _, terminated, _, info = env.step(np.zeros(1))
        assert not terminated
    assert 50 < abs(info["state"][0]) < 500 and 1e3 < abs(info["state"][1]) < 1e4


def test_rate_reading_is_milder():
    peaks = {}
    for reading in ("state", "rate"):
        env = gym.make("fir_gym/UncertainOscillator-v0", Q=0.0, uncertainty=reading).unwrapped
        env.reset(seed=0)
        peaks[reading] = max(abs(env.step(np.zeros(1))[4]["state"][0]) for _ in range(500))
    assert peaks["rate"] < 2.0 < 50.0 < peaks["state"]


def test_model_is_the_nominal_system_with_the_papers_noise():
    env = gym.make("fir_gym/UncertainOscillator-v0").unwrapped
    m = env.model
    np.testing.assert_array_equal(m.G, [[0.0], [0.01], [0.0]])
    assert m.Q[0, 0] == 0.4 and m.R[0, 0] == 0.1
    x = np.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(m.f(x, [0.2]), paper_step(x, 0.0, "state", u=5.0), atol=1e-15)


def test_process_noise_is_G_w_with_variance_Q():
    env = gym.make("fir_gym/UncertainOscillator-v0", delta_schedule=()).unwrapped
    _, info = env.reset(seed=2)
    w = []
    for _ in range(3000):
        x = info["state"]
        _, _, _, _, info = env.step(np.zeros(1))
        w.append(info["state"] - env.model.f(x, [0.0]))
    w = np.array(w)
    assert np.max(np.abs(w[:, [0, 2]])) < 1e-12                # noise only on x2
    n = len(w)
    assert np.var(w[:, 1]) == pytest.approx(0.4 * 0.01**2, rel=5 * np.sqrt(2 / n))


@pytest.mark.parametrize("kwargs", [{"uncertainty": "both"}, {"delta_schedule": ((5, 2, 0.1),)},
                                    {"delta_schedule": ((0, 2, -1.5),)}, {"Q": -0.4},
                                    {"R": 0.0}, {"dt": 0.0}])
def test_invalid_parameters_raise(kwargs):
    with pytest.raises(ValueError, match="|".join(kwargs)):
        gym.make("fir_gym/UncertainOscillator-v0", **kwargs)


@pytest.mark.parametrize("uncertainty", ["state", "rate"])
@pytest.mark.parametrize("delta", [0.0, 0.3, -0.2])
def test_the_jacobian_is_the_complex_step_derivative_of_the_step(uncertainty, delta):
    """``jacobian(x, u, δ)`` against the complex-step derivative of ``step(x, u, δ)`` (exact
    to round-off: the step is analytic in x), for both readings and a nonzero δ — the
    plant's Jacobian tests take δ = 0 and the default reading (mutation testing found the
    rest untested)."""
    from fir_gym.envs.uncertain_oscillator import OscillatorDynamics
    dyn = OscillatorDynamics(dt=0.05, stiffness=2.0, damping_gain=0.7, drive=0.4, u_max=1.5,
                             uncertainty=uncertainty)
    x, u = np.array([0.3, -0.8, 1.2]), np.array([0.25])
    h = 1e-30
    want = np.empty((3, 3))
    for j in range(3):
        xc = x.astype(complex)
        xc[j] += 1j * h
        want[:, j] = dyn.step(xc, u.astype(complex), delta).imag / h
    np.testing.assert_allclose(dyn.jacobian(x, u, delta), want, rtol=1e-13, atol=1e-15)
