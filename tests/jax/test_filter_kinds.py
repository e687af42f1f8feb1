"""The generic filter kinds of fir_gym.jax (:mod:`fir_gym.jax.filters`) on every plant,
against the numpy filter as the numpy env builds it.

The oracle is :class:`fir_gym.wrappers.EstimatorObservation` — the numpy env's own wrapper,
so the filter is built as ``gym.make(env_id, estimator=kind, estimator_kwargs=...)`` builds
it (the plant's ``model``, its prior, ``startup="prior"``, the kind's options) — wrapped
around an env that replays the JAX plant's measurements and applied actions and publishes
the numpy plant's model and prior. The JAX plant's measurements are the numpy plant's given
the same noise (the per-plant parity tests), and the plant's ``filter_model`` is its own
filter's model (tests/jax/test_kinds.py): together, the JAX kind is the numpy env's kind.
Over a closed-loop episode (random actions, some clipped) the estimate and covariance agree
to 1e-9 of their largest entry, the NIS to 1e-9 (1 + NIS), the divergence flag exactly.

The UKF is compared at ``alpha = 1, kappa = 1`` (options both envs take): at its default
``alpha = 1e-3`` the weights are ~1/alpha² in size and of mixed sign, so the one-ulp
differences of XLA's fused multiply-adds in ``f`` grow to ~1e-8 in the estimate — the
spread the numpy filter's own compiled twin shows against it (docs/jax.md#the-kinds;
tests/jax/test_unscented.py checks the default alpha with fusing turned off).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax_parity import compare_with_numpy_filter, replay  # noqa: E402

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.jax import PLANTS, make  # noqa: E402
from fir_gym.jax.filters import GENERIC_FILTERS  # noqa: E402
from fir_gym.robustness.plan import PLANTS as PLANS  # noqa: E402
from fir_gym.wrappers.estimator_observation import EstimatorObservation  # noqa: E402

RTOL = 1e-9
STEPS = 150
#: options both envs get, per kind (the module docstring says why the UKF's)
TEST_OPTIONS = {"ukf": {"alpha": 1.0, "kappa": 1.0}}
CASES = [(env_id, kind) for env_id, plant in PLANTS.items() for kind in plant.kinds
         if kind in GENERIC_FILTERS]


def _jax_rollout(env: Any, params: Any, actions: np.ndarray, seed: int) -> list[Any]:
    keys = jax.random.split(jax.random.key(seed), len(actions) + 1)
    _, state = jax.jit(env.reset_env)(keys[0], params)
    step = jax.jit(env.step_env)
    states, infos = [state], [None]
    for key, a in zip(keys[1:], actions, strict=True):
        _, state, _, _, info = step(key, state, jnp.asarray(a), params)
        states.append(state)
        infos.append(info)
        if bool(state.terminated):
            break
    return list(zip(states, infos, strict=True))


@pytest.mark.parametrize("env_id,kind", CASES)
def test_the_kind_is_the_numpy_envs_filter(env_id: str, kind: str) -> None:
    plan = PLANS[env_id]
    options = {**plan.estimator_kwargs.get(kind, {}), **TEST_OPTIONS.get(kind, {})}
    env, params = make(env_id, kind, kind_kwargs=options, **plan.env_kwargs)
    rng = np.random.default_rng(17)
    actions = rng.uniform(-1.2, 1.2, (STEPS, 1))
    run = _jax_rollout(env, params, actions, seed=23)
    assert len(run) > STEPS // 2, "the episode ended too early to compare"
    ys = np.array([np.asarray(s.y) for s, _ in run])
    applied = np.array([np.asarray(i["action"]) for _, i in run[1:]])
    with_plant = gym.make(env_id, **plan.env_kwargs)
    numpy_env = EstimatorObservation(replay(ys, applied, with_plant.unwrapped), kind, **options)
    with_plant.close()
    worst = compare_with_numpy_filter(run, numpy_env)
    print(env_id, kind, worst)
    assert max(worst.values()) < RTOL, worst
