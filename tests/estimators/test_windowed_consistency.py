"""Issue 18, items 1 and 2: the windowed filters' consistency test and observability rule.

Oracles: the χ²(n_y) law of the one-step NIS on data drawn from the filter's own linear
model (mean n_y, variance 2 n_y: estimators/_consistency.py derives it), the issue's
reproducers (an EFIR whose estimate grows to 1e44 unflagged; a PendulumSlider EFIR with a
wrong prior), a brute-force NIS from the filter's own x̂, P and the textbook prediction,
and the compiled twin against the numpy reference step by step.
"""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import pytest
import scipy.stats
from compiled_paths import needs_twins, numpy_path, step_on

import fir_gym  # noqa: F401
from fir_gym.estimators import (
    ExtendedFIRFilter,
    FIRFilter,
    FIRSmoother,
    LinearModel,
    RecursiveFIRFilter,
    UFIRFilter,
    make_estimator,
)
from fir_gym.wrappers import EstimatorObservation

PATHS = ("twin", "numpy")


def estimator_of(env: gym.Env):
    w = env
    while not isinstance(w, EstimatorObservation):
        w = w.env                                              # type: ignore[attr-defined]
    return w.estimator


def run_env(env_id: str, name: str, steps: int, seed: int, path: str, actions: str = "random",
            env_kwargs: dict | None = None, **estimator_kwargs):
    """Roll ``env_id`` with ``name`` in the loop; return (first flagged step or None, NIS list)."""
    env = gym.make(env_id, estimator=name, estimator_kwargs=estimator_kwargs,
                   **(env_kwargs or {}))
    env.action_space.seed(seed)
    est = estimator_of(env)
    env.reset(seed=seed)
    first, nis = None, []
    ctx = numpy_path() if path == "numpy" else _nothing()
    with ctx:
        for k in range(steps):
            a = env.action_space.sample() if actions == "random" else np.zeros(
                env.action_space.shape)
            _, _, terminated, truncated, info = env.step(a)
            nis.append(est.last_info["nis"])
            if info["estimator_diverged"] and first is None:
                first = k
            if terminated or truncated:
                break
    return first, np.array(nis, float)


class _nothing:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *args: object) -> None:
        return None


# ---------------------------------------------------------------- the issue's reproducers
@pytest.mark.parametrize("path", PATHS)
def test_the_issue_efir_that_grew_to_1e44_is_flagged_within_a_few_steps(path: str) -> None:
    first, nis = run_env("fir_gym/UncertainOscillator-v0", "efir", 100, 1, path, "zero",
                         x0=[50.0, 50.0, 50.5], P0=1e-6 * np.eye(3))
    assert first is not None and first < 12, first             # patience 10
    assert np.all(nis[:first + 1] > scipy.stats.chi2.isf(1e-9, 1))


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("x0", [[0.0, 0.0, 3.0, 0.0], [1.0, 0.0, -2.0, 5.0]])
def test_pendulum_slider_with_a_wrong_prior_is_flagged(path: str, x0: list[float]) -> None:
    first, _ = run_env("fir_gym/PendulumSlider-v0", "efir", 60, 0, path, "zero", x0=x0,
                       P0=1e-6 * np.eye(4))
    assert first is not None and first < 20, first


# ---------------------------------------------------------------- no false alarm, χ² law
CONSISTENT = [("fir_gym/Orbit-v0", "efir", {}), ("fir_gym/UncertainOscillator-v0", "efir",
                                                  {"delta_schedule": ()}),
              ("fir_gym/CarrierMotion-v0", "efir", {}), ("fir_gym/CarrierMotion-v0", "fir", {}),
              ("fir_gym/CarrierMotion-v0", "ufir", {}), ("fir_gym/CarrierMotion-v0", "rfir", {}),
              ("fir_gym/VanDerPol-v0", "efir", {}), ("fir_gym/PendulumSlider-v0", "efir", {})]


@pytest.mark.parametrize(("env_id", "name", "env_kwargs"), CONSISTENT)
def test_no_flag_on_the_plants_own_data(env_id: str, name: str, env_kwargs: dict) -> None:
    """Every windowed filter on every plant it applies to (UncertainOscillator without the
    paper's δ burst, which the δ = 0 model does not describe: there every filter, the EKF
    too, is rightly flagged): no flag over episodes of random actions, and a finite NIS
    whose tail stays far below the threshold. The long-run version is
    tests/test_long_run.py (1e6 steps per filter × plant)."""
    total, seed = 0, 0
    while total < 1500:
        first, nis = run_env(env_id, name, 1500 - total, seed, "twin", env_kwargs=env_kwargs)
        assert first is None, (seed, first)
        assert np.all(np.isfinite(nis))
        total += len(nis)
        seed += 1


def linear_data(model: LinearModel, steps: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    m = model.matrices(0)
    x = rng.normal(size=model.n_x)
    ys = []
    for _ in range(steps):
        ys.append(m.C @ x + rng.multivariate_normal(np.zeros(model.n_y), m.R))
        x = m.A @ x + m.G @ rng.multivariate_normal(np.zeros(m.Q.shape[0]), m.Q)
    return np.array(ys)


def carrier_model() -> LinearModel:
    env = gym.make("fir_gym/CarrierMotion-v0")
    return env.unwrapped.model                                 # type: ignore[attr-defined]


@pytest.mark.parametrize("name", ["fir", "rfir"])
def test_the_nis_of_the_unbiased_fir_filter_is_chi_square(name: str) -> None:
    """On its own model's data the minimum-variance unbiased FIR filter's one-step NIS has
    the χ²(n_y) law: mean n_y, variance 2 n_y, and a KS test does not reject it."""
    model = carrier_model()
    f = make_estimator(name, model, horizon=20)
    ys = linear_data(model, 6000, 3)
    nis = []
    for k, y in enumerate(ys):
        f.step(y, None if k == 0 else np.zeros(model.n_u))
        if k >= 20:                                            # past start-up
            nis.append(f.last_info["nis"])
    nis_ = np.array(nis)
    p = model.n_y
    assert abs(nis_.mean() - p) < 0.1 * p
    assert abs(nis_.var() - 2 * p) < 0.3 * 2 * p
    # the NIS sequence is correlated (windows overlap): a KS test on every 20th value
    assert scipy.stats.kstest(nis_[::20], scipy.stats.chi2(p).cdf).pvalue > 1e-3
    assert not f.diverged


def test_the_nis_is_the_textbook_one_step_innovation() -> None:
    """Brute force: the NIS equals ``eᵀ S⁻¹ e`` from the previous x̂, P and the model."""
    model = carrier_model()
    m = model.matrices(0)
    f = FIRFilter(model, horizon=8)
    ys = linear_data(model, 30, 4)
    u = np.array([0.3])
    for k, y in enumerate(ys):
        x, P = f.x, f.P
        f.step(y, None if k == 0 else u)
        if k:
            xm = m.A @ x + m.B @ u
            Pm = m.A @ P @ m.A.T + m.G @ m.Q @ m.G.T
            e = y - m.C @ xm
            S = m.C @ Pm @ m.C.T + m.R
            assert f.last_info["nis"] == pytest.approx(e @ np.linalg.solve(S, e), rel=1e-9)


# ---------------------------------------------------------------- twin = numpy reference
def makers():
    model = carrier_model()
    return {"fir": lambda: FIRFilter(model, horizon=6, nan_policy="skip"),
            "ufir": lambda: UFIRFilter(model, horizon=6, nan_policy="skip"),
            "rfir": lambda: RecursiveFIRFilter(model, horizon=6),
            "efir": lambda: ExtendedFIRFilter(model, horizon=6, nan_policy="skip"),
            "efir-reanchor": lambda: ExtendedFIRFilter(model, horizon=6, nominal="reanchor"),
            "fir-smoother": lambda: FIRSmoother(model, horizon=6, nan_policy="skip")}


@needs_twins
@pytest.mark.parametrize("name", sorted(makers()))
def test_twin_and_numpy_give_the_same_nis_and_flags(name: str) -> None:
    """A batch of 3 with a skipped measurement, a restart and a divergence (a data jump):
    NIS to 1e-10, flags identical, on the twin and the numpy reference."""
    twin = makers()[name]()
    ref = copy.deepcopy(twin)
    rng = np.random.default_rng(5)
    skip = name not in ("rfir", "efir-reanchor")
    for k in range(60):
        y = 0.3 * rng.normal(size=(3, 1))
        if k == 20 and skip:
            y[1, 0] = np.nan
        if k >= 40:
            y[2, 0] += 50.0 * (-1) ** k                       # system 2 leaves its model
        u = None if k == 0 else rng.normal(size=(3, 1))
        if k == 30:
            twin.restart([0])
            ref.restart([0])
        step_on(twin, True, y, u)
        step_on(ref, False, y, u)
        nt, nr = twin.last_info["nis"], ref.last_info["nis"]
        np.testing.assert_array_equal(np.isnan(nt), np.isnan(nr))
        np.testing.assert_allclose(nt, nr, rtol=1e-10)
        np.testing.assert_array_equal(twin.diverged, ref.diverged)
    assert list(twin.diverged) == [False, False, True]


@pytest.mark.parametrize("path", PATHS)
def test_a_restarted_system_is_tested_against_its_prior(path: str) -> None:
    model = carrier_model()
    f = FIRFilter(model, horizon=6, x0=[0.0, 0.0], P0=np.eye(2))
    ys = linear_data(model, 20, 6)
    Y = np.stack([ys, ys], axis=1)
    for k in range(10):
        step_on(f, path == "twin", Y[k], None if k == 0 else np.zeros((2, 1)))
    f.restart([1])
    step_on(f, path == "twin", Y[10], np.zeros((2, 1)))
    m = model.matrices(0)
    e = Y[10, 1] - m.C @ np.zeros(2)
    expected = e @ np.linalg.solve(m.C @ m.C.T + m.R, e)       # prior: x0 = 0, P0 = I
    assert f.last_info["nis"][1] == pytest.approx(expected, rel=1e-10)
    assert np.isfinite(f.last_info["nis"][0]) and not f.diverged.any()


@pytest.mark.parametrize("path", PATHS)
def test_the_growth_bound_flags_a_large_estimate(path: str) -> None:
    """The growth bound alone (an enormous nis_patience switches the NIS test off)."""
    model = carrier_model()
    f = FIRFilter(model, horizon=6, max_estimate=100.0, nis_patience=10**9)
    g = FIRFilter(model, horizon=6, nis_patience=10**9)
    for k in range(12):
        y = np.array([10.0 * k])
        step_on(f, path == "twin", y, None if k == 0 else np.zeros(1))
        step_on(g, path == "twin", y, None if k == 0 else np.zeros(1))
        assert f.diverged == bool(np.abs(f.x).max() > 100.0 or f.diverged)
    assert f.diverged and not g.diverged
    with pytest.raises(ValueError, match="max_estimate"):
        FIRFilter(model, horizon=6, max_estimate=0.0)


@pytest.mark.parametrize("path", PATHS)
def test_the_smoothers_test_is_the_filters_over_the_same_window(path: str) -> None:
    """The smoother's estimate lags; its innovation test is the FIR filter's over the same
    window (oracle: FIRFilter itself), and the prior propagated open loop during start-up."""
    model = carrier_model()
    s, f = FIRSmoother(model, horizon=12), FIRFilter(model, horizon=12)
    ys = linear_data(model, 200, 8)
    nis_s, nis_f = [], []
    for k, y in enumerate(ys):
        u = None if k == 0 else np.array([0.2])
        step_on(s, path == "twin", y, u)
        step_on(f, path == "twin", y, u)
        nis_s.append(s.last_info["nis"])
        nis_f.append(f.last_info["nis"])
    assert np.all(np.isfinite(nis_s)) and not s.diverged
    np.testing.assert_allclose(nis_s[12:], nis_f[12:], rtol=1e-9)
    first, _ = _smoother_on_a_jump(path)
    assert first is not None and first < 20


def _smoother_on_a_jump(path: str):
    model = carrier_model()
    s = FIRSmoother(model, horizon=12)
    ys = linear_data(model, 80, 9)
    ys[40:] += 30.0 * (-1.0) ** np.arange(40)[:, None]        # the data leave the model
    first = None
    for k, y in enumerate(ys):
        step_on(s, path == "twin", y, None if k == 0 else np.zeros(1))
        if s.diverged and first is None:
            first = k - 40
    return first, s


# ---------------------------------------------------------------- one observability rule
@pytest.mark.parametrize("env_id", ["fir_gym/Orbit-v0", "fir_gym/UncertainOscillator-v0",
                                    "fir_gym/CarrierMotion-v0", "fir_gym/VanDerPol-v0"])
def test_efir_refuses_a_window_shorter_than_the_observability_index(env_id: str) -> None:
    """The issue's case: ``horizon=1`` used to run open loop forever."""
    env = gym.make(env_id)
    plant = env.unwrapped
    x0 = plant.initial_state                                   # type: ignore[attr-defined]
    with pytest.raises(ValueError, match=r"horizon=1 is shorter than the observability index "
                                         r"(\d+) along its nominal .* use horizon >= \1"):
        ExtendedFIRFilter(plant.model, horizon=1, x0=x0)        # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="horizon=1 is shorter"):
        gym.make(env_id, estimator="efir", estimator_kwargs={"horizon": 1})


def test_every_windowed_filter_says_the_same() -> None:
    """One rule, one message: the FIR family and the EFIR on the same linear model."""
    model = carrier_model()
    messages = []
    for cls in (FIRFilter, UFIRFilter, FIRSmoother, ExtendedFIRFilter):
        with pytest.raises(ValueError) as err:
            cls(model, horizon=1)
        messages.append(str(err.value).replace("its nominal from x0=[0., 0.]", "(A, C)"))
    assert len(set(messages)) == 1, messages
    assert messages[0] == ("horizon=1 is shorter than the observability index 2 along (A, C): "
                           "the window cannot determine the state; use horizon >= 2")


def test_an_efir_unobservable_along_its_nominal_is_refused() -> None:
    from fir_gym.estimators import StateSpaceModel
    model = StateSpaceModel(f=lambda x, u: x.copy(), h=lambda x: x[..., :1] * x[..., 1:],
                            Q=1e-4 * np.eye(2), R=[[0.01]])
    with pytest.raises(ValueError, match="not observable along its nominal from x0"):
        ExtendedFIRFilter(model, horizon=4, x0=[1.0, 0.0])
    # a batched prior: every system's nominal must be observable
    with pytest.raises(ValueError, match="not observable"):
        ExtendedFIRFilter(model, horizon=4, x0=[[1.0, 0.0], [1.0, 2.0]])

