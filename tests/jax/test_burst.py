"""The ``burst`` condition on the JAX plants (``fir_gym.jax.make(env_id, kind, burst=...)``).

Oracle: the numpy plant built with the same ``burst`` (``gym.make(env_id, burst=...,
estimator=<its own filter>)``), run on the same standard normals — the JAX env's own,
recomputed from its keys and served to the numpy plant (``tests/helpers/jax_conditions.py``)
— and the same open-loop actions. The windows overlap (their δ add), one of them overlaps
UncertainOscillator-v0's own δ schedule (the burst adds to it there), and VanDerPol-v0's
interval-average measurement is stretched with its state. Over the episode the states,
observations (the filter's estimate), rewards, the filter's covariance and NIS, and
``info["burst"]`` agree to 1e-9 of each quantity's scale, the flags exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax_conditions import (  # noqa: E402
    SETTINGS,
    draws,
    jax_record,
    jax_rollout,
    nis_difference,
    numpy_run,
    worst_differences,
)

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.envs._conditions import burst_delta  # noqa: E402
from fir_gym.jax import PLANTS, make  # noqa: E402

STEPS = 40
#: overlapping windows: δ = 0.5 for k = 4..7, 0.2 for 8..9, −0.3 for 10..16
BURST = ((4, 9, 0.5), (8, 16, -0.3))
RTOL = 1e-9
QUANTITIES = ("state", "obs", "reward", "burst", "P")


def _actions(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.2, 1.2, (STEPS, 1)).astype(np.float32)


def _compare(got: dict, want: dict) -> dict[str, float]:
    n = len(want["reward"])
    for flag in ("terminated", "truncated", "diverged"):
        np.testing.assert_array_equal(got[flag], want[flag], err_msg=flag)
    worst = worst_differences(got, want, QUANTITIES)
    worst["nis"] = nis_difference(got["nis"], want["nis"])
    assert n == STEPS + 1 and want["truncated"][-1], "the episode runs to its time limit"
    return worst


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_a_burst_episode_matches_the_numpy_plant(env_id: str) -> None:
    own = PLANTS[env_id].env_class.estimator
    kwargs = {**SETTINGS[env_id], "max_episode_steps": STEPS}
    env, params = make(env_id, own, burst=BURST, **kwargs)
    keys = jax.random.split(jax.random.key(11), STEPS + 1)
    actions = _actions(3)
    obs0, state0, trace = jax_rollout(env)(keys, jnp.asarray(actions), params)
    want = numpy_run(gym.make(env_id, estimator=own, burst=BURST, **kwargs),
                     draws(env_id, env, params, keys), actions)
    got = jax_record(obs0, state0, trace, len(want["reward"]))
    np.testing.assert_array_equal(want["burst"], [burst_delta(BURST, k - 1) if k else 0.0
                                                  for k in range(STEPS + 1)])
    worst = _compare(got, want)
    if env_id == "fir_gym/UncertainOscillator-v0":       # the burst adds to the δ schedule
        delta = np.asarray(trace[5]["delta"])
        np.testing.assert_allclose(delta, [burst_delta(BURST, k) + (0.1 if 6 <= k <= 14 else 0)
                                           for k in range(STEPS)], rtol=0, atol=1e-15)
    print(env_id, own, "worst relative differences:",
          ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    assert max(worst.values()) < RTOL, worst


def test_the_burst_combines_with_randomize() -> None:
    """Orbit-v0 with its truth drawn at the reset (``randomize``) and the burst: the numpy
    plant whose true ``mu`` and ``thrust_max`` are the JAX env's draw (the model keeping its
    nominal values), under the same burst, on the same noise."""
    env_id = "fir_gym/Orbit-v0"
    kwargs = {**SETTINGS[env_id], "max_episode_steps": STEPS}
    env, params = make(env_id, "ekf", burst=BURST, randomize={"mu": 0.05, "thrust_max": 0.2},
                       **kwargs)
    keys = jax.random.split(jax.random.key(5), STEPS + 1)
    actions = _actions(4)
    obs0, state0, trace = jax_rollout(env)(keys, jnp.asarray(actions), params)
    drawn = {name: float(value) for name, value in state0.true_params.items()}
    assert abs(drawn["thrust_max"] - 1.0) > 1e-3 and abs(drawn["mu"] - 19.91) > 1e-3
    numpy_env = gym.make(env_id, estimator="ekf", burst=BURST, **drawn,
                         nominal={"thrust_max": 1.0}, **kwargs)
    want = numpy_run(numpy_env, draws(env_id, env.env, params, keys), actions)
    worst = _compare(jax_record(obs0, state0, trace, len(want["reward"])), want)
    print("Orbit-v0 randomized", drawn, "worst:", worst)
    assert max(worst.values()) < RTOL, worst


def test_a_bad_burst_is_refused_as_the_numpy_plant_refuses_it() -> None:
    for bad in (((5, 3, 0.1),), ((2, 4, -1.0),), ((1.5, 4, 0.1),), "soon"):
        with pytest.raises(ValueError, match="burst must be a sequence of") as ours:
            make("fir_gym/CarrierMotion-v0", burst=bad)
        with pytest.raises(ValueError) as theirs:
            gym.make("fir_gym/CarrierMotion-v0", burst=bad)
        assert str(ours.value) == str(theirs.value)
    env, _ = make("fir_gym/CarrierMotion-v0", burst=[[3, 4, 0.25]])
    assert env.burst == ((3, 4, 0.25),)
    assert make("fir_gym/CarrierMotion-v0")[0].burst == ()
