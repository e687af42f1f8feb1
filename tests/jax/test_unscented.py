"""fir_gym.jax.unscented against the numpy :class:`~fir_gym.estimators.unscented.
UnscentedKalmanFilter` it mirrors, step by step on the same model and data, on both numpy
paths (the reference and its compiled twin): estimate and covariance to 1e-9 relative
(``max |Δ| / max |ref|``), the NIS to ``1e-9 (1 + nis)``, the divergence flag exactly.

**Which scheme where.** The env's scheme, Merwe's α = 1e-3 (β = 2, κ = 0), is
ill-conditioned in round-off: the weights are ±2.5e5 (n = 2), so a one-ulp change of a
sigma point or of ``f(χ)`` moves ``x⁻`` by about ``ε |x| / (2 n α²)`` — and XLA's CPU
compiler contracts ``a * b + c`` into fused multiply-adds (LLVM ``AllowFPOpFusion = Fast``;
no flag turns it off) where numpy and numba round the product first. Two correct
implementations then drift apart by 1e-9 to 1e-7 over hundreds of steps: the numpy reference
and its own compiled twin differ by 9e-10 (x) and 8e-9 (NIS) on the linear system here.
So the in-process comparisons use the well-conditioned scheme :data:`WELL` (α = 1, κ = 1)
— the plants' own numpy models through ``gym.make(id, estimator="ukf")`` and a numpy
``LinearModel`` — and the env's scheme is checked in a child process with
``XLA_FLAGS=--xla_cpu_max_isa=AVX`` (no FMA instructions; the child first checks that XLA
then rounds as numpy does, and the test skips where it cannot), where the arithmetic is the
same bit for bit: Orbit-v0's own model on both numpy paths, and the linear system (the JAX
model's ``f``) on the compiled twin. The singular and indefinite covariances are checked
with the env's scheme over a few steps.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.estimators import compiled  # noqa: E402
from fir_gym.estimators.model import LinearModel, StateSpaceModel  # noqa: E402
from fir_gym.estimators.unscented import (  # noqa: E402
    MerweScaledSigmaPoints,
    UnscentedKalmanFilter,
    matrix_sqrt,
)
from fir_gym.jax import kalman as jk  # noqa: E402
from fir_gym.jax import orbit as jorbit  # noqa: E402
from fir_gym.jax import pendulum_slider as jps  # noqa: E402
from fir_gym.jax import unscented as ju  # noqa: E402
from fir_gym.jax._plant import filter_prior  # noqa: E402
from fir_gym.jax.filter_model import FilterModel  # noqa: E402

RTOL = 1e-9
STEPS = 400
#: a well-conditioned scheme (``W₀ᵐ = 1/3`` for two states): the in-process comparisons
WELL = {"alpha": 1.0, "beta": 2.0, "kappa": 1.0}
PATHS = ("numpy", "compiled") if compiled.ENABLED else ("numpy",)


@contextmanager
def numpy_path(path: str) -> Iterator[None]:
    """The numpy filters (and plant models) on their reference (``"numpy"``) or compiled path."""
    saved = compiled.ENABLED
    compiled.ENABLED = path == "compiled"
    try:
        yield
    finally:
        compiled.ENABLED = saved


# ---------------------------------------------------------------------------- the models
def linear_system() -> tuple[LinearModel, FilterModel]:
    """A damped oscillator driven by an input: the numpy model and its JAX FilterModel."""
    dt = 0.1
    A = np.array([[1.0, dt], [-0.5 * dt, 1.0 - 0.1 * dt]])
    B = np.array([[0.5 * dt * dt], [dt]])
    C = np.array([[1.0, 0.0]])
    Q = 1e-3 * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    R = np.array([[0.05]])
    model = LinearModel(A=A, B=B, C=C, Q=Q, R=R, dt=dt)
    Aj, Bj = jnp.asarray(A), jnp.asarray(B)

    def f(x: Any, u: Any) -> Any:
        return Aj @ x + Bj @ u

    return model, FilterModel(f=f, f_and_F=lambda x, u: (f(x, u), Aj), H=jnp.asarray(C),
                              Q=jnp.asarray(model.GQGT), R=jnp.asarray(R))


def orbit_model() -> FilterModel:
    """Orbit-v0's model at the nominal parameters (μ = 19.91, thrust_max 1, Δ = 1e-4, 100
    substeps; ``a = u · thrust_max`` as the numpy ``OrbitDynamics.propagate`` takes it): the
    plant's :meth:`~fir_gym.jax.orbit.Orbit.filter_model`."""
    return jorbit.Orbit().filter_model(jorbit.orbit_params())


def pendulum_slider_model(frame_skip: int = 10) -> FilterModel:
    """PendulumSlider-v0's model (``frame_skip`` RK4 steps of 1 ms, ``U = u · force_max``,
    ``H = I``) at the nominal parameters: the plant's
    :meth:`~fir_gym.jax.pendulum_slider.PendulumSlider.filter_model`."""
    return jps.PendulumSlider().filter_model(jps.pendulum_slider_params(frame_skip=frame_skip))


ENVS: dict[str, tuple[str, dict[str, Any], Callable[[], FilterModel], Callable[..., Any]]] = {
    # id, keywords, the JAX model, the prior's params
    "orbit": ("fir_gym/Orbit-v0", {}, orbit_model, jorbit.orbit_params),
    "pendulum_slider": ("fir_gym/PendulumSlider-v0", {"frame_skip": 10},
                        pendulum_slider_model,
                        lambda: jps.pendulum_slider_params(frame_skip=10)),
}


def actions(case: str, k: int, rng: np.random.Generator) -> np.ndarray:
    """An episode's actions: about the hover thrust (orbit), small pushes (pendulum)."""
    if case == "orbit":
        return np.array([0.311 + 0.3 * np.sin(k / 20) + 0.1 * rng.normal()])
    return np.array([0.3 * np.sin(k / 15) + 0.1 * rng.normal()])


def linear_data(steps: int = STEPS, seed: int = 1) -> tuple[list[np.ndarray], list[Any]]:
    """Measurements of the linear system driven by ``u = sin(k / 10)`` (none before ``y[0]``)."""
    model, _ = linear_system()
    rng = np.random.default_rng(seed)
    x, ys, us = np.array([1.0, 0.0]), [], []
    for k in range(steps):
        u = np.array([np.sin(k / 10)]) if k else None
        if k:
            x = model.A @ x + model.B @ u + rng.multivariate_normal(np.zeros(2), model.GQGT)
        ys.append(model.C @ x + np.sqrt(model.R[0, 0]) * rng.normal(size=1))
        us.append(u)
    return ys, us


LINEAR_PRIOR = (np.array([0.5, 0.2]), np.diag([1.0, 0.5]))


# ---------------------------------------------------------------------------- the drivers
Record = dict[str, list[Any]]


def empty_record() -> Record:
    return {key: [] for key in ("y", "u", "x", "P", "nis", "diverged")}


def record(est: UnscentedKalmanFilter, out: Record, y: np.ndarray, u: np.ndarray | None
           ) -> None:
    out["y"].append(np.array(y, dtype=np.float64))
    out["u"].append(None if u is None else np.array(u, dtype=np.float64))
    out["x"].append(est.x.copy())
    out["P"].append(est.P.copy())
    out["nis"].append(float(est.last_info["nis"]))
    out["diverged"].append(bool(est.diverged))


def run_env(case: str, steps: int = STEPS, seed: int = 0,
            scheme: dict[str, float] | None = None) -> Record:
    """An episode of the numpy env with ``estimator="ukf"`` (``scheme``: its α, β, κ; the
    defaults without) — what :class:`~fir_gym.wrappers.EstimatorObservation` feeds its
    filter: ``y[0]`` at reset, then ``y[k]`` with the applied ``info["action"]`` — and the
    filter after each step."""
    env_id, kwargs, _, _ = ENVS[case]
    env = gym.make(env_id, estimator="ukf", observation="estimate+measurement",
                   estimator_kwargs=scheme or {}, **kwargs)
    est = env.get_wrapper_attr("estimator")
    assert isinstance(est, UnscentedKalmanFilter) and est.redraw and est.jitter == 0.0
    out = empty_record()
    obs, _ = env.reset(seed=seed)
    record(est, out, obs["measurement"], None)
    rng = np.random.default_rng(seed)
    for k in range(1, steps):
        obs, _, terminated, truncated, info = env.step(actions(case, k, rng))
        assert not (terminated or truncated), f"{case}: the episode ended at step {k}"
        record(est, out, obs["measurement"], info["action"])
    env.close()
    return out


def run_filter(est: UnscentedKalmanFilter, ys: list[np.ndarray], us: list[Any]) -> Record:
    """The numpy filter on ``ys``/``us`` (a ``None`` input: an update only, the first step)."""
    out = empty_record()
    for y, u in zip(ys, us, strict=True):
        est.step(y, u)
        record(est, out, y, u)
    return out


def replay(ref: Record, model: FilterModel, x0: np.ndarray, P0: np.ndarray,
           scheme: dict[str, float] | None = None, b: jk.Belief | None = None
           ) -> dict[str, float]:
    """The JAX filter (jitted steps, then :func:`fir_gym.jax.kalman.watch`) on the record's
    data from ``N(x0, P0)`` (or the record ``b``): its worst errors against the numpy
    filter's record — :func:`relative` for ``x`` and ``P``, ``|Δnis| / (1 + nis)``, and
    whether a ``diverged`` flag ever differed."""
    w = ju.merwe_weights(int(np.shape(x0)[0]), **(scheme or {}))
    update = jax.jit(lambda x, P, y: ju.ukf_update(x, P, y, model, w))
    step = jax.jit(lambda x, P, y, u: ju.ukf_predict_update(x, P, y, u, model, w))
    limits = jk.watch_limits(int(model.R.shape[0]))
    b = jk.belief(jnp.asarray(x0), jnp.asarray(P0)) if b is None else b
    worst = {"x": 0.0, "P": 0.0, "nis": 0.0, "flags": 0.0}
    for k, (y, u) in enumerate(zip(ref["y"], ref["u"], strict=True)):
        out = update(b.x, b.P, jnp.asarray(y)) if u is None else \
            step(b.x, b.P, jnp.asarray(y), jnp.asarray(u))
        b = jk.watch(b, *out, limits)
        worst["x"] = max(worst["x"], relative(b.x, ref["x"][k]))
        worst["P"] = max(worst["P"], relative(b.P, ref["P"][k]))
        nis, want = float(b.nis), ref["nis"][k]
        worst["nis"] = max(worst["nis"], 0.0 if np.isnan(nis) and np.isnan(want)
                           else abs(nis - want) / (1.0 + abs(want)))
        worst["flags"] = max(worst["flags"], float(bool(b.diverged) != ref["diverged"][k]))
    return worst


def relative(got: Any, want: np.ndarray) -> float:
    """``max |got − want| / max |want|`` (inf where either holds a NaN)."""
    diff = float(np.max(np.abs(np.asarray(got) - want)))
    scale = float(np.max(np.abs(want)))
    if not np.isfinite(diff):
        return float("inf")
    return diff / scale if scale > 0 else diff


def assert_agree(worst: dict[str, float], label: Any) -> None:
    assert worst["x"] <= RTOL and worst["P"] <= RTOL and worst["nis"] <= RTOL, (label, worst)
    assert worst["flags"] == 0.0, (label, worst)


def fma_contracted() -> bool:
    """Whether XLA fuses ``a * b + c`` into one rounding here (``1 − 2⁻⁶⁰`` survives)."""
    a, b, c = 1.0 + 2.0 ** -30, 1.0 - 2.0 ** -30, -1.0
    return float(jax.jit(lambda a, b, c: a * b + c)(a, b, c)) != 0.0


def numpy_model_of(model: FilterModel) -> StateSpaceModel:
    """A numpy model whose ``f`` is the JAX model's (jitted over the points) and ``h = H x``."""
    f_points = jax.jit(jax.vmap(model.f))
    H = np.asarray(model.H)
    return StateSpaceModel(f=lambda X, U: np.asarray(f_points(jnp.asarray(X), jnp.asarray(U))),
                           h=lambda X: X @ H.T, Q=np.asarray(model.Q), R=np.asarray(model.R),
                           n_u=1)


def measure_default_scheme() -> dict[str, dict[str, float]]:
    """The JAX UKF against the numpy one with the env's scheme (α = 1e-3, β = 2, κ = 0), run
    by the child process (module docstring): Orbit-v0 through ``gym.make(..., estimator=
    "ukf")`` on each numpy path, and the linear system with the JAX model's ``f`` on the
    compiled twin."""
    out = {}
    _, _, make_model, make_params = ENVS["orbit"]
    model = make_model()
    x0, P0 = (np.asarray(a) for a in filter_prior(make_params()))
    for path in PATHS:
        with numpy_path(path):
            ref = run_env("orbit")
        out[f"orbit/{path}"] = replay(ref, model, x0, P0)
    if "compiled" in PATHS:
        _, jmodel = linear_system()
        ys, us = linear_data()
        with numpy_path("compiled"):
            ref = run_filter(UnscentedKalmanFilter(numpy_model_of(jmodel), x0=LINEAR_PRIOR[0],
                                                   P0=LINEAR_PRIOR[1]), ys, us)
        out["linear/compiled"] = replay(ref, jmodel, *LINEAR_PRIOR)
    return out


# ---------------------------------------------------------------------------- the tests
@pytest.mark.parametrize("n", [1, 2, 3, 4, 7])
@pytest.mark.parametrize("alpha,beta,kappa", [(1e-3, 2.0, 0.0), (0.5, 2.0, 1.0),
                                              (1.0, 0.0, 3.0)])
def test_weights_are_the_numpy_weights(n: int, alpha: float, beta: float, kappa: float
                                       ) -> None:
    sp = MerweScaledSigmaPoints(n, alpha, beta, kappa)
    w = ju.merwe_weights(n, alpha, beta, kappa)
    for a, b in ((w.xi, sp.xi), (w.Wm, sp.Wm), (w.Wc, sp.Wc)):
        np.testing.assert_array_equal(a, b)
    assert w.sum_Wc == sp.sum_Wc and w.same_tail == sp.same_tail
    with pytest.raises(ValueError, match="n must be"):
        ju.merwe_weights(0)


@pytest.mark.parametrize("path", PATHS)
def test_linear_model_follows_the_numpy_ukf(path: str) -> None:
    """The numpy ``LinearModel`` (a driven damped oscillator), 400 steps."""
    model, jmodel = linear_system()
    ys, us = linear_data()
    with numpy_path(path):
        ref = run_filter(UnscentedKalmanFilter(model, x0=LINEAR_PRIOR[0], P0=LINEAR_PRIOR[1],
                                               **WELL), ys, us)
    assert_agree(replay(ref, jmodel, *LINEAR_PRIOR, WELL), path)
    assert not ref["diverged"][-1]


@pytest.mark.parametrize("case", ["orbit", "pendulum_slider"])
def test_plant_models_follow_the_numpy_ukf(case: str) -> None:
    """Each plant's own numpy model, filtering an episode of ``gym.make(id, estimator="ukf")``
    (Orbit-v0: 400 steps; PendulumSlider-v0, ``frame_skip=10``: 300) against the JAX
    model, on each numpy path."""
    _, _, make_model, make_params = ENVS[case]
    x0, P0 = (np.asarray(a) for a in filter_prior(make_params()))
    for path in PATHS:
        with numpy_path(path):
            ref = run_env(case, STEPS if case == "orbit" else 300, scheme=WELL)
        assert_agree(replay(ref, make_model(), x0, P0, WELL), (case, path))


def test_the_envs_scheme_without_fma() -> None:
    """The env's own scheme (α = 1e-3), in a child process whose XLA emits no fused
    multiply-adds (module docstring): Orbit-v0's own model through ``gym.make(...,
    estimator="ukf")`` on each numpy path, and the linear system (the JAX ``f``) on the
    compiled twin, to 1e-9."""
    code = (
        "import importlib.util, json, sys\n"
        f"spec = importlib.util.spec_from_file_location('ukf_parity', {__file__!r})\n"
        "m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)\n"
        "if m.fma_contracted(): print(json.dumps('fma')); sys.exit(0)\n"
        "print(json.dumps(m.measure_default_scheme()))\n")
    env = dict(os.environ)
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " --xla_cpu_max_isa=AVX").strip()
    done = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True,
                          env=env, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if result == "fma":
        pytest.skip("XLA contracts multiply-adds even with --xla_cpu_max_isa=AVX here")
    want = {f"orbit/{p}" for p in PATHS} | ({"linear/compiled"} if "compiled" in PATHS else set())
    assert set(result) == want
    for label, worst in result.items():
        assert_agree(worst, label)


def test_a_semidefinite_covariance_takes_the_eigen_square_root() -> None:
    """A singular PSD ``P`` (a state known exactly along a direction): Cholesky fails and both
    filters take ``V Λ₊^½``; the reset update from such a prior and the steps after it
    agree (the env's scheme, α = 1e-3)."""
    for P in (np.array([[1.0, 1.0], [1.0, 1.0]]), np.diag([2.0, 0.0]),
              np.array([[4.0, 2.0], [2.0, 1.0]])):
        S = matrix_sqrt(P[None])[0]
        Sj = np.asarray(jax.jit(ju.matrix_sqrt)(jnp.asarray(P)))
        assert not np.isfinite(np.asarray(jnp.linalg.cholesky(jnp.asarray(P)))).all()
        assert np.isfinite(S).all() and np.isfinite(Sj).all()
        np.testing.assert_allclose(Sj @ Sj.T, P, rtol=0, atol=1e-15)
        np.testing.assert_allclose(Sj @ Sj.T, S @ S.T, rtol=0, atol=1e-15)
    model, jmodel = linear_system()
    x0, P0 = np.array([0.3, -0.2]), np.array([[1.0, 1.0], [1.0, 1.0]])
    ys, us = linear_data(6, seed=3)
    for path in PATHS:
        with numpy_path(path):
            ref = run_filter(UnscentedKalmanFilter(model, x0=x0, P0=P0), ys, us)
        assert_agree(replay(ref, jmodel, x0, P0), path)
        assert np.isfinite(ref["nis"][0]) and not ref["diverged"][-1]


def test_an_indefinite_covariance_is_nan_and_the_watch_keeps_the_estimate() -> None:
    """An indefinite ``P`` has no square root: numpy's points, estimate and covariance are not
    finite, its watch keeps the last estimate and raises ``diverged``; the JAX steps return
    NaN and :func:`fir_gym.jax.kalman.watch` keeps the same estimate, flags the same."""
    model, jmodel = linear_system()
    bad = np.array([[1.0, 0.0], [0.0, -0.5]])
    assert not np.isfinite(matrix_sqrt(bad[None])).all()
    assert np.isnan(np.asarray(ju.matrix_sqrt(jnp.asarray(bad)))).all()
    for out in (jax.jit(lambda x, P, y: ju.ukf_update(x, P, y, jmodel))(
                    jnp.zeros(2), jnp.asarray(bad), jnp.ones(1)),
                jax.jit(lambda x, P, y, u: ju.ukf_predict_update(x, P, y, u, jmodel))(
                    jnp.zeros(2), jnp.asarray(bad), jnp.ones(1), jnp.ones(1))):
        assert all(np.isnan(np.asarray(o)).all() for o in out)
    ys, us = linear_data(8, seed=4)
    x0, P0 = LINEAR_PRIOR
    for path in PATHS:
        with numpy_path(path):
            est = UnscentedKalmanFilter(model, x0=x0, P0=P0)
            head = run_filter(est, ys[:3], us[:3])
            est.state.P[...] = bad                   # the live record, as if a step left it
            tail = run_filter(est, ys[3:], us[3:])
        assert tail["diverged"][0] and np.isnan(tail["nis"][0])
        np.testing.assert_array_equal(tail["x"][-1], head["x"][-1])        # kept
        np.testing.assert_array_equal(tail["P"][-1], bad)
        assert_agree(replay(head, jmodel, x0, P0), path)
        kept = jk.Belief(jnp.asarray(head["x"][-1]), jnp.asarray(bad),
                         jnp.asarray(head["nis"][-1]), jnp.asarray(0), jnp.asarray(False))
        worst = replay(tail, jmodel, x0, P0, b=kept)
        assert worst["x"] == 0.0 and worst["P"] == 0.0 and worst["flags"] == 0.0, worst


def test_jit_and_vmap_over_a_batch_are_the_single_steps() -> None:
    """``vmap`` over 8 systems gives each system's own jitted step (linear and orbit)."""
    _, jmodel = linear_system()
    rng = np.random.default_rng(5)
    for m, center, spread in ((jmodel, np.zeros(2), 1.0),
                              (orbit_model(), np.array([8.0, 0.5]), 1e-2)):
        B = 8
        x = jnp.asarray(center + spread * rng.normal(size=(B, 2)))
        L = spread * rng.normal(size=(B, 2, 2))
        P = jnp.asarray(L @ L.mT + spread ** 2 * 1e-3 * np.eye(2))
        y = jnp.asarray(center[:1] + spread * rng.normal(size=(B, 1)))
        u = jnp.asarray(rng.uniform(-1, 1, size=(B, 1)))

        def step(x: Any, P: Any, y: Any, u: Any, m: FilterModel = m) -> Any:
            return ju.ukf_predict_update(x, P, y, u, m)

        def update(x: Any, P: Any, y: Any, m: FilterModel = m) -> Any:
            return ju.ukf_update(x, P, y, m)

        pairs = ((jax.jit(jax.vmap(step))(x, P, y, u), jax.jit(step), (x, P, y, u)),
                 (jax.jit(jax.vmap(update))(x, P, y), jax.jit(update), (x, P, y)))
        for got, single, args in pairs:
            for i in range(B):
                want = single(*(a[i] for a in args))
                for g, w_ in zip(got, want, strict=True):
                    assert np.isfinite(np.asarray(w_)).all()
                    assert relative(g[i], np.asarray(w_)) <= 1e-12, (m, i)
