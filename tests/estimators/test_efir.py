"""ExtendedFIRFilter: equals FIRFilter on linear models; bounded error on Orbit-v0."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import scipy.stats
from sample_models import random_linear_3x1

import fir_gym  # noqa: F401  (registers the environments)
from fir_gym.envs.orbit import NOMINAL_MU, TRUE_MU
from fir_gym.estimators import LinearModel, StateSpaceModel
from fir_gym.estimators.efir import ExtendedFIRFilter
from fir_gym.estimators.fir import FIRFilter
from fir_gym.estimators.registry import make_estimator

N = 10                                   # paper 000 sim 1: 10 measurements per window
X0_FILTER = [7.997, 1.992]               # the filter's (and nominal's) initial state


def linear_model() -> LinearModel:
    return random_linear_3x1(1.08)


@pytest.mark.parametrize("nominal", ["open-loop", "reanchor"])
@pytest.mark.parametrize("form", ["filter", "predictor"])
def test_linear_model_equals_fir_filter(form: str, nominal: str) -> None:
    model = linear_model()
    rng = np.random.default_rng(1)
    fir = FIRFilter(model, horizon=6, form=form)
    efir = ExtendedFIRFilter(model, horizon=6, form=form, nominal=nominal,
                             x0=rng.normal(size=3) * 4.0)     # any nominal start
    x = rng.normal(size=3)
    for k in range(40):
        u = rng.normal(size=1)
        if k:
            x = model.A @ x + model.B @ u + rng.normal(size=3) * 0.3
        y = model.C @ x + rng.normal(size=1) * 0.6
        a, b = fir.step(y, u if k else None), efir.step(y, u if k else None)
        if not efir.last_info["rank_deficient"]:
            assert np.abs(a - b).max() <= 1e-10 * max(1.0, np.abs(a).max())
            assert np.allclose(fir.P, efir.P, rtol=1e-9, atol=1e-12)
        assert fir.last_info["startup"] == efir.last_info["startup"]


def test_missing_measurements_skipped_like_fir_filter() -> None:
    model = linear_model()
    rng = np.random.default_rng(2)
    fir = FIRFilter(model, horizon=6, nan_policy="skip")
    efir = ExtendedFIRFilter(model, horizon=6, nan_policy="skip", nominal="reanchor")
    for k in range(30):
        y = rng.normal(size=1) if k % 7 != 3 else np.array([np.nan])
        u = rng.normal(size=1) if k else None
        a, b = fir.step(y, u), efir.step(y, u)
        assert fir.last_info["rank_deficient"] == efir.last_info["rank_deficient"]
        if not fir.last_info["rank_deficient"]:
            assert np.abs(a - b).max() <= 1e-10 * max(1.0, np.abs(a).max())


def test_batch_in_lockstep_equals_separate_filters() -> None:
    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:       # a pendulum with damping
        return np.stack([x[..., 0] + 0.05 * x[..., 1],
                         x[..., 1] - 0.05 * (np.sin(x[..., 0]) + 0.2 * x[..., 1]) + u[..., 0]],
                        -1)

    def F(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = np.zeros(x.shape[:-1] + (2, 2))
        J[..., 0, 0], J[..., 0, 1] = 1.0, 0.05
        J[..., 1, 0], J[..., 1, 1] = -0.05 * np.cos(x[..., 0]), 1.0 - 0.01
        return J

    # analytic Jacobians: a batch and a single system run different (equally exact)
    # arithmetic, and central differences would magnify their round-off ~1e5 times
    model = StateSpaceModel(f=f, F=F, h=lambda x: np.sin(x[..., :1]),
                            H=lambda x: np.stack([np.cos(x[..., 0]), 0.0 * x[..., 0]], -1)[
                                ..., None, :], Q=[[1e-3]], R=[[0.01]], G=[[0.0], [1.0]], n_u=1)
    rng = np.random.default_rng(3)
    B, T = 4, 30
    x0 = rng.normal(size=(B, 2)) * 0.3
    Y = 0.5 * rng.normal(size=(T, B, 1))
    U = 0.1 * rng.normal(size=(T, B, 1))
    for nominal in ("open-loop", "reanchor"):
        batch = ExtendedFIRFilter(model, horizon=8, nominal=nominal, x0=x0)
        together = np.array([batch.step(Y[k], U[k]) for k in range(T)])
        for b in range(B):
            alone = ExtendedFIRFilter(model, horizon=8, nominal=nominal, x0=x0[b])
            sep = np.array([alone.step(Y[k, b], U[k, b]) for k in range(T)])
            assert np.abs(together[:, b] - sep).max() <= 1e-12 * max(1.0, np.abs(sep).max())


def test_rank_deficient_linearisation_flags_and_predicts() -> None:
    # y = x1·x2 seen from a nominal with x2 = 0 carries no information on x1. The nominal
    # starts at x2 = 1 and drains to x2 = 0 in four steps (a nominal unobservable from the
    # start is refused at construction: test_the_observability_rule_* below)
    def draining(x, u):
        return np.concatenate([x[..., :1], np.maximum(x[..., 1:] - 0.25, 0.0)], axis=-1)
    model = StateSpaceModel(f=draining, h=lambda x: x[..., :1] * x[..., 1:],
                            Q=1e-4 * np.eye(2), R=[[0.01]])
    f = ExtendedFIRFilter(model, horizon=4, x0=[1.0, 1.0])
    for _ in range(12):
        prev = f.x
        x = f.step([0.0])
    assert f.last_info["rank_deficient"] and not f.last_info["startup"]
    assert np.allclose(x, draining(prev, None))                # the fallback: f(x̂)


# ---------------------------------------------------------------------------- Orbit-v0
def orbit_run(form: str, nominal: str, noise_free: bool = False, seed: int = 0):
    """The paper's setting: N = 10, filter/nominal start [7.997, 1.992], zero thrust."""
    env = gym.make("fir_gym/Orbit-v0")
    model = env.unwrapped.model
    y, info = env.reset(seed=seed)
    f = ExtendedFIRFilter(model, horizon=N, form=form, nominal=nominal, x0=X0_FILTER)
    out: dict[str, list] = {"e": [], "sd": [], "state": [], "drift": []}
    k, done = 0, False
    while not done:
        x_hat = f.step(info["state"][:1] if noise_free else y, None if k == 0 else np.zeros(1))
        if not f.last_info["startup"]:
            out["e"].append(x_hat - info["state"])
            out["sd"].append(np.sqrt(np.diag(f.P)))
            out["state"].append(info["state"])
            out["drift"].append(f.x_nominal - info["state"])
        y, _, term, trunc, info = env.step(np.zeros(1))
        done, k = term or trunc, k + 1
    return {key: np.array(v) for key, v in out.items()}, float(model.R[0, 0])


def model_error_bias(sd: np.ndarray, R: float, states: np.ndarray, drift: float, form: str
                     ) -> np.ndarray:
    """Bound on the noise-free error from the μ mismatch and the linearisation (Q = 0).

    Over a window the truth departs from the model's linearised prediction (same
    start) by ``e`` with ``ë = a_true(r) − a_lin(r) + (2μ/r³) e``: forcing
    ``|F| ≤ δμ/r² + (3μ/r⁴) δr²`` (model error plus the second-order term of
    ``−μ/r²`` at nominal distance ``δr``), gradient ``ω² = 2μ/r³``, so
    ``|e_r(t)| ≤ F (cosh ωt − 1)/ω²``, ``|e_v(t)| ≤ F sinh(ωt)/ω`` (Euler steps
    obey the same bound). With ``Q = 0`` the estimate error is ``S d − d_T`` and
    ``S R Sᵀ = P``, so ``|s_i · d| ≤ sqrt(P_ii / R) ‖d‖``.
    """
    r_lo = states[:, 0].min() - drift
    F = (TRUE_MU - NOMINAL_MU) / r_lo**2 + 3.0 * TRUE_MU * drift**2 / r_lo**4
    w = np.sqrt(2.0 * TRUE_MU / r_lo**3)
    t = 0.01 * np.arange(N)                         # measurement instants in the window
    tT = 0.01 * (N - 1 if form == "filter" else N)
    d = np.linalg.norm(F * (np.cosh(w * t) - 1.0) / w**2)
    dT = np.array([F * (np.cosh(w * tT) - 1.0) / w**2, F * np.sinh(w * tT) / w])
    return sd / np.sqrt(R) * d + dT


@pytest.mark.parametrize("form", ["predictor", "filter"])
def test_orbit_error_bounded_by_noise_and_model_error(form: str) -> None:
    res, R = orbit_run(form, "open-loop")
    e, sd = np.abs(res["e"]), res["sd"]
    drift = np.abs(res["drift"][:, 0]).max()
    assert len(e) >= 900                                 # the whole 1000-step episode
    z = scipy.stats.norm.isf(1e-3 / (2 * e.size))        # union bound: 1e-3 for the run
    bound = z * sd + model_error_bias(sd, R, res["state"], drift, form)
    assert np.all(e <= bound), f"max |e| = {e.max(0)}, worst e/bound = {(e / bound).max()}"


def test_orbit_noise_free_error_is_within_the_model_error_bias() -> None:
    res, R = orbit_run("predictor", "open-loop", noise_free=True)
    drift = np.abs(res["drift"][:, 0]).max()
    bias = model_error_bias(res["sd"], R, res["state"], drift, "predictor")
    assert np.all(np.abs(res["e"]) <= bias)
    assert np.abs(res["e"]).max() > 0.01 * bias.max()     # the bound is not vacuous


def test_orbit_reanchored_nominal_noise_bound() -> None:
    res, R = orbit_run("predictor", "reanchor")
    e, sd = np.abs(res["e"]), res["sd"]
    # a window's nominal starts at the previous estimate: its distance to the truth
    # is at most that estimate's error plus the velocity error over the window
    drift = e[:, 0].max() + 0.01 * N * e[:, 1].max()
    z = scipy.stats.norm.isf(1e-3 / (2 * e.size))
    bound = z * sd + model_error_bias(sd, R, res["state"], drift, "predictor")
    assert np.all(e <= bound)


def test_registry_and_arguments() -> None:
    model = linear_model()
    assert isinstance(make_estimator("efir", model, horizon=5), ExtendedFIRFilter)
    with pytest.raises(ValueError, match="nominal"):
        ExtendedFIRFilter(model, horizon=5, nominal="closed-loop")
    with pytest.raises(ValueError, match="horizon"):
        ExtendedFIRFilter(model, horizon=0)

