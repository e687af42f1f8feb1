"""The divergence watch's NIS rule against its documented definition (``estimators/base.py``,
*Divergence*): a system is flagged when its NIS has stayed above the ``1 − nis_tail`` χ²
quantile *with n_y degrees of freedom* for ``nis_patience`` consecutive steps, and a NaN NIS
of a usable measurement counts as above (a skipped measurement's NaN does not).

Oracles: ``scipy.stats.chi2.isf(nis_tail, n_y)`` for the threshold, on a model with
``n_y = 1 < n_x = 3`` (so a threshold with ``n_x`` degrees of freedom is far off); NIS values
placed just above / just below that quantile by choosing the measurement from the Kalman
filter's own definition (``x⁻ = A x̂``, ``P⁻ = A P Aᵀ + Q``, ``S = C P⁻ Cᵀ + R``,
``y = C x⁻ + √(q S)`` gives NIS ``q``), computed here from the filter's public ``x`` and ``P``;
and the NaN rule booked directly into the watch (the numpy reference ``_accept`` and the
compiled ``watch.accept``) with finite estimates, so nothing but the NIS can flag.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import scipy.stats
from compiled_paths import TWINS, on_path

from fir_gym.estimators import KalmanFilter, LinearModel
from fir_gym.estimators.compiled import watch
from fir_gym.estimators.state import NIS_THRESHOLD

TAIL, PATIENCE = 1e-6, 3
PATHS = ["numpy", pytest.param("compiled", marks=pytest.mark.skipif(
    not TWINS, reason="the compiled twins are off in this run"))]


def model_3x1() -> LinearModel:
    """Three states, one output: ``χ²(1)`` and ``χ²(3)`` quantiles differ by far."""
    A = np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.1], [0.0, -0.05, 0.95]])
    return LinearModel(A=A, C=[[1.0, 0.0, 0.0]], Q=0.01 * np.eye(3), R=[[0.2]])


def kalman(model: LinearModel) -> KalmanFilter:
    return KalmanFilter(model, x0=np.zeros(3), P0=np.eye(3), nis_tail=TAIL,
                        nis_patience=PATIENCE)


def started(model: LinearModel) -> KalmanFilter:
    """A filter after one step whose NIS is 0 (``y = C x0``): its watch is booked, no run."""
    est = kalman(model)
    est.step([0.0])
    assert est.last_info["nis"] == 0.0 and not est.diverged
    return est


def test_the_threshold_is_the_chi2_quantile_with_n_y_degrees_of_freedom() -> None:
    """``state.limits[NIS_THRESHOLD] == chi2.isf(nis_tail, n_y)`` (not ``n_x``)."""
    model = model_3x1()
    est = kalman(model)
    want = scipy.stats.chi2.isf(TAIL, model.n_y)
    assert est.state.limits[NIS_THRESHOLD] == pytest.approx(want, rel=1e-12)
    assert scipy.stats.chi2.isf(TAIL, model.n_x) > 1.2 * want     # the two are far apart


def measurement_with_nis(est: KalmanFilter, model: LinearModel, q: float, first: bool
                         ) -> np.ndarray:
    """The ``y`` whose innovation has NIS ``q`` for the filter's next step, from the Kalman
    filter's definition and its public ``x``, ``P`` (the first step is an update only)."""
    x, P = est.x, est.P
    assert P is not None
    if not first:
        x, P = model.A @ x, model.A @ P @ model.A.T + model.GQGT
    S = float((model.C @ P @ model.C.T + model.R)[0, 0])
    return model.C @ x + np.sqrt(q * S)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize(("factor", "flags"), [(1.02, True), (0.98, False)])
def test_a_nis_just_above_the_n_y_quantile_for_patience_steps_flags(factor: float, flags: bool,
                                                                     path: str) -> None:
    """NIS = 1.02 · χ²₁ quantile every step flags the system at step ``nis_patience`` (not
    before); 0.98 · the quantile never does. Both are below the χ²₃ quantile."""
    model = model_3x1()
    est = kalman(model)
    q = factor * scipy.stats.chi2.isf(TAIL, model.n_y)
    assert q < scipy.stats.chi2.isf(TAIL, model.n_x)
    with on_path(path):
        for k in range(3 * PATIENCE):
            est.step(measurement_with_nis(est, model, q, first=k == 0))
            assert est.last_info["nis"] == pytest.approx(q, rel=1e-9)   # the placement holds
            assert est.diverged == (flags and k + 1 >= PATIENCE), k


# ---------------------------------------------------------------------------- NaN NIS
def book_numpy(est: KalmanFilter, nis: float, valid: bool) -> None:
    """One booking of the numpy reference watch with a finite estimate and covariance."""
    x, P = np.zeros((1, 3)), np.eye(3)[None]
    with np.errstate(invalid="ignore"):
        est._accept(x, P, np.array([nis]), np.array([valid]))


def book_compiled(est: KalmanFilter, nis: float, valid: bool) -> None:
    """The same booking through the compiled watch, on the filter's state record."""
    watch.accept(np.zeros((1, 3)), np.eye(3)[None], np.array([nis]), np.array([valid]), True,
                 est.state)


BOOKERS: dict[str, Callable[[KalmanFilter, float, bool], None]] = {
    "numpy": book_numpy,
    "compiled": book_compiled,
}


@pytest.mark.parametrize("path", list(BOOKERS))
def test_a_nan_nis_of_a_usable_measurement_counts_as_above(path: str) -> None:
    """``nis_patience`` NaN NIS of usable measurements flag the system (at the last one, not
    before), also when they continue a run of finite NIS above the threshold."""
    book = BOOKERS[path]
    limit = scipy.stats.chi2.isf(TAIL, 1)
    est = started(model_3x1())
    for k in range(PATIENCE):
        book(est, np.nan, True)
        assert est.diverged == (k + 1 >= PATIENCE), k
    mixed = started(model_3x1())
    for k, nis in enumerate([2.0 * limit, np.nan, 2.0 * limit][:PATIENCE]):
        book(mixed, nis, True)
        assert mixed.diverged == (k + 1 >= PATIENCE), k


@pytest.mark.parametrize("path", list(BOOKERS))
def test_a_skipped_measurements_nan_nis_never_counts(path: str) -> None:
    """A NaN NIS because the measurement is missing (``valid`` False) never flags, and it ends
    a run of high NIS (the run counts consecutive usable steps above)."""
    book = BOOKERS[path]
    limit = scipy.stats.chi2.isf(TAIL, 1)
    est = started(model_3x1())
    for _ in range(3 * PATIENCE):
        book(est, np.nan, False)
        assert not est.diverged
    for _ in range(4):
        for _ in range(PATIENCE - 1):
            book(est, 2.0 * limit, True)
        book(est, np.nan, False)
    assert not est.diverged


@pytest.mark.parametrize("path", PATHS)
def test_missing_measurements_in_a_run_of_steps_never_flag(path: str) -> None:
    """Through the public step: ``nan_policy="skip"`` with every measurement missing gives a
    NaN NIS each step and never flags."""
    model = model_3x1()
    est = KalmanFilter(model, x0=np.zeros(3), P0=np.eye(3), nis_tail=TAIL,
                       nis_patience=PATIENCE, nan_policy="skip")
    with on_path(path):
        for _ in range(3 * PATIENCE):
            est.step([np.nan])
            assert np.isnan(est.last_info["nis"]) and not est.diverged


# ------------------------------------------------------- the windowed filters' one-step NIS
# (from the mutation run, docs/mutation.md: every windowed-filter test measured one channel,
# so the twin's 2 x 2 closed form, its symmetrisation and its Cholesky branch went untested)

def textbook_innovation_nis(P, A, Qx, H, R, e, predict, valid):
    """``eᵀ S⁻¹ e`` per system with ``S = H P⁻ Hᵀ + R``, ``P⁻ = A P Aᵀ + Qx`` (or ``P``),
    by ``np.linalg.solve``; NaN where not valid or ``S`` is not positive definite."""
    out = np.full(P.shape[0], np.nan)
    for b in range(P.shape[0]):
        Ab, Qb, Hb = (M[b] if M.shape[0] > 1 else M[0] for M in (A, Qx, H))
        Pm = Ab @ P[b] @ Ab.T + Qb if predict[b] else P[b]
        S = Hb @ Pm @ Hb.T + R
        if valid[b] and np.all(np.linalg.eigvalsh(S) > 0):
            out[b] = e[b] @ np.linalg.solve(S, e[b])
    return out


@pytest.mark.skipif(not TWINS, reason="the compiled twins are off in this run")
@pytest.mark.parametrize("p", [1, 2, 3, 4])
@pytest.mark.parametrize("shared", [True, False], ids=["shared A, Qx, H", "per-system"])
def test_the_twins_innovation_nis_is_the_textbook_one(p: int, shared: bool) -> None:
    from fir_gym.estimators._consistency import innovation_nis
    rng = np.random.default_rng(10 * p + shared)
    n_b, n = 6, 3
    G = rng.normal(size=(n_b, n, n))
    P = G @ G.mT + 0.1 * np.eye(n)
    k = 1 if shared else n_b
    A, H = rng.normal(size=(k, n, n)), rng.normal(size=(k, p, n))
    Gq = rng.normal(size=(k, n, n))
    Qx = 0.1 * Gq @ Gq.mT
    Gr = rng.normal(size=(p, p))
    R = Gr @ Gr.T + 0.2 * np.eye(p)
    e = rng.normal(size=(n_b, p))
    predict = np.array([True, False, True, True, False, True])
    valid = np.array([True, True, False, True, True, True])
    R_bad = -np.eye(p) * 1e3                           # S not positive definite
    for R_, want_nan in ((R, ~valid), (R_bad, np.ones(n_b, bool))):
        want = textbook_innovation_nis(P, A, Qx, H, R_, e, predict, valid)
        np.testing.assert_array_equal(np.isnan(want), want_nan)
        out = np.empty(n_b)
        watch.innovation_nis(P, A, Qx, H, R_, e, predict, valid, out)
        np.testing.assert_allclose(out, want, rtol=1e-10)
        np.testing.assert_allclose(innovation_nis(P, A, Qx, H, R_, e, predict, valid), want,
                                   rtol=1e-10)


# ------------------------------------------------- the watch's arguments (from the mutation run)
@pytest.mark.parametrize(("option", "value", "message"), [
    ("nis_tail", 1.0, r"nis_tail must be in \(0, 1\); got 1.0"),
    ("nis_tail", 1.5, r"nis_tail must be in \(0, 1\)"),
    ("nis_patience", 2.5, "nis_patience"),
])
def test_the_watch_refuses_a_tail_outside_0_1_and_a_fractional_patience(option, value, message):
    model = LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2), R=[[1.0]])
    with pytest.raises(ValueError, match=message):
        KalmanFilter(model, **{option: value})


def test_a_scalar_input_serves_a_one_input_model():
    """``u`` may be a number when the model has one input: the same step as ``[u]``."""
    model = LinearModel(A=np.eye(2), B=[[0.0], [1.0]], C=[[1.0, 0.0]], Q=np.eye(2), R=[[1.0]])
    a, b = KalmanFilter(model), KalmanFilter(model)
    a.step([0.3]), b.step([0.3])
    np.testing.assert_array_equal(a.step([0.1], 0.5), b.step([0.1], [0.5]))
