"""The extended FIR filter's step: a single system is a batch of one, bit for bit, on the
compiled twins and on the numpy reference alike, and the compiled step equals the numpy
reference to round-off.

One system given as ``(n_y,)`` against the same system as a batch of one ``(1, n_y)``,
step by step — estimates, covariances, flags and the whole internal state (nominal,
window bank) — through start-up, full windows, skipped measurements, restarts,
rank-deficient windows and divergence, in both forms and with both nominals, on models
with and without inputs, process noise, analytic Jacobians and with more than one
output. Every step of a run takes the path the run chose (no step hands back to the
numpy reference).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from compiled_paths import TWINS, needs_twins, numpy_path
from estimator_checks import assert_rejects_bad_input
from sample_models import duffing_model, random_linear_3x1

import fir_gym  # noqa: F401  (registers the environments)
from fir_gym.benchmarks.fir import sim2_model
from fir_gym.estimators import LinearModel, StateSpaceModel
from fir_gym.estimators.efir import ExtendedFIRFilter

FORMS = ("filter", "predictor")
NOMINALS = ("open-loop", "reanchor")


def pendulum_model() -> StateSpaceModel:
    """A damped pendulum driven by ``u``, ``y = sin θ``: finite-difference Jacobians."""
    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.stack([x[..., 0] + 0.05 * x[..., 1],
                         x[..., 1] - 0.05 * (np.sin(x[..., 0]) + 0.2 * x[..., 1]) + u[..., 0]],
                        -1)

    return StateSpaceModel(f=f, h=lambda x: np.sin(x[..., :1]), Q=[[1e-3]], R=[[0.01]],
                           G=[[0.0], [1.0]], n_u=1)


def scalar_model() -> StateSpaceModel:
    """One state (``n = 1``: every product is a single multiplication), analytic Jacobians."""
    return StateSpaceModel(f=lambda x, u: x + 0.1 * np.sin(x) + 0.05 * u,
                           F=lambda x, u: (1.0 + 0.1 * np.cos(x))[..., None],
                           h=lambda x: x + 0.2 * x**2, H=lambda x: (1.0 + 0.4 * x)[..., None],
                           Q=[[1e-3]], R=[[0.05]], n_u=1)


def linear_model() -> LinearModel:
    return random_linear_3x1(1.02)


def orbit_model() -> StateSpaceModel:
    """Orbit-v0's model: ``Q = 0`` (no process noise in the windows), a fused ``fF``."""
    env = gym.make("fir_gym/Orbit-v0")
    model = env.unwrapped.model
    env.close()
    return model


def same(a: Any, b: Any) -> bool:
    """Bit for bit (NaN equal to NaN, ``-0.0`` not equal to ``0.0``)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8))


PATHS = ("twin", "numpy")


def count_steps(flt: ExtendedFIRFilter, counter: dict[str, int]) -> None:
    """Count the steps ``flt`` takes on the compiled twin and on the numpy reference."""
    for name, key in (("_compiled_update", "twin"), ("_compiled_predict_update", "twin"),
                      ("_numpy_step", "numpy")):
        original = getattr(flt, name)

        def counted(*args: Any, _original: Any = original, _key: str = key) -> Any:
            counter[_key] += 1
            return _original(*args)
        setattr(flt, name, counted)


def run_pair(make: Callable[[], ExtendedFIRFilter], ys: np.ndarray, us: np.ndarray | None,
             between: Callable[[int, ExtendedFIRFilter], None] | None = None,
             path: str = "twin") -> tuple[dict[str, int], ExtendedFIRFilter]:
    """Step a single-system filter and its batch-of-one twin on the same data on ``path``;
    assert they agree bit for bit after every step; return how many steps took each path."""
    single, batch = make(), make()
    counter = {"twin": 0, "numpy": 0}
    count_steps(single, counter)
    for k, y in enumerate(ys):
        u = None if us is None or k == 0 else us[k]
        if path == "twin":
            xs, xb = single.step(y, u), batch.step(y[None], None if u is None else u[None])
        else:
            with numpy_path():
                xs, xb = single.step(y, u), batch.step(y[None], None if u is None else u[None])
        assert same(xs, xb[0]), k
        assert same(single.P, batch.P[0]), k
        assert same(single.x_nominal, batch.x_nominal[0]), k
        assert single.diverged == bool(batch.diverged[0]), k
        info_s, info_b = single.last_info, batch.last_info
        assert info_s.keys() == info_b.keys(), k
        # the one-step innovation test (estimators/_consistency.py): a float per system
        assert same(np.array([info_s["nis"]]), np.asarray(info_b["nis"])[:1]), k
        for key in ("startup", "rank_deficient", "diverged"):
            assert info_s[key] == bool(np.asarray(info_b[key])[0]), (k, key)
        assert same(single._bank.Z, batch._bank.Z), k
        assert same(single._nom, batch._nom), k
        assert same(single._age, batch._age), k
        if between is not None:
            between(k, single)
            between(k, batch)
    taken = "twin" if path == "twin" and TWINS else "numpy"
    assert counter[taken] == len(ys) and counter[
        "numpy" if taken == "twin" else "twin"] == 0, counter
    return counter, single


def noisy(rng: np.random.Generator, steps: int, n_y: int, level: float = 0.3,
          center: float = 0.0) -> np.ndarray:
    return center + level * rng.standard_normal((steps, n_y))


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("nominal", NOMINALS)
@pytest.mark.parametrize("form", FORMS)
def test_benchmark_model_through_startup_full_windows_and_divergence(form: str, nominal: str,
                                                                     path: str) -> None:
    """The speed benchmark's model (paper 000 sim 2) on its kind of data: healthy windows
    first, then windows that barely see x₂ (the nominal settles where ``∂f/∂x₂ ≈ 0``),
    with inverses near 1e33 and a covariance past ``max_covariance_trace``."""
    ys = noisy(np.random.default_rng(1), 1500, 1, center=0.48)

    def make() -> ExtendedFIRFilter:
        return ExtendedFIRFilter(sim2_model(), horizon=10, form=form, nominal=nominal,
                                 x0=[0.0, 0.0, 0.5])
    _, flt = run_pair(make, ys, None, path=path)
    assert flt.diverged


CASES = {  # model, its nominal's start x0, the measurements' centre and spread
    "pendulum (finite differences)": (pendulum_model, [0.3, 0.0], 0.0, 0.5),
    "duffing (two outputs)": (duffing_model, [0.5, 0.0, 1.0], 0.0, 0.3),
    "linear": (linear_model, None, 0.0, 0.5),
    "scalar (n = 1)": (scalar_model, [0.4], 0.4, 0.2),
    "orbit (Q = 0, fused fF)": (orbit_model, [7.997, 1.992], 8.0, 0.03),
}


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("nominal", NOMINALS)
@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("case", list(CASES))
def test_models_with_time_varying_inputs(case: str, form: str, nominal: str, path: str
                                         ) -> None:
    model, x0, center, spread = CASES[case]
    m = model()
    rng = np.random.default_rng(7)
    ys = noisy(rng, 160, m.n_y, spread, center)
    us = 0.2 * rng.standard_normal((160, m.n_u))

    def make() -> ExtendedFIRFilter:
        return ExtendedFIRFilter(m, horizon=6, form=form, nominal=nominal, x0=x0)
    run_pair(make, ys, us, path=path)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("nominal", NOMINALS)
@pytest.mark.parametrize("form", FORMS)
def test_skipped_measurements_and_restarts(form: str, nominal: str, path: str) -> None:
    """NaN measurements (``nan_policy='skip'``), restarts and a reset stay on the run's
    path."""
    rng = np.random.default_rng(3)
    ys = noisy(rng, 200, 1, 0.5)
    ys[[9, 40, 41, 77, 150]] = np.nan
    us = 0.1 * rng.standard_normal((200, 1))

    def between(k: int, flt: ExtendedFIRFilter) -> None:
        if k == 60:
            flt.restart([0])
        elif k == 120:
            flt.restart(np.array([True]))
        elif k == 170:
            flt.reset(x0=[0.1, -0.2])

    def make() -> ExtendedFIRFilter:
        return ExtendedFIRFilter(pendulum_model(), horizon=8, form=form, nominal=nominal,
                                 nan_policy="skip", x0=[0.3, 0.0])
    run_pair(make, ys, us, between, path=path)


def _draining(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``x1`` kept, ``x2`` lowered by 0.25 a step down to 0 (then kept at 0)."""
    return np.concatenate([x[..., :1], np.maximum(x[..., 1:] - 0.25, 0.0)], axis=-1)


@pytest.mark.parametrize("path", PATHS)
def test_rank_deficient_windows_fall_back(path: str) -> None:
    """``y = x1·x2`` seen from a nominal with ``x2 = 0`` carries no information on ``x1``:
    such windows are read out through the documented fallback. (The nominal starts at
    ``x2 = 1`` and reaches ``x2 = 0`` after four steps: a nominal that is unobservable
    from the start is refused at construction, the one observability rule.)"""
    model = StateSpaceModel(f=_draining, h=lambda x: x[..., :1] * x[..., 1:],
                            Q=1e-4 * np.eye(2), R=[[0.01]])
    ys = noisy(np.random.default_rng(4), 30, 1, 0.1)

    def make() -> ExtendedFIRFilter:
        return ExtendedFIRFilter(model, horizon=4, x0=[1.0, 1.0])
    _, flt = run_pair(make, ys, None, path=path)
    assert flt.last_info["rank_deficient"] and not flt.last_info["startup"]


@pytest.mark.parametrize("path", PATHS)
def test_covariance_over_the_limit_flags_divergence(path: str) -> None:
    """The benchmark model's covariance grows past a limit well after start-up: the step
    flags it (and keeps the estimate, which is finite)."""
    ys = noisy(np.random.default_rng(1), 300, 1, center=0.48)
    flagged: list[int] = []

    def watch(k: int, flt: ExtendedFIRFilter) -> None:
        if flt.diverged is True and not flagged:
            flagged.append(k)

    def make() -> ExtendedFIRFilter:
        return ExtendedFIRFilter(sim2_model(), horizon=10, x0=[0.0, 0.0, 0.5],
                                 max_covariance_trace=1e8)
    _, flt = run_pair(make, ys, None, watch, path=path)
    assert flt.diverged and flagged[0] > 20
    assert np.isfinite(flt.x).all() and np.trace(flt.P) > 1e8


@pytest.mark.parametrize("path", PATHS)
def test_non_finite_estimates_keep_the_last_finite_one(path: str) -> None:
    """An exploding model: the estimate overflows; the last finite one is kept."""
    model = LinearModel(A=[[40.0, 1.0], [0.0, 30.0]], C=[[1.0, 0.0]], Q=0.01 * np.eye(2),
                        R=[[0.1]])
    ys = noisy(np.random.default_rng(6), 400, 1, 1.0)

    def make() -> ExtendedFIRFilter:
        return ExtendedFIRFilter(model, horizon=4, x0=[1.0, 1.0])
    _, flt = run_pair(make, ys, None, path=path)
    assert flt.diverged and np.isfinite(flt.x).all()


def test_inputs_of_other_shapes_and_bad_inputs() -> None:
    """Lists, scalars and ``(1, n_u)`` inputs step like arrays; NaN, inf and wrong shapes are
    skipped or raised as documented."""
    a = ExtendedFIRFilter(pendulum_model(), horizon=4, x0=[0.2, 0.0])
    b = ExtendedFIRFilter(pendulum_model(), horizon=4, x0=[0.2, 0.0])
    rng = np.random.default_rng(8)
    for k in range(12):
        y, u = 0.3 * rng.standard_normal(1), 0.1 * rng.standard_normal(1)
        forms = [u, float(u[0]), u[None], list(u)]
        xa = a.step(list(y) if k % 2 else y, None if k == 0 else forms[k % 4])
        xb = b.step(y[None], None if k == 0 else u[None])
        assert same(xa, xb[0]) and same(a.P, b.P[0])
    assert_rejects_bad_input(a)
    with pytest.raises(ValueError, match="u must"):
        a.step(np.zeros(1), [0.0, 1.0])


def test_returned_estimate_is_a_copy() -> None:
    flt = ExtendedFIRFilter(linear_model(), horizon=3)
    for _ in range(6):
        x = flt.step(np.ones(1), np.zeros(1))
    x[:] = 1e9
    assert np.all(np.abs(flt.x) < 1e8)


def test_a_subclass_that_overrides_the_watch_steps_on_numpy() -> None:
    """The compiled step is the same pass (``_advance``, ``_readout`` overrides run in it)
    with the compiled watch; a subclass with its own ``_accept`` steps on numpy."""
    calls: list[int] = []

    class Custom(ExtendedFIRFilter):
        def _accept(self, *args: Any) -> None:
            calls.append(1)
            super()._accept(*args)

    assert ExtendedFIRFilter.has_compiled_step and not Custom.has_compiled_step
    flt = Custom(linear_model(), horizon=3)
    flt.step(np.zeros(1))
    assert calls == [1]


def window_condition(flt: ExtendedFIRFilter, w: int) -> float:
    """The largest finite condition number over the batch of window ``w``'s information
    matrix (a singular one is not inverted: its system falls back)."""
    n = flt.model.n_x
    F = -flt._bank.Z[:, n:, w, n:2 * n]                      # type: ignore[union-attr]
    with np.errstate(all="ignore"):
        kappa = np.linalg.cond(F)
    return float(np.max(kappa[np.isfinite(kappa)], initial=1.0))


@needs_twins
@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("case", [c for c in CASES if "finite differences" not in c])
@pytest.mark.parametrize("batch", [None, 3])
def test_compiled_step_equals_numpy_reference(case: str, form: str, batch: int | None
                                              ) -> None:
    """The compiled step (the bank's compiled operations and the compiled watch) against the
    numpy reference on the paper's open-loop nominal, with skipped measurements and a
    restart. The two sum in other orders, and the read-out ``T F⁻¹ b`` amplifies that
    round-off by the window's condition number ``κ(F)`` (perturbation theory of a linear
    solve: a relative error of order ``eps·κ``); the bound is 1e-12 relative to the size
    of the numbers up to ``κ = 1e3`` and ``1e-15 κ`` (≈ 5 eps κ) beyond. Not here: the
    finite-difference model, whose Jacobians amplify the last bits of the nominal by
    ``1/step ≈ 2e5``, and the re-anchored nominal, which feeds every read-out's round-off
    into later windows' linearisations — both are run on each path above (against the
    batch of one, bit for bit), and the bank's per-window operations are checked against
    the numpy bank in test_compiled.py."""
    model, x0, center, spread = CASES[case]
    m = model()
    L = 6
    rng = np.random.default_rng(17)
    lead = () if batch is None else (batch,)
    ys = center + spread * rng.standard_normal((120, *lead, m.n_y))
    ys[[30, 31]] = np.nan
    us = 0.2 * rng.standard_normal((120, *lead, m.n_u))
    twin = ExtendedFIRFilter(m, horizon=L, form=form, x0=x0, nan_policy="skip")
    ref = ExtendedFIRFilter(m, horizon=L, form=form, x0=x0, nan_policy="skip")
    for k in range(120):
        u = None if k == 0 else us[k]
        if k == 70 and batch:
            twin.restart([1])
            ref.restart([1])
        w_out = max(0, k - L + (form == "filter")) % L
        kappa = window_condition(ref, w_out) if form == "predictor" and k >= L else 1.0
        xt = twin.step(ys[k], u)
        with numpy_path():
            xr = ref.step(ys[k], u)
        if form == "filter" and k >= L - 1:
            kappa = window_condition(ref, w_out)
        tol = max(1e-12, 1e-15 * kappa)
        scale = max(1.0, float(np.abs(xr).max()))
        np.testing.assert_allclose(xt, xr, rtol=0, atol=tol * scale)
        np.testing.assert_allclose(twin.P, ref.P, rtol=0,
                                   atol=tol * max(1.0, float(np.abs(ref.P).max())))
        np.testing.assert_array_equal(twin.diverged, ref.diverged)
        for key in ("startup", "rank_deficient"):
            np.testing.assert_array_equal(twin.last_info[key], ref.last_info[key])
