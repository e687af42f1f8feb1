"""fir_gym.jax.fir against the numpy FIR filters it mirrors
(:class:`fir_gym.estimators.efir.ExtendedFIRFilter`, configured as the fir-gym envs build it:
``startup="prior"``, ``form="filter"``, ``nominal="open-loop"``), on the same model and the
same measurements, step by step: the estimate and covariance the divergence watch keeps, the
NIS, the sticky ``diverged`` flag and the start-up / rank-deficient flags — over hundreds of
steps (start-up and full windows), on a linear model with an input and ``Q ≠ 0`` (one and
two channels), on Orbit-v0 (``Q = 0``; the numpy env's own filter in a closed-loop episode,
horizons 50 and 5, and a model far wrong about its sensor, which the watch flags), on a
model whose window loses rank (the fallback), and batched under ``jit`` + ``vmap``; and the
linear :class:`fir_gym.estimators.fir.FIRFilter` (its fixed gain against the staggered bank)
on the linear model and in a numpy CarrierMotion-v0 episode."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import fir_gym  # noqa: E402,F401  (registers the envs)
from fir_gym.estimators import _consistency, _fir_bank  # noqa: E402
from fir_gym.estimators.efir import ExtendedFIRFilter  # noqa: E402
from fir_gym.estimators.fir import FIRFilter  # noqa: E402
from fir_gym.estimators.model import LinearModel, StateSpaceModel  # noqa: E402
from fir_gym.jax import fir as jf  # noqa: E402
from fir_gym.jax import kalman as jk  # noqa: E402
from fir_gym.jax.filter_model import FilterModel  # noqa: E402
from fir_gym.jax.orbit import orbit_interval  # noqa: E402

RTOL = 1e-9


def numpy_record(est: Any) -> dict[str, Any]:
    """What the numpy filter holds after a step (its watch's record and ``last_info``)."""
    info = est.last_info
    return {"x": est.x.copy(), "P": est.P.copy(), "nis": float(info["nis"]),
            "diverged": bool(est.diverged), "startup": bool(info["startup"]),
            "rank_deficient": bool(info["rank_deficient"])}


def run_numpy(est: Any, ys: np.ndarray, us: np.ndarray) -> list[dict[str, Any]]:
    """The numpy filter over ``y[0..K]`` with ``u[0..K-1]`` (``step(y0)``, then ``step(y, u)``
    — :class:`fir_gym.wrappers.EstimatorObservation`'s calls)."""
    est.step(ys[0])
    out = [numpy_record(est)]
    for k in range(1, len(ys)):
        est.step(ys[k], us[k - 1])
        out.append(numpy_record(est))
    return out


#: the filters' (start, update, predict_update)
KINDS = {"efir": (jf.efir_start, jf.efir_update, jf.efir_predict_update),
         "fir": (jf.fir_start, jf.fir_update, jf.fir_predict_update)}


def jax_steps(model: FilterModel, limits: jk.WatchLimits, kind: str = "efir"
              ) -> tuple[Any, Any]:
    """The reset's update and one step, each followed by the watch, jitted."""
    _, update, predict_update = KINDS[kind]

    def first(memory: Any, b: jk.Belief, y: jax.Array) -> tuple[Any, jk.Belief]:
        memory, x, P, nis = update(memory, b.x, b.P, y, model)
        return memory, jk.watch(b, x, P, nis, limits)

    def step(memory: Any, b: jk.Belief, y: jax.Array, u: jax.Array) -> tuple[Any, jk.Belief]:
        memory, x, P, nis = predict_update(memory, b.x, b.P, y, u, model)
        return memory, jk.watch(b, x, P, nis, limits)

    return jax.jit(first), jax.jit(step)


def jax_record(memory: Any, b: jk.Belief) -> dict[str, Any]:
    return {"x": np.asarray(b.x), "P": np.asarray(b.P), "nis": float(b.nis),
            "diverged": bool(b.diverged), "startup": bool(memory.startup),
            "rank_deficient": bool(memory.rank_deficient)}


def run_jax(model: FilterModel, x0: np.ndarray, P0: np.ndarray, horizon: int, ys: np.ndarray,
            us: np.ndarray, kind: str = "efir") -> list[dict[str, Any]]:
    first, step = jax_steps(model, jk.watch_limits(ys.shape[1]), kind)
    b = jk.belief(jnp.asarray(x0), jnp.asarray(P0))
    memory, b = first(KINDS[kind][0](b.x, b.P, horizon, model), b, jnp.asarray(ys[0]))
    out = [jax_record(memory, b)]
    for k in range(1, len(ys)):
        memory, b = step(memory, b, jnp.asarray(ys[k]), jnp.asarray(us[k - 1]))
        out.append(jax_record(memory, b))
    return out


def assert_agree(ours: list[dict[str, Any]], ref: list[dict[str, Any]]) -> dict[str, float]:
    """Step by step: estimates and covariances to ``RTOL`` of their size, the NIS to ``RTOL
    (1 + nis)``, every flag exact. Returns the largest errors seen."""
    assert len(ours) == len(ref)
    worst = {"x": 0.0, "P": 0.0, "nis": 0.0}
    for k, (a, r) in enumerate(zip(ours, ref, strict=True)):
        for key in ("diverged", "startup", "rank_deficient"):
            assert a[key] == r[key], (k, key, a[key], r[key])
        for key in ("x", "P"):
            err = np.max(np.abs(a[key] - r[key])) / max(np.max(np.abs(r[key])), 1e-300)
            worst[key] = max(worst[key], err)
            assert err <= RTOL, (k, key, a[key], r[key])
        if np.isnan(r["nis"]):
            assert np.isnan(a["nis"]), k
        else:
            err = abs(a["nis"] - r["nis"]) / (1.0 + abs(r["nis"]))
            worst["nis"] = max(worst["nis"], err)
            assert err <= RTOL, (k, a["nis"], r["nis"])
    return worst


# ---------------------------------------------------------------------------- models
def linear_filter_model(ref: LinearModel) -> FilterModel:
    """The :class:`FilterModel` of a numpy :class:`LinearModel`: ``A x + B u``, ``A``, ``C``,
    ``G Q Gᵀ``, ``R``."""
    A, B = jnp.asarray(ref.A), jnp.asarray(ref.B)

    def f_and_F(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
        return A @ x + B @ u, A

    return FilterModel(lambda x, u: f_and_F(x, u)[0], f_and_F, jnp.asarray(ref.C),
                       jnp.asarray(ref.GQGT), jnp.asarray(ref.R))


def linear_case(p: int) -> tuple[LinearModel, FilterModel]:
    """A damped oscillator with a force input, process noise on both states, ``p`` channels."""
    A = np.array([[1.0, 0.1], [-0.05, 0.98]])
    B = np.array([[0.005], [0.1]])
    C = np.array([[1.0, 0.0]]) if p == 1 else np.array([[1.0, 0.0], [0.5, 1.0]])
    Q = np.array([[1e-4, 2e-5], [2e-5, 1e-3]])
    R = np.array([[1e-2]]) if p == 1 else np.array([[1e-2, 2e-3], [2e-3, 4e-2]])
    ref = LinearModel(A=A, B=B, C=C, Q=Q, R=R)
    return ref, linear_filter_model(ref)


def simulate(model: LinearModel | StateSpaceModel, x0: np.ndarray, us: np.ndarray,
             seed: int) -> np.ndarray:
    """Measurements ``y[0..K]`` of the model driven by ``us`` with its own noise."""
    rng = np.random.default_rng(seed)
    Lq = np.linalg.cholesky(model.GQGT + 1e-300 * np.eye(model.n_x))
    Lr = np.linalg.cholesky(model.R)
    x = np.array(x0, dtype=float)
    ys = [model.h(x) + Lr @ rng.normal(size=model.n_y)]
    for u in us:
        x = model.f(x, u) + Lq @ rng.normal(size=model.n_x)
        ys.append(model.h(x) + Lr @ rng.normal(size=model.n_y))
    return np.array(ys)


def test_constants_are_the_numpy_filters() -> None:
    assert jf.RANK_RTOL == _fir_bank.RANK_RTOL
    assert jf.MAX_ESTIMATE == _consistency.MAX_ESTIMATE


# ---------------------------------------------------------------------------- (a) linear
@pytest.mark.parametrize("p,horizon", [(1, 20), (2, 1), (2, 7)])
def test_linear_model_with_input_and_process_noise(p: int, horizon: int) -> None:
    ref, model = linear_case(p)
    x0, P0 = np.array([1.0, -0.5]), np.diag([0.2, 0.3])
    rng = np.random.default_rng(p + 10 * horizon)
    us = rng.uniform(-1.0, 1.0, size=(350, 1))
    ys = simulate(ref, rng.multivariate_normal(x0, P0), us, seed=p)
    est = ExtendedFIRFilter(ref, horizon=horizon, x0=x0, P0=P0, startup="prior")
    expected = run_numpy(est, ys, us)
    assert_agree(run_jax(model, x0, P0, horizon, ys, us), expected)
    assert sum(r["startup"] for r in expected) == horizon - 1      # start-up, then full


# ---------------------------------------------------------------------------- (b) Orbit-v0
def orbit_model(mu: float = 19.91, R: float = 1e-3) -> FilterModel:
    """Orbit-v0's filter model (:class:`fir_gym.envs.orbit.OrbitDynamics` with the nominal
    thrust 1, Δ = 1e-4, 100 substeps; ``u`` the applied action in units of the thrust)."""
    def f_and_F(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
        return orbit_interval(x, u[0] * 1.0, mu, 1e-4, 100)

    return FilterModel(lambda x, u: f_and_F(x, u)[0], f_and_F, jnp.array([[1.0, 0.0]]),
                       jnp.zeros((2, 2)), jnp.array([[R]]))


def orbit_episode(horizon: int, steps: int, seed: int, **env_kwargs: Any
                  ) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """A numpy Orbit-v0 episode with ``estimator="efir"`` under a noisy hover controller on
    the estimate: the env's filter, its measurements, the applied actions, its records."""
    env = gym.make("fir_gym/Orbit-v0", estimator="efir", estimator_kwargs={"horizon": horizon},
                   observation="estimate+measurement", **env_kwargs)
    wrapper = env
    while not hasattr(wrapper, "estimator"):
        wrapper = wrapper.env
    est = wrapper.estimator
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    ys, us, records = [obs["measurement"].copy()], [], [numpy_record(est)]
    for _ in range(steps):
        r, v = obs["estimate"]
        a = np.clip(0.311 - 0.5 * (r - 8.0) - 0.5 * v + 0.3 * rng.normal(), -1.0, 1.0)
        obs, _, terminated, truncated, info = env.step(np.array([a]))
        ys.append(obs["measurement"].copy())
        us.append(np.asarray(info["action"], dtype=np.float64).copy())
        records.append(numpy_record(est))
        if terminated or truncated:
            break
    return est, np.array(ys), np.array(us), records


@pytest.mark.parametrize("horizon", [50, 5])
def test_orbit_closed_loop_episode(horizon: int) -> None:
    est, ys, us, expected = orbit_episode(horizon, 400, seed=3)
    assert len(ys) == 401 and est.startup == "prior" and est.form == "filter"
    assert est.nominal == "open-loop" and est._Qx is None           # Q = 0
    x0, P0 = est.prior
    assert_agree(run_jax(orbit_model(), x0, P0, horizon, ys, us), expected)
    assert not expected[-1]["diverged"]


def test_orbit_plant_filter_model() -> None:
    """The JAX plant's own model (:meth:`fir_gym.jax.orbit.Orbit.filter_model` at the default
    params), which the generic filter kinds run on, in place of the one built here."""
    from fir_gym.jax import orbit as jorbit

    env = jorbit.Orbit("ekf")
    if not hasattr(env, "filter_model"):
        pytest.skip("this fir_gym.jax has no filter_model")
    est, ys, us, expected = orbit_episode(50, 200, seed=8)
    x0, P0 = est.prior
    assert_agree(run_jax(env.filter_model(env.default_params), x0, P0, 50, ys, us), expected)


def test_orbit_with_a_far_wrong_model_is_flagged_at_the_same_step() -> None:
    """A model that believes the sensor 10⁴ times better than it is (and a wrong μ): the NIS
    runs high from the first full windows and the watch flags it."""
    est, ys, us, expected = orbit_episode(20, 300, seed=5, nominal={"mu": 17.0, "R": 1e-7})
    x0, P0 = est.prior
    assert_agree(run_jax(orbit_model(17.0, 1e-7), x0, P0, 20, ys, us), expected)
    assert expected[-1]["diverged"] and not expected[5]["diverged"]


def test_orbit_nominal_through_the_planet() -> None:
    """A model with twice the true μ: its open-loop nominal falls through ``r = 0`` near step
    580, the estimate runs away and the watch flags it. Every flag agrees over the whole
    episode and the values to ``RTOL`` until just past the flag; after that they may part
    (measured: up to 1e-3): the nominal's Euler step at ``r ≈ 0`` makes the numpy and JAX
    interval maps themselves differ by 7.5e-11 (:func:`orbit_interval` against
    ``OrbitDynamics.propagate``, from 1e-16 before), and the window's linearisation about
    that nominal amplifies it."""
    est, ys, us, expected = orbit_episode(20, 600, seed=5, nominal={"mu": 40.0})
    x0, P0 = est.prior
    ours = run_jax(orbit_model(40.0), x0, P0, 20, ys, us)
    flagged = [r["diverged"] for r in expected].index(True)
    assert 500 < flagged < len(ys) - 10
    for key in ("diverged", "startup", "rank_deficient"):
        assert [a[key] for a in ours] == [r[key] for r in expected], key
    assert_agree(ours[:flagged + 3], expected[:flagged + 3])


# ---------------------------------------------------------------------------- (c) rank loss
def shear_case() -> tuple[StateSpaceModel, FilterModel]:
    """``r ← r + c(u) v``, ``v ← v``, ``c(u) = 0.1 (1 − u)``, ``y = r + noise``: at ``u = 1``
    the velocity leaves the measurements, and a window of such steps is rank deficient."""
    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        c = 0.1 * (1.0 - u[..., 0])
        return np.stack([x[..., 0] + c * x[..., 1], x[..., 1]], axis=-1)

    def F(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        c = 0.1 * (1.0 - np.broadcast_to(u[..., 0], x.shape[:-1]))
        J = np.zeros(x.shape[:-1] + (2, 2))
        J[..., 0, 0] = J[..., 1, 1] = 1.0
        J[..., 0, 1] = c
        return J

    Q, R = np.diag([1e-4, 1e-4]), np.array([[1e-2]])
    ref = StateSpaceModel(f=f, h=lambda x: x[..., :1], F=F, H=lambda x: np.broadcast_to(
        np.array([[1.0, 0.0]]), x.shape[:-1] + (1, 2)), Q=Q, R=R, n_u=1)

    def f_and_F(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
        c = 0.1 * (1.0 - u[0])
        return jnp.stack([x[0] + c * x[1], x[1]]), jnp.array([[1.0, c], [0.0, 1.0]])

    return ref, FilterModel(lambda x, u: f_and_F(x, u)[0], f_and_F, jnp.array([[1.0, 0.0]]),
                            jnp.asarray(Q), jnp.asarray(R))


def test_rank_deficient_windows_fall_back_to_the_prediction() -> None:
    ref, model = shear_case()
    x0, P0 = np.array([0.0, 1.0]), np.diag([0.1, 0.1])
    us = np.concatenate([np.zeros(40), np.ones(60), np.full(60, 0.5), np.ones(30),
                         np.zeros(130)])[:, None]
    ys = simulate(ref, x0, us, seed=7)
    est = ExtendedFIRFilter(ref, horizon=10, x0=x0, P0=P0, startup="prior")
    expected = run_numpy(est, ys, us)
    assert sum(r["rank_deficient"] for r in expected) > 50        # the fallback ran
    assert_agree(run_jax(model, x0, P0, 10, ys, us), expected)


def test_the_regularity_test_is_the_numpy_banks() -> None:
    rng = np.random.default_rng(2)
    cases = [np.diag([1.0, 0.0]), np.diag([1.0, 1e-13]), np.diag([1.0, 1e-11]),
             np.array([[1.0, 1.0], [1.0, 1.0 + 1e-11]]), np.full((2, 2), np.nan)]
    for _ in range(20):
        M = rng.normal(size=(3, 3)) * np.array([1.0, 1e3, 1e-3])
        cases.append(M @ M.T)
    for F in cases:
        ours = bool(jf.information_is_regular(jnp.asarray(F)))
        with np.errstate(all="ignore"):
            assert ours == bool(_fir_bank.spd_inverse(F[None])[1][0]), F


# ---------------------------------------------------------------------------- (d) batched
@pytest.mark.parametrize("kind", ["efir", "fir"])
def test_jit_vmap_over_a_batch_is_the_unbatched_filter(kind: str) -> None:
    ref, model = linear_case(1)
    x0, P0, horizon, n_b, K = np.array([1.0, -0.5]), np.diag([0.2, 0.3]), 8, 4, 60
    rng = np.random.default_rng(11)
    us = rng.uniform(-1.0, 1.0, size=(n_b, K, 1))
    ys = np.stack([simulate(ref, x0, us[i], seed=20 + i) for i in range(n_b)])
    limits = jk.watch_limits(1)
    first, step = jax_steps(model, limits, kind)
    vfirst, vstep = jax.jit(jax.vmap(first)), jax.jit(jax.vmap(step))
    start = jax.vmap(lambda x, P: KINDS[kind][0](x, P, horizon))
    bx, bP = jnp.broadcast_to(jnp.asarray(x0), (n_b, 2)), jnp.broadcast_to(jnp.asarray(P0),
                                                                          (n_b, 2, 2))
    B = jax.vmap(jk.belief)(bx, bP)
    memory, B = vfirst(start(bx, bP), B, jnp.asarray(ys[:, 0]))
    batched = [B]
    for k in range(1, K + 1):
        memory, B = vstep(memory, B, jnp.asarray(ys[:, k]), jnp.asarray(us[:, k - 1]))
        batched.append(B)
    for i in range(n_b):
        single = run_jax(model, x0, P0, horizon, ys[i], us[i], kind)
        for k, b in enumerate(batched):
            np.testing.assert_allclose(np.asarray(b.x[i]), single[k]["x"], rtol=1e-12,
                                       atol=1e-14)
            np.testing.assert_allclose(np.asarray(b.P[i]), single[k]["P"], rtol=1e-12,
                                       atol=1e-14)
            assert float(b.nis[i]) == pytest.approx(single[k]["nis"], rel=1e-12, abs=1e-14)
            assert bool(b.diverged[i]) == single[k]["diverged"]
    assert memory.Z.shape == (n_b, horizon, 4, 5)


# ---------------------------------------------------------------------------- the linear FIR
@pytest.mark.parametrize("p,horizon", [(1, 20), (2, 7), (1, 50)])
def test_linear_fir_filter(p: int, horizon: int) -> None:
    """:class:`fir_gym.estimators.fir.FIRFilter` (time-invariant: a fixed gain over the
    window, the growing window through start-up, the propagated prior before it determines
    the state) against the staggered bank, which is the same estimator."""
    ref, model = linear_case(p)
    x0, P0 = np.array([1.0, -0.5]), np.diag([0.2, 0.3])
    rng = np.random.default_rng(p + 10 * horizon)
    us = rng.uniform(-1.0, 1.0, size=(350, 1))
    ys = simulate(ref, rng.multivariate_normal(x0, P0), us, seed=p)
    expected = run_numpy(FIRFilter(ref, horizon=horizon, x0=x0, P0=P0), ys, us)
    assert_agree(run_jax(model, x0, P0, horizon, ys, us, "fir"), expected)
    assert expected[0]["rank_deficient"] == (p == 1)                # the prior, then the data


def test_carrier_motion_fir_episode() -> None:
    """The numpy CarrierMotion-v0 env's own ``estimator="fir"`` (horizon 50) over 400 steps."""
    env = gym.make("fir_gym/CarrierMotion-v0", estimator="fir",
                   estimator_kwargs={"horizon": 50}, observation="estimate+measurement")
    wrapper = env
    while not hasattr(wrapper, "estimator"):
        wrapper = wrapper.env
    est = wrapper.estimator
    assert isinstance(est, FIRFilter) and est.gain == "two-stage" and est.form == "filter"
    obs, _ = env.reset(seed=4)
    rng = np.random.default_rng(4)
    ys, us, expected = [obs["measurement"].copy()], [], [numpy_record(est)]
    for _ in range(400):
        a = np.clip(-0.5 * obs["estimate"][0] + 0.3 * rng.normal(), -1.0, 1.0)
        obs, _, terminated, truncated, info = env.step(np.array([a]))
        ys.append(obs["measurement"].copy())
        us.append(np.asarray(info["action"], dtype=np.float64).copy())
        expected.append(numpy_record(est))
        assert not (terminated or truncated)
    x0, P0 = est.prior
    assert_agree(run_jax(linear_filter_model(env.unwrapped.model), x0, P0, 50, np.array(ys),
                         np.array(us), "fir"), expected)
