"""The innovation gate (``gate=<probability>``) of every filter that has one.

Oracles, none of which is the gate's own code:

* a twin filter *without* a gate fed the outlier as a missing measurement (``step(None)``, a
  masked entry of a ``numpy.ma`` array) — the package's missing-data path, which the gate
  must reproduce bit for bit in the estimate, the covariance and every later step;
* ``scipy.stats.chi2.ppf(gate, n_y)`` and the first step's ``S = C P0 Cᵀ + R`` computed here
  with numpy, against which measurements are placed just above and just below the threshold;
* the binomial law of the number of rejections when the data come from the filter's own
  linear-Gaussian model (each NIS is then χ²(n_y));
* the numpy reference, for the compiled twins (``tests/helpers/compiled_paths.py``);
* the original filter, for its deep copies and pickles.
"""

from __future__ import annotations

import copy
import pickle
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
import scipy.stats
from compiled_paths import needs_twins, on_path, step_on
from sample_models import duffing_model, random_linear_3x1

from fir_gym.estimators import (
    Estimator,
    KalmanFilter,
    LinearModel,
    estimator_class,
    make_estimator,
)
from fir_gym.estimators.continuous import ContinuousModel
from fir_gym.estimators.errors import accepted_options

#: a gate no measurement of these models' own data reaches (χ²(2) tail 1e-12: NIS ≈ 55)
STRICT = 1.0 - 1e-12
PATHS = ["numpy", "compiled"]


def carrier_model() -> ContinuousModel:
    """A linear continuous model (2 states, 1 output) both continuous filters run on."""
    return ContinuousModel.linear(A=[[0.0, 1.0], [-0.36, -0.06]], C=[[1.0, 0.0]],
                                  G=[[0.6], [-0.036]], Q=0.035, R=1.0, dt=0.1)


@dataclass(frozen=True)
class Case:
    """A gate-capable filter on a model: ``make(**options)`` builds it."""

    label: str
    name: str
    model: Callable[[], Any]
    options: dict[str, Any]

    def make(self, **options: Any) -> Any:
        return make_estimator(self.name, self.model(), **self.options, **options)


def rotating_2x2() -> LinearModel:
    """Two states, both measured, rotating: every window of the FIR filters is well
    conditioned however many of its samples are missing (one determines the state), so the
    compiled twins agree with the numpy references to 1e-12 (the bound of
    tests/estimators/test_efir_fast_path.py, which grows with the window's condition number —
    random_linear_3x1's reaches 4e5 with two samples missing)."""
    c, s = np.cos(0.3), np.sin(0.3)
    return LinearModel(A=0.95 * np.array([[c, -s], [s, c]]), C=[[1.0, 0.2], [0.0, 1.0]],
                       B=[[0.0], [0.5]], Q=0.05 * np.eye(2), R=np.diag([0.2, 0.3]))


DUFFING_PRIOR = {"x0": [0.5, 0.2, 1.0], "P0": 0.01 * np.eye(3)}
CASES = [
    Case("kf", "kf", lambda: random_linear_3x1(0.9), {}),
    Case("ekf (linear model)", "ekf", lambda: random_linear_3x1(0.9), {}),
    Case("ekf", "ekf", duffing_model, DUFFING_PRIOR),
    Case("lkf", "lkf", duffing_model, DUFFING_PRIOR),
    # α = 1: the default α = 1e-3 amplifies round-off by 1/α² = 1e6 (test_fast_paths.py), and
    # test 4 compares the two paths to 1e-12
    Case("ukf", "ukf", duffing_model, {"alpha": 1.0, **DUFFING_PRIOR}),
    Case("fir", "fir", rotating_2x2, {"horizon": 8}),
    Case("fir (3 states, 1 output)", "fir", lambda: random_linear_3x1(0.9), {"horizon": 8}),
    Case("fir-smoother", "fir-smoother", rotating_2x2, {"horizon": 8}),
    Case("ufir", "ufir", rotating_2x2, {"horizon": 8}),
    Case("efir", "efir", duffing_model, {"horizon": 12, **DUFFING_PRIOR}),
    Case("cd-ekf", "cd-ekf", carrier_model, {}),
    Case("bpf-kf", "bpf-kf", carrier_model, {}),
]
IDS = [c.label for c in CASES]


def simulate(model: Any, x0: Any, P0: Any, T: int, batch: int | None, rng: np.random.Generator
             ) -> tuple[np.ndarray, np.ndarray]:
    """Measurements ``(T, [B,] n_y)`` and inputs of the discrete model ``model`` (a filter's
    own ``model``: for the continuous filters, their sampled view), started from ``N(x0,
    P0)``, with its own noise."""
    n, m, n_u = model.n_x, model.n_y, model.n_u
    B = batch or 1
    x = rng.multivariate_normal(np.zeros(n) if x0 is None else np.asarray(x0, float),
                                np.eye(n) if P0 is None else np.asarray(P0, float), size=B)
    Y, U = [], []
    for _ in range(T):
        y = model.h(x) + rng.multivariate_normal(np.zeros(m), model.R, size=B)
        u = 0.3 * rng.standard_normal((B, n_u))
        Y.append(y)
        U.append(u)
        x = model.f(x, u) + rng.multivariate_normal(np.zeros(n), model.GQGT, size=B)
    Y_, U_ = np.array(Y), np.array(U)
    return (Y_[:, 0], U_[:, 0]) if batch is None else (Y_, U_)


def sigma(flt: Any) -> np.ndarray:
    """The measurement noise's standard deviation per channel, as the filter sees it."""
    return np.sqrt(np.diag(flt.model.R))


def masked(y: np.ndarray, hit: np.ndarray, single: bool) -> Any:
    """``y`` with the systems ``hit`` missing: ``None`` for one system, masked rows for a batch."""
    if not hit.any():
        return y
    if single:
        return None
    return np.ma.masked_array(y, mask=np.repeat(hit[:, None], y.shape[1], axis=1))


# ---------------------------------------------------------------------------- 1. the outlier
@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("batch", [None, 5])
@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_a_rejected_outlier_leaves_exactly_what_a_missing_measurement_does(case, batch, path):
    """100σ outliers (the first step's, later ones on one system or on some of a batch):
    the gated filter's estimate and covariance equal bit for bit those of a filter without
    a gate fed them as missing, at that step and every later one; its NIS is reported, its
    log-likelihood is 0 and it is counted."""
    gated, twin = case.make(gate=STRICT), case.make()
    T = 40
    Y, U = simulate(gated.model, case.options.get("x0"), case.options.get("P0"), T, batch,
                    np.random.default_rng(7))
    B = batch or 1
    outliers = {0: [0], 12: [1, 3] if batch else [0], 13: [2] if batch else [],
                30: [1] if batch else [0]}
    if case.name == "fir-smoother":     # its test does not count over a window with a gap
        del outliers[13]
    threshold = scipy.stats.chi2.ppf(STRICT, gated.model.n_y)
    count = np.zeros(B, int)
    with on_path(path):
        for k in range(T):
            hit = np.zeros(B, bool)
            hit[outliers.get(k, [])] = True
            y = Y[k].reshape(B, -1).copy()
            y[hit, 0] += 100.0 * sigma(gated)[0]
            y_in = y[0] if batch is None else y
            u = None if k == 0 else U[k - 1]
            x_gated = gated.step(y_in, u)
            x_twin = twin.step(masked(y_in, hit, batch is None), u)
            np.testing.assert_array_equal(x_gated, x_twin, err_msg=f"x at step {k}")
            np.testing.assert_array_equal(gated.P, twin.P, err_msg=f"P at step {k}")
            info, ref = gated.last_info, twin.last_info
            np.testing.assert_array_equal(np.reshape(info["gated"], B), hit)
            count += hit
            np.testing.assert_array_equal(np.reshape(info["gated_count"], B), count)
            nis, nis_twin = np.reshape(info["nis"], B), np.reshape(ref["nis"], B)
            assert (nis[hit] > threshold).all() and np.isnan(nis_twin[hit]).all()
            np.testing.assert_array_equal(nis[~hit], nis_twin[~hit])
            if info["log_likelihood"] is not None:
                ll = np.reshape(info["log_likelihood"], B)
                assert (ll[hit] == 0.0).all()
                np.testing.assert_array_equal(ll, np.reshape(ref["log_likelihood"], B))
            np.testing.assert_array_equal(gated.diverged, twin.diverged)
    assert count.sum() == sum(map(len, outliers.values()))


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("shared", [True, False])
def test_the_kalman_filter_gates_in_its_steady_state_and_with_a_shared_covariance(shared,
                                                                                   path):
    """The KF's shortcuts: a batch settled in the steady state (one covariance for all
    systems, or one each) meets an outlier on two systems. The gated filter leaves the
    steady state and gives every system its own covariance exactly as a filter without a
    gate fed those measurements as missing does — same bits then and after, when both
    settle again."""
    model = random_linear_3x1(0.9)
    B = 6
    P0 = np.eye(3) if shared else np.repeat(np.eye(3)[None], B, axis=0)
    gated = KalmanFilter(model, x0=np.zeros((B, 3)), P0=P0, gate=STRICT)
    twin = KalmanFilter(model, x0=np.zeros((B, 3)), P0=P0)
    T, hit_at = 700, (400, 650)
    Y, U = simulate(model, np.zeros(3), np.eye(3), T, B, np.random.default_rng(3))
    hit = np.zeros(B, bool)
    hit[[2, 4]] = True
    with on_path(path):
        for k in range(T):
            y = Y[k].copy()
            if k in hit_at:
                assert gated.steady_state and twin.steady_state
                assert (gated.state.P.shape[0] == 1) == (shared and k == hit_at[0])
                y[hit, 0] += 100.0 * np.sqrt(model.R[0, 0])
            u = None if k == 0 else U[k - 1]
            x_gated = gated.step(y, u)
            x_twin = twin.step(masked(y, hit, False) if k in hit_at else y, u)
            np.testing.assert_array_equal(x_gated, x_twin, err_msg=f"x at step {k}")
            np.testing.assert_array_equal(gated.P, twin.P, err_msg=f"P at step {k}")
            assert gated.steady_state == twin.steady_state
            np.testing.assert_array_equal(gated.last_info["gated"], hit & (k in hit_at))
            if k in hit_at:
                assert not gated.steady_state and gated.state.P.shape[0] == B
    np.testing.assert_array_equal(gated.last_info["gated_count"], 2 * hit)


# ---------------------------------------------------------------------------- 2. the threshold
def random_linear(n: int, m: int, seed: int) -> LinearModel:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A *= 0.9 / np.max(np.abs(np.linalg.eigvals(A)))
    M = rng.normal(size=(m, m))
    return LinearModel(A=A, C=rng.normal(size=(m, n)), Q=0.1 * np.eye(n),
                       R=M @ M.T + 0.5 * np.eye(m))


def continuous_linear(n: int, m: int, seed: int) -> ContinuousModel:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n)) - 2.0 * np.eye(n)
    M = rng.normal(size=(m, m))
    return ContinuousModel.linear(A=A, C=rng.normal(size=(m, n)), Q=0.1 * np.eye(n),
                                  R=M @ M.T + 0.5 * np.eye(m), dt=0.1)


GATE_NAMES = ["kf", "lkf", "ekf", "ukf", "fir", "fir-smoother", "ufir", "efir", "cd-ekf",
              "bpf-kf"]


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("gate", [0.9, 0.999])
@pytest.mark.parametrize(("n_x", "n_y"), [(3, 1), (6, 4), (2, 4)])
@pytest.mark.parametrize("name", GATE_NAMES)
def test_the_threshold_is_the_chi2_quantile_with_n_y_degrees_of_freedom(name, n_x, n_y, gate,
                                                                        path):
    """First measurements of a batch placed at NIS = t (1 ± 1e-6), t = chi2.ppf(gate, n_y),
    with ``S = C P0 Cᵀ + R`` computed here: those above are rejected, those below are not.
    With n_y ≠ n_x, a threshold of χ²(n_x) (or any other) would misjudge half of them."""
    continuous = name in ("cd-ekf", "bpf-kf")
    model = continuous_linear(n_x, n_y, n_x + n_y) if continuous else \
        random_linear(n_x, n_y, n_x + n_y)
    rng = np.random.default_rng(n_x * 7 + n_y)
    B = 8
    x0 = rng.normal(size=n_x)
    L = rng.normal(size=(n_x, n_x))
    P0 = L @ L.T / n_x + 0.2 * np.eye(n_x)
    opts: dict[str, Any] = {"x0": x0, "P0": P0, "gate": gate}
    if "fir" in name:
        opts["horizon"] = 2 * n_x
    flt = make_estimator(name, model, **opts)
    C, R = np.asarray(model.C), np.asarray(model.R) / (model.dt if continuous else 1.0)
    S = C @ P0 @ C.T + R
    t = scipy.stats.chi2.ppf(gate, n_y)
    assert t != scipy.stats.chi2.ppf(gate, n_x) or n_x == n_y
    d = rng.normal(size=(B, n_y))
    above = np.arange(B) % 2 == 0
    # 1e-6 apart: far above round-off (the UKF's α = 1e-3 weights amplify it by 1/α² = 1e6,
    # to about 1e-10), far below the gap to any other quantile
    want = t * np.where(above, 1.0 + 1e-6, 1.0 - 1e-6)
    scale = np.sqrt(want / np.einsum("bi,ij,bj->b", d, np.linalg.inv(S), d))
    y = x0 @ C.T + scale[:, None] * d
    with on_path(path):
        flt.step(y)
    info = flt.last_info
    np.testing.assert_allclose(info["nis"], want, rtol=1e-8)
    np.testing.assert_array_equal(info["gated"], above)
    np.testing.assert_array_equal(info["gated_count"], above.astype(int))
    if info["log_likelihood"] is not None:
        assert (info["log_likelihood"][above] == 0.0).all()
        assert (info["log_likelihood"][~above] < 0.0).all()


# ---------------------------------------------------------------------------- 3. the rate
def white_state_model(n: int, m: int, seed: int) -> LinearModel:
    """``x[k+1] = w[k]``: every prediction is ``N(0, Q)`` whatever came before, so on this
    model's data every NIS of a Kalman-family filter is χ²(n_y) and independent of the others
    — rejections included, which change no later prediction: their count is binomial."""
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(m, m))
    return LinearModel(A=np.zeros((n, n)), C=rng.normal(size=(m, n)),
                       Q=0.5 * np.eye(n), R=M @ M.T + 0.5 * np.eye(m))


def within_binomial(rejected: int, trials: int, p: float, z: float = 4.5) -> None:
    mean, sd = trials * p, np.sqrt(trials * p * (1.0 - p))
    assert abs(rejected - mean) <= z * sd, (rejected, trials, mean, sd)


@pytest.mark.parametrize("name", ["kf", "lkf", "ekf", "ukf"])
@pytest.mark.parametrize(("n_x", "n_y"), [(3, 1), (3, 4)])
def test_the_kalman_family_rejects_a_binomial_one_minus_gate_of_its_own_data(name, n_x, n_y):
    """Data from the filter's own model: over 300 steps of 200 systems the rejections are
    within 4.5 binomial standard deviations of (1 − gate) per measurement (a 7e-6 chance
    to fail by bad luck; the seed is fixed)."""
    model = white_state_model(n_x, n_y, 11)
    B, T, gate = 200, 300, 0.98
    P0 = 0.5 * np.eye(n_x)
    flt = make_estimator(name, model, x0=np.zeros(n_x), P0=P0, gate=gate)
    Y, _ = simulate(model, np.zeros(n_x), P0, T, B, np.random.default_rng(n_x + n_y))
    for y in Y:
        flt.step(y)
    within_binomial(int(flt.last_info["gated_count"].sum()), B * T, 1.0 - gate)


@pytest.mark.parametrize("name", ["fir", "fir-smoother", "efir"])
def test_the_minimum_variance_fir_filters_reject_a_binomial_one_minus_gate(name):
    """The minimum-variance unbiased FIR filter reports its true error covariance, so its
    one-step NIS is χ²(n_y) at every step (docs/architecture.md#windowed-consistency); data
    from its model, a rare gate (1e-3: few windows lose a sample, whose loss could tell the
    next test anything) and 4.5 binomial standard deviations, over the steps that have a
    NIS (the FIR smoother's test skips windows with a gap)."""
    model = random_linear_3x1(0.9)
    B, T, gate = 400, 250, 0.999
    flt = make_estimator(name, model, horizon=8, gate=gate)
    Y, U = simulate(model, np.zeros(3), np.eye(3), T, B, np.random.default_rng(5))
    trials = 0
    for k in range(T):
        flt.step(Y[k], None if k == 0 else U[k - 1])
        trials += int(np.isfinite(flt.last_info["nis"]).sum())
    assert trials > 0.9 * B * T
    within_binomial(int(flt.last_info["gated_count"].sum()), trials, 1.0 - gate)


# ---------------------------------------------------------------------------- 4. twin vs numpy
def random_outliers(Y: np.ndarray, flt: Any, rng: np.random.Generator) -> np.ndarray:
    """``Y (T, B, n_y)`` with 30σ outliers on a tenth of the measurements."""
    Y = Y.copy()
    where = rng.uniform(size=Y.shape[:2]) < 0.1
    Y[where, 0] += 30.0 * sigma(flt)[0] * rng.choice([-1.0, 1.0], size=int(where.sum()))
    return Y


TWIN_CASES = [c for c in CASES if c.label != "fir (3 states, 1 output)"]


@needs_twins
@pytest.mark.parametrize("batch", [None, 6])
@pytest.mark.parametrize("case", TWIN_CASES, ids=[c.label for c in TWIN_CASES])
def test_the_compiled_twin_gates_as_the_numpy_reference(case, batch):
    """One filter on the compiled twin, its copy on the numpy reference, a gate that often
    fires (0.99, and outliers): estimates and covariances agree to 1e-12 (the bound of
    tests/estimators/test_fast_paths.py for well-conditioned steps; the FIR cases' windows
    are well conditioned), the NIS to 1e-10 (absolute too: it is a χ² number of order 1,
    and an innovation that cancels its measurement loses relative accuracy), the
    rejections exactly."""
    twin = case.make(gate=0.99)
    ref = copy.deepcopy(twin)
    rng = np.random.default_rng(17)
    T = 120
    Y, U = simulate(twin.model, case.options.get("x0"), case.options.get("P0"), T, batch or 1,
                    rng)
    Y = random_outliers(Y, twin, rng)
    fired = 0
    for k in range(T):
        y = Y[k, 0] if batch is None else Y[k]
        u = None if k == 0 else (U[k - 1, 0] if batch is None else U[k - 1])
        xt, xr = step_on(twin, True, y, u), step_on(ref, False, y, u)
        np.testing.assert_allclose(xt, xr, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(twin.P, ref.P, rtol=1e-12, atol=1e-12)
        it, ir = twin.last_info, ref.last_info
        np.testing.assert_allclose(it["nis"], ir["nis"], rtol=1e-10, atol=1e-10)
        np.testing.assert_array_equal(it["gated"], ir["gated"])
        np.testing.assert_array_equal(twin.diverged, ref.diverged)
        fired += int(np.sum(it["gated"]))
    np.testing.assert_array_equal(twin.last_info["gated_count"], ref.last_info["gated_count"])
    assert fired >= 5


@needs_twins
@pytest.mark.parametrize("shared, single", [(True, True), (True, False), (False, False)],
                         ids=["one-system", "shared-batch", "own-covariances"])
def test_the_kalman_twin_gates_as_the_numpy_reference_in_the_steady_state(shared, single):
    """The KF's twin against its reference through the steady state and the shared
    covariance: both settle, the gate fires in the steady state (and under the shared
    covariance), both leave it — each covariance its own — and settle again; estimates to
    round-off, rejections the same. (When the regime is entered is decided at round-off,
    ``max|ΔP| <= 4 eps max|P|``: the two paths may enter it a step apart, with or without
    a gate, so the regimes are checked on each path, not against each other.)"""
    model = random_linear_3x1(0.9)
    B = 1 if single else 5
    P0 = np.eye(3) if shared else np.repeat(np.eye(3)[None], B, axis=0)
    x0 = np.zeros(3) if single else np.zeros((B, 3))
    twin = KalmanFilter(model, x0=x0, P0=P0, gate=0.999)
    ref = copy.deepcopy(twin)
    rng = np.random.default_rng(23)
    T = 900
    Y, U = simulate(model, np.zeros(3), np.eye(3), T, B, rng)
    fired_steady = np.zeros(2, int)
    for k in range(T):
        y, u = Y[k], None if k == 0 else U[k - 1]
        if k >= 300 and k % 150 == 0:
            y = y.copy()
            y[rng.integers(B), 0] += 50.0
        if single:
            y, u = y[0], None if u is None else u[0]
        steady = [twin.steady_state, ref.steady_state]
        xt, xr = step_on(twin, True, y, u), step_on(ref, False, y, u)
        np.testing.assert_allclose(xt, xr, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(twin.P, ref.P, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(twin.last_info["gated"], ref.last_info["gated"])
        if np.any(twin.last_info["gated"]):
            fired_steady += steady
            for f in (twin, ref):
                assert not f.steady_state and f.state.P.shape[0] == B
    assert (fired_steady >= 3).all()


# ---------------------------------------------------------------------------- 5. copies
@pytest.mark.parametrize("copier", ["deepcopy", "pickle"])
@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_a_gated_filter_copied_mid_run_has_the_original_future(case, copier):
    """Copied after rejections (counts and all), the copy's future — estimates, covariances,
    rejections and counts — equals the original's bit for bit, on either path."""
    flt = case.make(gate=0.99)
    B = 4
    rng = np.random.default_rng(29)
    Y, U = simulate(flt.model, case.options.get("x0"), case.options.get("P0"), 50, B, rng)
    Y = random_outliers(Y, flt, rng)
    for k in range(25):
        flt.step(Y[k], None if k == 0 else U[k - 1])
    assert flt.last_info["gated_count"].sum() > 0
    dup = copy.deepcopy(flt) if copier == "deepcopy" else pickle.loads(pickle.dumps(flt))
    runs = []
    for f in (dup, flt):
        out = []
        for k in range(25, 50):
            with on_path("numpy" if k % 2 else "compiled"):
                out.append((f.step(Y[k], U[k - 1]), f.P, f.last_info["gated"].copy(),
                            f.last_info["gated_count"].copy(), f.last_info["nis"]))
        runs.append(out)
    for a, b in zip(*runs, strict=True):
        for u, v in zip(a, b, strict=True):
            np.testing.assert_array_equal(u, v)


# ---------------------------------------------------------------------------- 6. refusals
@pytest.mark.parametrize(("value", "error"), [
    (True, TypeError), (False, TypeError), ("0.99", TypeError), (0.9 + 0j, TypeError),
    ([0.99], TypeError), (0, ValueError), (1, ValueError), (0.0, ValueError),
    (1.0, ValueError), (-0.5, ValueError), (1.5, ValueError), (float("nan"), ValueError),
    (float("inf"), ValueError)])
@pytest.mark.parametrize("name", ["kf", "ekf", "fir"])
def test_a_bad_gate_is_refused_naming_it(name, value, error):
    opts = {"horizon": 4} if name == "fir" else {}
    with pytest.raises(error, match=r"gate must be a probability strictly between 0 and 1"):
        make_estimator(name, random_linear_3x1(0.9), gate=value, **opts)
    flt = make_estimator(name, random_linear_3x1(0.9), **opts)
    with pytest.raises(error, match=r"gate must be a probability strictly between 0 and 1"):
        flt.gate = value
    assert flt.gate is None


def test_every_registered_filter_takes_the_option():
    for name in GATE_NAMES + ["rfir"]:
        assert "gate" in accepted_options(estimator_class(name)), name


def test_the_recursive_fir_filter_refuses_a_gate_and_says_why():
    with pytest.raises(ValueError, match=r"gate: RecursiveFIRFilter cannot gate .*every "
                                         r"measurement.*FIRFilter gates"):
        make_estimator("rfir", random_linear_3x1(0.9), horizon=6, gate=0.99)
    flt = make_estimator("rfir", random_linear_3x1(0.9), horizon=6)
    with pytest.raises(ValueError, match="cannot gate"):
        flt.gate = 0.99
    flt.gate = None                                    # no gate is always fine
    flt.step([0.1])
    assert "gated" not in flt.last_info


class NoInnovation(Estimator):
    """A filter without a NIS (a moving average of the measurement)."""

    reports_nis = False
    provides_covariance = False

    def _update(self, x, P, y, valid):
        return np.where(valid[:, None], y, x), None, None

    def _predict_update(self, x, P, y, u, valid):
        return self._update(x, P, y, valid)


def test_a_filter_without_a_nis_refuses_a_gate_and_says_why():
    model = LinearModel(A=[[1.0]], C=[[1.0]], Q=[[1.0]], R=[[1.0]])
    with pytest.raises(ValueError, match=r"NoInnovation cannot gate .*no normalised innovation"):
        NoInnovation(model, gate=0.99)
    NoInnovation(model, gate=None).step([1.0])


# ---------------------------------------------------------------------------- the rest
@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", ["kf", "ukf", "fir"])
def test_a_nis_that_stays_above_the_watch_is_flagged_though_the_gate_rejects_it(name, path):
    """The watch counts a rejected measurement's NIS: constant 1000σ outliers flag the filter
    after ``nis_patience`` steps, while its estimate coasts exactly as with no data."""
    model = random_linear_3x1(0.9)
    opts: dict[str, Any] = {"horizon": 6} if name == "fir" else {}
    gated = make_estimator(name, model, gate=0.999, nis_patience=3, **opts)
    twin = make_estimator(name, model, nis_patience=3, **opts)
    with on_path(path):
        for k in range(12):
            y = np.array([0.1 * np.sin(k)]) + (1000.0 * np.sqrt(model.R[0, 0]) if k >= 6 else 0)
            np.testing.assert_array_equal(gated.step(y), twin.step(None if k >= 6 else y))
            assert gated.diverged == (k >= 8)
            assert gated.last_info["gated"] == (k >= 6)
    assert not twin.diverged and gated.last_info["gated_count"] == 6


def test_without_a_gate_last_info_has_no_gate_keys_and_filter_reports_rejections():
    model = random_linear_3x1(0.9)
    flt = KalmanFilter(model)
    flt.step([0.1])
    assert "gated" not in flt.last_info and "gated_count" not in flt.last_info
    ys = np.array([[0.1], [0.2], [90.0], [0.1], [np.nan], [0.0]])
    gated = KalmanFilter(model, gate=0.999)
    result = gated.filter(ys)
    np.testing.assert_array_equal(result.gated, [False, False, True, False, False, False])
    assert result.log_likelihoods[2] == 0.0 and result.nis[2] > 10.8
    assert KalmanFilter(model).filter(ys).gated is None


def test_restart_zeroes_the_restarted_systems_counts_and_a_live_gate_takes_effect():
    model = random_linear_3x1(0.9)
    flt = KalmanFilter(model, x0=np.zeros((3, 3)), P0=np.eye(3), gate=0.999)
    big = np.array([[50.0], [50.0], [0.0]])
    flt.step(big)
    flt.step(big)
    np.testing.assert_array_equal(flt.last_info["gated_count"], [2, 2, 0])
    flt.restart([1])
    np.testing.assert_array_equal(flt.last_info["gated_count"], [2, 0, 0])
    flt.gate = None                                    # assignable: the next step takes it
    flt.step(np.zeros((3, 1)))
    assert "gated" not in flt.last_info
    flt.gate = 0.999
    flt.step(big)
    np.testing.assert_array_equal(flt.last_info["gated"], [True, True, False])
    np.testing.assert_array_equal(flt.last_info["gated_count"], [3, 1, 0])
