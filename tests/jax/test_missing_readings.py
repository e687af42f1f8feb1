"""Missing readings in the generic filter kinds of fir_gym.jax (:mod:`fir_gym.jax.filters`,
``missing=``) against the numpy filters as the numpy env runs them: a reading whose
``info["measurement_missing"]`` is True gives the filter no measurement
(:class:`fir_gym.wrappers.EstimatorObservation`: ``step(None)``, at the reset too).

The oracle is :class:`~fir_gym.wrappers.EstimatorObservation` itself — the filter built as
``gym.make(env_id, estimator=kind, ...)`` builds it (tests/jax/test_filter_kinds.py) —
around an env that replays a JAX plant's measurements and applied actions and reports the
missing pattern in ``info["measurement_missing"]`` as :class:`~fir_gym.wrappers.SensorFaults`
does (tests/helpers/jax_parity.py, ``replay``). The JAX kind runs on the plant's
``filter_model`` from the plant's prior, each step followed by the divergence watch with
``usable=~missing`` (what the plants do), and is handed NaN for a missing reading: it must
not look at it.

The pattern (:func:`missing_pattern`) misses the reset's reading, readings while the window
fills, an isolated one, a run of ``horizon + 3`` — longer than the window: the windowed
filters' full windows hold no data and fall back to the prediction, and go on falling back
until enough readings have come in again —, two more isolated ones, then runs clean for
long enough to show the filters are back on the numpy ones' track. Every step: the
estimate and the covariance to 1e-9 of their largest entry, the NIS to 1e-9 (1 + NIS) and
NaN exactly on the missing steps, the divergence flag and the windowed filters' start-up
and rank-deficient flags exact. Measured once (x86-64 with FMA, numba's twins as the
oracle; ``-s`` prints them): the UKF ≤ 5e-15 in ``x``, 5e-13 in ``P``, 2e-13 in the NIS; the
FIR (CarrierMotion-v0) 1e-14; the EFIR 1e-14 on Orbit-v0 and UncertainOscillator-v0 and
1e-11 on VanDerPol-v0 — at the two steps after the run only, whose windows hold two readings
for two states (a barely regular information matrix amplifies round-off; 3e-14 on the other
steps). On the numpy reference path (numba off) the same order.

The UKF runs at ``alpha = 1, kappa = 1`` (as in test_filter_kinds.py: at the default
``alpha = 1e-3`` XLA's fused multiply-adds alone part the two by ~1e-8).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax_parity import normwise, replay  # noqa: E402

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.estimators import compiled  # noqa: E402
from fir_gym.jax import kalman as jk  # noqa: E402
from fir_gym.jax import make  # noqa: E402
from fir_gym.jax._plant import filter_prior, watch_limits_of  # noqa: E402
from fir_gym.jax.filters import GENERIC_FILTERS  # noqa: E402
from fir_gym.jax.fir import MAX_ESTIMATE  # noqa: E402
from fir_gym.robustness.plan import PLANTS as PLANS  # noqa: E402
from fir_gym.wrappers.estimator_observation import EstimatorObservation  # noqa: E402

RTOL = 1e-9
STEPS = 160
HORIZON = 8
#: the kinds' options in both envs (the UKF's: the module docstring says why)
OPTIONS = {"ukf": {"alpha": 1.0, "kappa": 1.0}, "efir": {"horizon": HORIZON},
           "fir": {"horizon": HORIZON}}
CASES = [("fir_gym/Orbit-v0", "ukf"), ("fir_gym/VanDerPol-v0", "ukf"),
         ("fir_gym/CarrierMotion-v0", "ukf"),
         ("fir_gym/Orbit-v0", "efir"), ("fir_gym/VanDerPol-v0", "efir"),
         ("fir_gym/CarrierMotion-v0", "fir")]


def missing_pattern(steps: int, horizon: int) -> np.ndarray:
    """Which of the readings ``0..steps`` are missing (the module docstring)."""
    missing = np.zeros(steps + 1, bool)
    missing[[0, 2, 3, 5]] = True                           # the reset's; while the window fills
    missing[horizon + 4] = True                            # isolated
    missing[2 * horizon + 3:3 * horizon + 6] = True        # a run of horizon + 3
    missing[[4 * horizon + 1, 4 * horizon + 3]] = True     # isolated again
    assert 5 < horizon - 1 and 4 * horizon + 3 < steps // 3
    return missing


def plant_data(env_id: str, kind: str, seed: int = 23
               ) -> tuple[Any, Any, np.ndarray, np.ndarray]:
    """The JAX env (observing ``kind``), its params, and an open-loop episode's measurements
    ``y[0..K]`` and applied actions (random, some clipped)."""
    env, params = make(env_id, kind, kind_kwargs=OPTIONS[kind], **PLANS[env_id].env_kwargs)
    actions = np.random.default_rng(17).uniform(-1.2, 1.2, (STEPS, 1))
    keys = jax.random.split(jax.random.key(seed), STEPS + 1)
    _, state = jax.jit(env.reset_env)(keys[0], params)
    step = jax.jit(env.step_env)
    ys, applied = [np.asarray(state.y)], []
    for key, a in zip(keys[1:], actions, strict=True):
        _, state, _, _, info = step(key, state, jnp.asarray(a), params)
        ys.append(np.asarray(state.y))
        applied.append(np.asarray(info["action"]))
        if bool(state.terminated):
            break
    assert len(ys) == STEPS + 1, "the episode ended too early to compare"
    return env, params, np.array(ys), np.array(applied)


def jax_kind(env: Any, params: Any, kind: str) -> tuple[Any, Any]:
    """The kind's reset update and step, each followed by the watch with ``usable =
    ~missing``, jitted with ``missing`` traced (:meth:`FilteredPlant.finish_reset`,
    :meth:`~FilteredPlant.finish_step` as the plants call them)."""
    filt = GENERIC_FILTERS[kind]
    model, options, limits = env.filter_model(params), env.options, watch_limits_of(params)
    x0, P0 = filter_prior(params)

    @jax.jit
    def first(y: jax.Array, missing: jax.Array) -> tuple[Any, jk.Belief]:
        b = jk.belief(x0, P0)
        memory = filt.start(b.x, b.P, options)
        memory, x, P, nis = filt.update(memory, b.x, b.P, y, model, options, missing=missing)
        return memory, jk.watch(b, x, P, nis, limits, usable=~missing)

    @jax.jit
    def step(memory: Any, b: jk.Belief, y: jax.Array, u: jax.Array, missing: jax.Array
             ) -> tuple[Any, jk.Belief]:
        memory, x, P, nis = filt.predict_update(memory, b.x, b.P, y, u, model, options,
                                                missing=missing)
        return memory, jk.watch(b, x, P, nis, limits, usable=~missing)

    return first, step


def numpy_env(env_id: str, kind: str, ys: np.ndarray, applied: np.ndarray,
              missing: np.ndarray) -> EstimatorObservation:
    """The oracle: the numpy env's wrapper around the replay, with the numpy plant's model and
    prior."""
    with_plant = gym.make(env_id, **PLANS[env_id].env_kwargs)
    wrapped = EstimatorObservation(replay(ys, applied, with_plant.unwrapped, missing), kind,
                                   **OPTIONS[kind])
    with_plant.close()
    return wrapped


def compare(env_id: str, kind: str) -> tuple[dict[str, float], int, int | None]:
    """The JAX kind and the numpy env's filter over the episode with :func:`missing_pattern`,
    step by step (the module docstring): the worst differences, the number of rank-deficient
    fallbacks, and the first step whose numpy estimate passed the growth bound (None: none)
    — from there on only the flags are compared: the numpy watch stores such an estimate and
    flags it, the JAX kind hands the watch NaN and keeps the previous one
    (:mod:`fir_gym.jax.fir`), so the records part."""
    env, params, ys, applied = plant_data(env_id, kind)
    missing = missing_pattern(STEPS, HORIZON)
    fed = np.where(missing[:, None], np.nan, ys)              # the JAX kind must not look
    first, step = jax_kind(env, params, kind)
    oracle = numpy_env(env_id, kind, ys, applied, missing)
    windowed = kind != "ukf"
    estimate, info = oracle.reset()
    assert bool(info["measurement_missing"])
    memory, b = first(jnp.asarray(fed[0]), jnp.asarray(missing[0]))
    worst = {"x": 0.0, "P": 0.0, "nis": 0.0}
    fallbacks, grown = 0, None
    for k in range(STEPS + 1):
        if k:
            estimate, _, _, _, info = oracle.step(applied[k - 1])
            assert bool(info["measurement_missing"]) == missing[k]
            before = np.asarray(b.x)
            memory, b = step(memory, b, jnp.asarray(fed[k]), jnp.asarray(applied[k - 1]),
                             jnp.asarray(missing[k]))
        est = oracle.estimator
        numpy_info = est.last_info
        assert bool(b.diverged) == bool(est.diverged), f"step {k}"
        if windowed:
            assert bool(memory.startup) == bool(numpy_info["startup"]), f"step {k}"
            assert bool(memory.rank_deficient) == bool(numpy_info["rank_deficient"]), \
                f"step {k}"
            fallbacks += bool(numpy_info["rank_deficient"])
        nis, got = float(numpy_info["nis"]), float(b.nis)
        if missing[k]:
            assert np.isnan(nis) and np.isnan(got), f"step {k}: {nis}, {got}"
        if grown is None and windowed and np.max(np.abs(estimate)) > MAX_ESTIMATE:
            grown = k                                   # the JAX record kept the previous
            assert np.array_equal(np.asarray(b.x), before) and bool(b.diverged)
        if grown is not None:
            continue
        err_x = normwise(np.asarray(b.x), estimate)
        err_P = normwise(np.asarray(b.P), est.P)
        assert err_x < RTOL and err_P < RTOL, (k, err_x, err_P)
        worst["x"], worst["P"] = max(worst["x"], err_x), max(worst["P"], err_P)
        if np.isnan(nis):
            assert np.isnan(got), f"step {k}"
        else:
            err = abs(got - nis) / (1.0 + abs(nis))
            assert err < RTOL, (k, got, nis)
            worst["nis"] = max(worst["nis"], err)
    print(env_id, kind, worst, "fallbacks", fallbacks, "grown", grown)
    return worst, fallbacks, grown


@pytest.mark.parametrize("env_id,kind", CASES)
def test_missing_readings_are_the_numpy_filters(env_id: str, kind: str) -> None:
    _, fallbacks, grown = compare(env_id, kind)
    assert grown is None
    if kind != "ukf":                 # the run longer than the window: full windows empty
        assert fallbacks >= 2, fallbacks


@pytest.mark.skipif(not compiled.ENABLED, reason="the numpy reference ran above already")
@pytest.mark.parametrize("env_id,kind", [("fir_gym/Orbit-v0", "ukf"),
                                         ("fir_gym/VanDerPol-v0", "efir"),
                                         ("fir_gym/CarrierMotion-v0", "fir")])
def test_missing_readings_on_the_numpy_reference_path(env_id: str, kind: str) -> None:
    """The same against the numpy filters' reference path (their hooks ``_update``,
    ``_predict_update``, ``_accept``; above, with numba, their compiled twins ran)."""
    saved = compiled.ENABLED
    compiled.ENABLED = False
    try:
        _, fallbacks, grown = compare(env_id, kind)
    finally:
        compiled.ENABLED = saved
    assert grown is None and (kind == "ukf" or fallbacks >= 2)


def test_a_filter_that_blows_up_in_the_gap_is_flagged_at_the_same_steps() -> None:
    """UncertainOscillator-v0's EFIR (its state carries the uncertain rate) falls back to
    its prediction through the run of misses and the prediction runs away: ``trace P`` and
    then the growth bound flag it, on the same steps in both. Until the growth bound the
    values agree at round-off; from there the records part (:func:`compare`), the flags
    not."""
    _, fallbacks, grown = compare("fir_gym/UncertainOscillator-v0", "efir")
    assert fallbacks >= 2 and grown is not None


@pytest.mark.parametrize("kind", ["ukf", "efir", "fir"])
def test_missing_false_is_the_step_without_it(kind: str) -> None:
    """``missing`` left out, the literal ``False`` and a traced ``False``: the same bits, at
    the reset and over the steps."""
    env_id = "fir_gym/CarrierMotion-v0" if kind != "efir" else "fir_gym/VanDerPol-v0"
    env, params, ys, applied = plant_data(env_id, kind)
    filt = GENERIC_FILTERS[kind]
    model, options = env.filter_model(params), env.options
    x0, P0 = filter_prior(params)

    def run(**how: Any) -> list[Any]:
        traced = "traced" in how

        @jax.jit
        def first(y: jax.Array, flag: jax.Array) -> Any:
            extra = {"missing": flag} if traced else how
            return filt.update(filt.start(x0, P0, options), x0, P0, y, model, options, **extra)

        @jax.jit
        def step(memory: Any, x: Any, P: Any, y: jax.Array, u: jax.Array, flag: jax.Array
                 ) -> Any:
            extra = {"missing": flag} if traced else how
            return filt.predict_update(memory, x, P, y, u, model, options, **extra)

        out = [first(jnp.asarray(ys[0]), jnp.asarray(False))]
        for k in range(1, 60):
            memory, x, P, _ = out[-1]
            out.append(step(memory, x, P, jnp.asarray(ys[k]), jnp.asarray(applied[k - 1]),
                            jnp.asarray(False)))
        return [[np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(o)] for o in out]

    plain = run()
    for other in (run(missing=False), run(traced=True)):
        for k, (a, b) in enumerate(zip(plain, other, strict=True)):
            for u, v in zip(a, b, strict=True):
                assert u.dtype == v.dtype and u.tobytes() == v.tobytes(), f"step {k}"

