"""Recurrent PPO on a :mod:`fir_gym.jax` environment: the JAX twin of the ``recurrent`` kind.

The SB3 backend trains the ``recurrent`` kind with sb3-contrib's ``RecurrentPPO``
(``MlpLstmPolicy``, the recipe of ``fir_gym/training/hyperparams/ppo_lstm.yml``): the raw
measurements, normalised as ``VecNormalize`` does, through a one-layer LSTM, then SB3's MLP.
:class:`RecurrentPPO` is :class:`~fir_gym.jax.ppo.SB3LikePPO` with that policy:

* **the networks** (sb3-contrib's ``RecurrentActorCriticPolicy`` with
  ``enable_critic_lstm=True``, ``shared_lstm=False``, ``n_lstm_layers=1``): the actor is an
  LSTM of ``lstm_hidden_size`` units (:class:`fir_gym.jax.lstm.LSTMCell`, torch's layer)
  whose output feeds :class:`~fir_gym.jax.ppo.Policy` (the Gaussian head: MLP, mean,
  ``log_std``); the critic has its own LSTM feeding :class:`~fir_gym.jax.ppo.Critic`. The
  parameters are ``{"lstm": ..., "head": ...}`` per network; the LSTMs' carries of the
  ``num_envs`` training envs ride in the train state (``actor_carry``, ``critic_carry``) from
  rollout to rollout, cleared where an episode starts (``last_done``), as sb3-contrib's
  ``_last_lstm_states`` and ``_last_episode_starts``.
* **the rollout** (``RecurrentPPO.collect_rollouts``): each step runs both LSTMs one step and
  stores the step's episode-start flag; an episode cut by the time limit is bootstrapped with
  ``γ V(terminal observation)`` where the critic's LSTM continues from its state after the
  step (not cleared), as sb3-contrib does; the last value of the rollout is the critic's on
  the next observation with the carry cleared where an episode starts.
* **the update**: minibatches of whole envs' sequences (``num_envs / num_minibatches`` envs
  each, the envs shuffled every epoch), each replayed through the LSTMs from the carry the
  rollout began with, clearing it at each episode start — the backpropagation through time of
  PureJaxRL's recurrent PPO. sb3-contrib cuts its minibatches as contiguous slices of
  ``batch_size`` samples of the env-major buffer from a random offset and starts each
  sequence from the LSTM state *stored* at its first step (computed by the rollout's
  parameters): with the shipped recipe (``batch_size`` = ``n_steps`` × envs per minibatch)
  both give minibatches of the same size, and sequences that begin at the rollout's start
  begin from the same state; they differ where sb3-contrib's offset cuts a sequence
  (:data:`UNMATCHED`). The losses are SB3's (:func:`fir_gym.jax.ppo.actor_loss`, the
  critic's mean squared error times ``vf_coef``) over all the minibatch's steps.

Tested against sb3-contrib in ``tests/jax/test_recurrent_ppo.py``: the same parameters give
the same actions, log-probabilities, entropies and values as ``RecurrentActorCriticPolicy``
over sequences with episode starts, and the training learns a task only memory solves.
"""

from __future__ import annotations

from typing import Any

from fir_gym._extras import require

require("jax", "gymnax", "rejax")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from flax import struct  # noqa: E402
from rejax.algos.algorithm import register_init  # noqa: E402

from . import lstm  # noqa: E402
from .ppo import NETWORK_DTYPES, SB3LikePPO, actor_loss  # noqa: E402

#: where this training differs from sb3-contrib's RecurrentPPO (besides SB3LikePPO's own)
UNMATCHED = (
    "minibatches: whole envs' sequences replayed from the rollout's first carry "
    "(sb3-contrib: contiguous slices from a random offset, each sequence started from the "
    "carry stored at its first step)",
)


class RecurrentTrajectory(struct.PyTreeNode):
    """One rollout, time first (``(num_steps, num_envs, ...)``): rejax's ``Trajectory`` and
    each step's episode-start flag (the LSTMs' carries are cleared before that step)."""

    obs: jax.Array
    action: jax.Array
    log_prob: jax.Array
    reward: jax.Array
    value: jax.Array
    done: jax.Array
    start: jax.Array


class SequenceMinibatch(struct.PyTreeNode):
    """Some envs' whole sequences: their trajectories (time first), advantages and targets,
    and the carries their rollout began with."""

    trajectories: RecurrentTrajectory
    advantages: jax.Array
    targets: jax.Array
    actor_carry: Any
    critic_carry: Any


class RecurrentPPO(SB3LikePPO):
    """:class:`~fir_gym.jax.ppo.SB3LikePPO` with sb3-contrib's LSTM policy (module
    docstring)."""

    lstm_hidden_size: int = struct.field(pytree_node=False, default=64)

    @property
    def cell(self) -> lstm.LSTMCell:
        return lstm.LSTMCell(self.lstm_hidden_size, NETWORK_DTYPES[self.network_dtype])

    def zero_carry(self, batch: int) -> lstm.Carry:
        """The carry of ``batch`` envs at an episode's start, in the networks' dtype."""
        return lstm.zeros(batch, self.lstm_hidden_size, NETWORK_DTYPES[self.network_dtype])

    @register_init
    def initialize_network_params(self, rng: Any) -> dict[str, Any]:
        keys = jax.random.split(rng, 4)
        n_obs = self.env.observation_space(self.env_params).shape[0]
        carry = self.zero_carry(1)
        latent = carry[0]
        actor = {"lstm": self.cell.init(keys[0], carry, jnp.zeros((1, n_obs))),
                 "head": self.actor.init(keys[1], latent, keys[1])}
        critic = {"lstm": self.cell.init(keys[2], carry, jnp.zeros((1, n_obs))),
                  "head": self.critic.init(keys[3], latent)}
        return self.train_states(actor, critic)

    @register_init
    def initialize_lstm_carries(self, rng: Any) -> dict[str, Any]:
        return {"actor_carry": self.zero_carry(self.num_envs),
                "critic_carry": self.zero_carry(self.num_envs)}

    # ------------------------------------------------------------------ the networks
    def actor_step(self, params: Any, carry: Any, obs: Any, start: Any) -> tuple[Any, Any]:
        """``(carry, latent)``: the actor's LSTM one step on ``obs (batch, n)``."""
        carry = lstm.step(self.cell, params["lstm"], carry, obs, start)
        return carry, carry[0]

    def critic_step(self, params: Any, carry: Any, obs: Any, start: Any) -> tuple[Any, Any]:
        """``(carry, value)``: the critic one step on ``obs (batch, n)``."""
        carry = lstm.step(self.cell, params["lstm"], carry, obs, start)
        return carry, self.critic.apply(params["head"], carry[0])

    def policy_carry(self, batch: int) -> Any:
        return self.zero_carry(batch)

    def policy_action(self, actor_params: Any, carry: Any, obs: Any, start: Any
                      ) -> tuple[Any, Any]:
        carry, latent = self.actor_step(actor_params, carry, obs, start)
        return carry, self.actor.apply(actor_params["head"], latent, method="mean_action")

    def final_value(self, ts: Any, final: Any) -> Any:
        # the critic's LSTM continues from its state after the step (sb3-contrib: the
        # terminal observation's value with episode_starts False)
        _, value = self.critic_step(ts.critic_ts.params, ts.critic_carry, final,
                                    jnp.zeros(final.shape[0], dtype=bool))
        return value

    # ------------------------------------------------------------------ the rollout
    def collect_trajectories(self, ts: Any) -> Any:
        """One rollout (module docstring): ``(ts, trajectory, (actor carry, critic carry) it
        began with)``."""
        began = (ts.actor_carry, ts.critic_carry)

        def env_step(ts: Any, unused: Any) -> Any:
            ts, rng_steps, rng_action = self.step_keys(ts)
            start = ts.last_done
            actor_carry, latent = self.actor_step(ts.actor_ts.params, ts.actor_carry,
                                                  ts.last_obs, start)
            unclipped_action, log_prob = self.actor.apply(
                ts.actor_ts.params["head"], latent, rng_action, method="action_log_prob")
            critic_carry, value = self.critic_step(ts.critic_ts.params, ts.critic_carry,
                                                   ts.last_obs, start)
            # the carries after this step first: the bootstrap's critic continues from them
            ts = ts.replace(actor_carry=actor_carry, critic_carry=critic_carry)
            ts, next_obs, env_state, reward, done = self.step_envs(ts, rng_steps,
                                                                   unclipped_action)
            transition = RecurrentTrajectory(ts.last_obs, unclipped_action, log_prob, reward,
                                             value, done, start)
            ts = ts.replace(env_state=env_state, last_obs=next_obs, last_done=done,
                            global_step=ts.global_step + self.num_envs)
            return ts, transition

        ts, trajectories = jax.lax.scan(env_step, ts, None, self.num_steps)
        return ts, trajectories, began

    # ------------------------------------------------------------------ the update
    def train_iteration(self, ts: Any) -> Any:
        ts, trajectories, (actor_carry, critic_carry) = self.collect_trajectories(ts)
        _, last_val = self.critic_step(ts.critic_ts.params, ts.critic_carry, ts.last_obs,
                                       ts.last_done)
        last_val = jnp.where(ts.last_done, 0, last_val)
        advantages, targets = self.calculate_gae(trajectories, last_val)
        batch = SequenceMinibatch(trajectories, advantages, targets, actor_carry, critic_carry)

        def update_epoch(ts: Any, unused: Any) -> Any:
            rng, minibatch_rng = jax.random.split(ts.rng)
            ts = ts.replace(rng=rng)
            minibatches = self.split_envs(batch, minibatch_rng)
            ts, _ = jax.lax.scan(lambda ts, mb: (self.update(ts, mb), None), ts, minibatches)
            return ts, None

        ts, _ = jax.lax.scan(update_epoch, ts, None, self.num_epochs)
        return ts

    def split_envs(self, batch: SequenceMinibatch, rng: Any) -> SequenceMinibatch:
        """``num_minibatches`` minibatches (a leading axis) of shuffled envs' whole sequences."""
        envs = jax.random.permutation(rng, self.num_envs)
        per = self.num_envs // self.num_minibatches

        def time_major(x: Any) -> Any:          # (T, E, ...) -> (M, T, E/M, ...)
            x = jnp.take(x, envs, axis=1)
            x = x.reshape((x.shape[0], self.num_minibatches, per, *x.shape[2:]))
            return jnp.swapaxes(x, 0, 1)

        def env_major(x: Any) -> Any:           # (E, ...) -> (M, E/M, ...)
            x = jnp.take(x, envs, axis=0)
            return x.reshape((self.num_minibatches, per, *x.shape[1:]))

        return SequenceMinibatch(
            jax.tree.map(time_major, batch.trajectories), time_major(batch.advantages),
            time_major(batch.targets), jax.tree.map(env_major, batch.actor_carry),
            jax.tree.map(env_major, batch.critic_carry))

    def actor_objective(self, params: Any, batch: Any) -> Any:
        """SB3's policy loss over the minibatch's sequences, replayed through the actor's
        LSTM from the carries the rollout began with."""
        t = batch.trajectories
        _, latent = lstm.unroll(self.cell, params["lstm"], batch.actor_carry, t.obs, t.start)
        log_prob, entropy = self.actor.apply(params["head"], _flat(latent), _flat(t.action),
                                             method="log_prob_entropy")
        return actor_loss(self, log_prob, entropy, _flat(t.log_prob), _flat(batch.advantages))

    def critic_objective(self, params: Any, batch: Any) -> Any:
        """``vf_coef`` times the values' mean squared error over the minibatch's sequences,
        replayed through the critic's LSTM."""
        t = batch.trajectories
        _, latent = lstm.unroll(self.cell, params["lstm"], batch.critic_carry, t.obs, t.start)
        value = self.critic.apply(params["head"], _flat(latent))
        return self.vf_coef * jnp.mean(jnp.square(value - _flat(batch.targets)))


def _flat(x: Any) -> Any:
    """``(T, B, ...)`` -> ``(T·B, ...)``: the heads take one batch axis."""
    return x.reshape((x.shape[0] * x.shape[1], *x.shape[2:]))
