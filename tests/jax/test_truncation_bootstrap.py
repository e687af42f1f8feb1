"""fir_gym.jax.train.SB3LikePPO: stable-baselines3's bootstrap of episodes cut by the time limit.

SB3's ``OnPolicyAlgorithm.collect_rollouts`` adds ``gamma * V(terminal observation)`` to the
(normalised) reward of a step that ends an episode by ``TimeLimit.truncated`` (truncated and
not terminated), the terminal observation normalised by ``VecNormalize.step_wait`` with the
statistics after that step's update. The oracles run on a tiny deterministic plant whose
observation climbs by one a step (:class:`Ticker`), episodes of three steps, two envs, seven
steps (two episode ends and a partial third episode): one against rejax's own
``PPO.collect_trajectories`` and a numpy replay of the statistics (SB3's ``RunningMeanStd``),
one against SB3's own ``DummyVecEnv`` + ``TimeLimit`` + ``VecNormalize`` pipeline and its rule
computed by hand.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("gymnax")
pytest.importorskip("rejax")
pytest.importorskip("yaml")

import jax
import jax.numpy as jnp
from jax_runs import ORBIT
from rejax import PPO
from ticker import EPISODE, X0, Ticker, TickerParams

from fir_gym.jax import train as jt

STEPS = 7            # collected per env: ends after steps 3 and 6


def algorithm(terminate_at: int = 0, *, normalize_rewards: bool = True
              ) -> tuple[jt.SB3LikePPO, Any]:
    """The shipped recipe on :class:`Ticker`: 2 envs, 7 steps, gamma 0.99, VecNormalize's
    clips; and one seed's initial state."""
    rec = dataclasses.replace(jt.recipe(ORBIT), steps=2 * STEPS, num_envs=2, num_steps=STEPS,
                              num_minibatches=1, normalize_rewards=normalize_rewards)
    algo = jt.make_algorithm(Ticker(), TickerParams(terminate_at=terminate_at), rec)
    return algo, algo.init_state(jax.random.PRNGKey(3))


def value(algo: jt.SB3LikePPO, ts: Any, obs: np.ndarray) -> np.ndarray:
    """The rollout's critic at (already normalised) observations."""
    return np.asarray(algo.critic.apply(ts.critic_ts.params, jnp.asarray(obs)))


def replay(terminate_at: int) -> list[dict[str, np.ndarray]]:
    """The plant's steps for two envs, straight from gymnax's ``step``: per step the returned
    observations, the terminal observations and the two flags."""
    env, params = Ticker(), TickerParams(terminate_at=terminate_at)
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    _, state = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
    steps = []
    for _ in range(STEPS):
        obs, state, _, term, trunc, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
            keys, state, jnp.zeros((2, 1)), params)
        steps.append({"obs": np.asarray(obs), "final": np.asarray(info["final_observation"]),
                      "terminated": np.asarray(term), "truncated": np.asarray(trunc)})
    return steps


# ---------------------------------------------------------------------------- against rejax
@pytest.mark.parametrize(("terminate_at", "bootstrapped_steps"), [
    (0, [2, 5]),           # episodes always truncate: steps 3 and 6 (0-based 2, 5)
    (EPISODE, []),         # terminated at the time limit too: a true termination
    (2, []),               # terminated before the limit: never truncated
])
def test_the_bootstrap_is_gamma_v_of_the_normalised_final_obs_at_a_truncation_only(
        terminate_at: int, bootstrapped_steps: list[int]) -> None:
    """Our rewards minus rejax's, from the same state (the same actions and plant steps):
    exactly ``γ V(clip((final − mean) / sqrt(var + 1e-8), ±10))`` at a truncation, the
    statistics after that step's update (SB3's ``RunningMeanStd`` replayed over the first
    observations, as ``VecNormalize.reset`` counts them, then the returned ones), and
    exactly 0 at every other step, a termination included."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    algo, ts = algorithm(terminate_at)
    _, ours = jax.jit(algo.collect_trajectories)(ts)
    _, rejax = jax.jit(lambda ts: PPO.collect_trajectories(algo, ts))(ts)
    np.testing.assert_array_equal(np.asarray(ours.done), np.asarray(rejax.done))
    np.testing.assert_array_equal(np.asarray(ours.obs), np.asarray(rejax.obs))
    added = np.asarray(ours.reward) - np.asarray(rejax.reward)

    rms = RunningMeanStd(shape=(2,))
    rms.update(np.array([[X0, X0 * X0 / 4.0]] * 2))        # the reset's observations
    expected = np.zeros((STEPS, 2))
    for t, step in enumerate(replay(terminate_at)):
        rms.update(step["obs"])                     # the step's update, then the final obs
        final = np.clip((step["final"] - rms.mean) / np.sqrt(rms.var + 1e-8), -10.0, 10.0)
        cut = step["truncated"] & ~step["terminated"]
        expected[t] = np.where(cut, algo.gamma * value(algo, ts, final), 0.0)
        assert cut.any() == (t in bootstrapped_steps), t
    assert np.all(added[[t for t in range(STEPS) if t not in bootstrapped_steps]] == 0.0)
    np.testing.assert_allclose(added, expected, rtol=1e-12, atol=1e-12)
    if bootstrapped_steps:
        assert np.all(np.abs(added[bootstrapped_steps]) > 1e-3)   # a real addition


def test_the_final_obs_is_not_the_reset_obs_and_the_stats_update_once() -> None:
    """The bootstrap values the terminal observation (x = 3.5 after three steps), not the
    next episode's first (x = 0.5, what the step returns), and the statistics are updated
    once a step, by the returned observations only (as rejax without the bootstrap)."""
    algo, ts = algorithm()
    ours_ts, _ = jax.jit(algo.collect_trajectories)(ts)
    rejax_ts, _ = jax.jit(lambda ts: PPO.collect_trajectories(algo, ts))(ts)
    for a, b in zip(jax.tree.leaves(ours_ts.obs_rms_state),
                    jax.tree.leaves(rejax_ts.obs_rms_state), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    step = replay(0)[EPISODE - 1]
    np.testing.assert_array_equal(step["final"][:, 0], [X0 + EPISODE] * 2)
    np.testing.assert_array_equal(step["obs"][:, 0], [X0] * 2)


# ---------------------------------------------------------------------------- against SB3
def sb3_rewards(algo: jt.SB3LikePPO, ts: Any, terminate_at: int, norm_reward: bool
                ) -> np.ndarray:
    """SB3's rule computed by hand on SB3's own pipeline: a gymnasium twin of
    :class:`Ticker` in ``TimeLimit``, ``DummyVecEnv`` (which sets ``TimeLimit.truncated`` and
    ``terminal_observation``), ``VecNormalize`` (its statistics from its reset on, the
    rewards' too where ``normalize_rewards``), then ``reward + gamma *
    V(terminal_observation)`` where ``done`` and ``TimeLimit.truncated``, as
    ``OnPolicyAlgorithm.collect_rollouts``."""
    import gymnasium as gym
    from gymnasium.wrappers import TimeLimit
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    class TickerGym(gym.Env):
        observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float64)
        action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

        def obs(self) -> np.ndarray:
            return np.array([self.x, self.x * self.x / 4.0])

        def reset(self, *, seed: int | None = None, options: Any = None) -> Any:
            super().reset(seed=seed)
            self.x, self.time = X0, 0
            return self.obs(), {}

        def step(self, action: Any) -> Any:
            self.x, self.time = self.x + 1.0, self.time + 1
            return self.obs(), -self.x, self.time == terminate_at, False, {}

    venv = VecNormalize(DummyVecEnv([lambda: TimeLimit(TickerGym(), EPISODE)] * 2),
                        norm_obs=True, norm_reward=norm_reward, clip_obs=10.0,
                        clip_reward=10.0, gamma=algo.gamma)
    venv.reset()
    rewards = np.zeros((STEPS, 2))
    for t in range(STEPS):
        _, reward, dones, infos = venv.step(np.zeros((2, 1), np.float32))
        for idx, done in enumerate(dones):
            if (done and infos[idx].get("terminal_observation") is not None
                    and infos[idx].get("TimeLimit.truncated", False)):
                terminal = infos[idx]["terminal_observation"][None].astype(np.float64)
                reward[idx] += algo.gamma * value(algo, ts, terminal)[0]
        rewards[t] = reward
    return rewards


@pytest.mark.parametrize("norm_reward", [False, True])
@pytest.mark.parametrize("terminate_at", [0, EPISODE, 2])
def test_the_rewards_are_sb3_rule_on_sb3_pipeline(terminate_at: int, norm_reward: bool
                                                  ) -> None:
    """The whole of it on SB3's pipeline: the first observations counted and normalised, the
    reward statistics' running return reset one step after an episode's end (VecNormalize's),
    the bootstrap."""
    algo, ts = algorithm(terminate_at, normalize_rewards=norm_reward)
    _, ours = jax.jit(algo.collect_trajectories)(ts)
    # VecNormalize hands float32 observations and rewards to the policy: float32 rounding
    np.testing.assert_allclose(np.asarray(ours.reward),
                               sb3_rewards(algo, ts, terminate_at, norm_reward),
                               rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(np.asarray(ours.obs[0]), sb3_first_obs(algo), rtol=1e-6)


def sb3_first_obs(algo: jt.SB3LikePPO) -> np.ndarray:
    """What ``VecNormalize.reset`` returns on two Tickers: the first observations normalised
    by statistics that have counted them."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    first = np.array([[X0, X0 * X0 / 4.0]] * 2)
    rms = RunningMeanStd(shape=(2,))
    rms.update(first)
    return np.clip((first - rms.mean) / np.sqrt(rms.var + 1e-8), -10.0, 10.0)

