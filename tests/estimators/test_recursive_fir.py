"""RecursiveFIRFilter (paper 004 §IV, corrected): equal to the direct form, then round-off."""

from __future__ import annotations

import numpy as np
import pytest

from fir_gym.estimators import LinearModel
from fir_gym.estimators.fir import FIRFilter
from fir_gym.estimators.fir_smoother import FIRSmoother
from fir_gym.estimators.recursive_fir import RecursiveFIRFilter
from fir_gym.estimators.registry import make_estimator

A = np.array([[1.0, 0.1], [-0.3, 0.9]])
C = np.array([[1.0, 0.0]])


def model(inputs: bool = True) -> LinearModel:
    return LinearModel(A=A, C=C, B=[[0.0], [0.1]] if inputs else None, Q=0.05 * np.eye(2),
                       R=[[0.5]])


def data(steps: int, inputs: bool, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    m = model(inputs)
    x, ys, us = rng.normal(size=2), [], rng.normal(size=(steps, 1))
    for k in range(steps):
        ys.append(C @ x + 0.7 * rng.normal(size=1))
        x = A @ x + (m.B @ us[k] if inputs else 0.0) + 0.2 * rng.normal(size=2)
    return np.array(ys), us


def deviation(reinit_every: int | str | None, prior: str | None, steps: int
              ) -> tuple[np.ndarray, np.ndarray, RecursiveFIRFilter]:
    """|recursive − direct| per step, for the filter and the smoother."""
    inputs = prior is None
    m = model(inputs)
    ys, us = data(steps, inputs)
    r = RecursiveFIRFilter(m, horizon=8, prior=prior, reinit_every=reinit_every)
    f, s = FIRFilter(m, horizon=8, prior=prior), FIRSmoother(m, horizon=8, prior=prior)
    df, ds = [], []
    for k, y in enumerate(ys):
        u = us[k - 1] if (k and inputs) else None
        a, b, c = r.step(y, u), f.step(y, u), s.step(y, u)
        scale = max(1.0, np.abs(b).max())
        df.append(np.abs(a - b).max() / scale)
        ds.append(np.nan if r.x_smoothed is None else np.abs(r.x_smoothed - c).max() / scale)
    return np.array(df), np.array(ds), r


@pytest.mark.parametrize("prior", [None, "stationary"], ids=["cor4.1", "thm4.1"])
def test_equals_direct_filter_and_smoother_on_the_first_steps(prior: str | None) -> None:
    df, ds, _ = deviation(None, prior, 20)
    assert df.max() <= 1e-11 and np.nanmax(ds) <= 1e-11


@pytest.mark.parametrize("prior", [None, "stationary"], ids=["cor4.1", "thm4.1"])
def test_round_off_grows_without_reinitialisation_and_not_with_it(prior: str | None) -> None:
    df, _, r = deviation(None, prior, 150)
    assert r.spectral_radius > 1.0
    assert df[140:].max() > 1e4 * max(df[7:17].max(), 1e-16)   # orders of magnitude
    assert df[140:].max() > 1e-7                                # far beyond round-off
    df10, ds10, _ = deviation(10, prior, 150)
    assert df10.max() <= 1e-11 and np.nanmax(ds10) <= 1e-11
    dfa, _, ra = deviation("auto", prior, 150)
    assert ra.reinit_every is not None
    assert dfa.max() <= 1e-15 * 1e6 * 10                       # growth capped at AUTO_GROWTH


def test_transition_eigenvalues_come_in_reciprocal_pairs() -> None:
    r = RecursiveFIRFilter(model(), horizon=8)
    lam = np.sort(np.abs(np.linalg.eigvals(r.transition)))
    assert np.allclose(lam * lam[::-1], 1.0, rtol=1e-8)


def test_printed_M4_does_not_reproduce_the_direct_filter() -> None:
    """Erratum: eq (4.13)'s printed M4 = [A − H_s(−N) C A] H(N) C M2 breaks the recursion."""
    m = model(inputs=False)
    r = RecursiveFIRFilter(m, horizon=8, reinit_every=None)
    n = 2
    H, Hs = r._G[:, :, :1], r._Gs[:, :, :1]
    HN, Hs0, HsN = H[:, 0], Hs[:, 0], Hs[:, -1]
    M2 = np.linalg.inv(np.eye(n) - Hs0 @ C)
    printed = (A - HsN @ C @ A) @ HN @ C @ M2
    assert not np.allclose(printed, r.transition[n:, n:], atol=1e-3)
    ys, _ = data(12, inputs=False)
    f = FIRFilter(m, horizon=8)
    direct = [f.step(y) for y in ys]
    M = r._M.copy()                                       # rows act on [f, s, z⁺, z⁻]
    M[n:2 * n, n:] = printed.T                            # printed M4 …
    M[2 * n + 1, n:] = (-printed @ Hs0).T[0]              # … and printed z(i−N) weight
    s = FIRSmoother(m, horizon=8)
    sm = [s.step(y) for y in ys]
    fs = np.concatenate([direct[7], sm[7]])
    for k in range(8, 12):
        fs = np.concatenate([fs, ys[k], ys[k - 8]]) @ M
    assert np.abs(fs[:n] - direct[11]).max() > 1e-3


def test_arguments_and_registry() -> None:
    assert isinstance(make_estimator("rfir", model(), horizon=5), RecursiveFIRFilter)
    with pytest.raises(ValueError, match="invertible A"):
        RecursiveFIRFilter(LinearModel(A=[[1.0, 1.0], [0.0, 0.0]], C=C, Q=np.eye(2), R=[[1.0]]),
                           horizon=5)
    with pytest.raises(ValueError, match="nan_policy"):
        RecursiveFIRFilter(model(), horizon=5, nan_policy="skip")
    with pytest.raises(ValueError, match="horizon >= 3"):
        RecursiveFIRFilter(model(), horizon=2)               # one sample cannot fix 2 states
    with pytest.raises(ValueError, match="without inputs"):
        RecursiveFIRFilter(model(), horizon=5, prior="stationary")


def test_batch_in_lockstep_equals_separate_filters() -> None:
    rng = np.random.default_rng(1)
    Y, U = rng.normal(size=(40, 3, 1)), rng.normal(size=(40, 3, 1))
    together = RecursiveFIRFilter(model(), horizon=6, reinit_every=15)
    out = np.array([together.step(Y[k], U[k - 1] if k else None) for k in range(40)])
    for b in range(3):
        alone = RecursiveFIRFilter(model(), horizon=6, reinit_every=15)
        sep = np.array([alone.step(Y[k, b], U[k - 1, b] if k else None) for k in range(40)])
        assert np.abs(out[:, b] - sep).max() <= 1e-12 * max(1.0, np.abs(sep).max())


def test_a_missing_measurement_is_refused_not_read_as_zero() -> None:
    """The recursion has no missing-data form: step(None), a masked row and a NaN row are
    refused naming y (before, the window read them as 0), and the filter goes on as if the
    refused call had not happened (it equals a twin that never saw it)."""
    ys, us = data(12, True)
    r, twin = RecursiveFIRFilter(model(), horizon=4), RecursiveFIRFilter(model(), horizon=4)
    for k in range(6):
        u = us[k - 1] if k else None
        r.step(ys[k], u)
        twin.step(ys[k], u)
    assert not RecursiveFIRFilter.accepts_missing
    for missing in (None, np.ma.masked_array(ys[6], mask=[True])):
        with pytest.raises(ValueError, match=r"y: RecursiveFIRFilter needs every measurement"):
            r.step(missing, us[5])
    for k in range(6, 12):
        np.testing.assert_array_equal(r.step(ys[k], us[k - 1]), twin.step(ys[k], us[k - 1]))
