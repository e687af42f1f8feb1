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
  stores the step's episode-start flag and the carries the LSTMs had *before* the step (before
  an episode start clears them: sb3-contrib's ``lstm_states`` given to
  ``RecurrentRolloutBuffer.add``); an episode cut by the time limit is bootstrapped with
  ``γ V(terminal observation)`` where the critic's LSTM continues from its state after the
  step (not cleared), as sb3-contrib does; the last value of the rollout is the critic's on
  the next observation with the carry cleared where an episode starts.
* **the minibatches** (``RecurrentRolloutBuffer.get`` and ``_get_samples``, ``get`` called
  once per epoch): each epoch draws one split index uniform over the rollout's ``num_envs ·
  num_steps`` samples (sb3-contrib's ``np.random.randint``; here from the train state's key,
  :meth:`RecurrentPPO.split_index`); the env-major flat indices rotated by it
  (``indices[split:] + indices[:split]``) are cut into consecutive slices of ``batch_size``,
  not otherwise shuffled (:meth:`RecurrentPPO.slice_starts`). Within a slice a sequence
  begins at the slice's first sample, at every episode start and at every env change (each
  env's step 0, the wrap from the last env to env 0 too: ``create_sequencers``), from the
  carries *stored* at its first step — constants, the rollout's — which the episode start
  then clears; the sequences are padded and the losses masked.
  The recipe's ``batch_size`` is ``k · num_steps`` (``k = num_envs / num_minibatches``), so
  the slice from flat index ``f0`` covers env ``e0 = f0 // T`` from ``t0 = f0 % T`` on, envs
  ``e0+1 … e0+k−1`` whole and env ``e0+k`` (mod ``num_envs``) before ``t0``. Here it is
  ``k + 1`` rows of those envs' whole ``T``-step sequences (:class:`SequenceMinibatch`,
  :meth:`RecurrentPPO.minibatch`) with a mask of the slice's samples and a flag where the
  replay takes the stored carry (row 0 at ``t0``, the others at step 0;
  :func:`fir_gym.jax.lstm.replay`): the same samples in the same sequences from the same
  carries as sb3-contrib's padded ones, at ``1/k`` more LSTM work than the slice's own
  samples (25 % with the shipped recipe's ``k = 4``).
* **the losses** (``RecurrentPPO.train``'s, masked): the advantages normalised with the mean
  and the unbiased standard deviation over the mask, the clipped surrogate, the entropy and
  the critic's squared error (times ``vf_coef``) as means over the mask
  (:func:`fir_gym.jax.ppo.actor_loss` with a mask, :meth:`RecurrentPPO.critic_objective`);
  the gradients are then clipped together as :class:`~fir_gym.jax.ppo.SB3LikePPO`'s.
  Nothing of sb3-contrib's training is left unmatched (:data:`UNMATCHED`).

Tested against sb3-contrib in ``tests/jax/test_recurrent_ppo.py``: the same parameters give
the same actions, log-probabilities, entropies and values as ``RecurrentActorCriticPolicy``
over sequences with episode starts; the rollout stores what the torch policy computes step by
step, its carries included; for split indices chosen in a real ``RecurrentRolloutBuffer``,
each of our minibatches holds the buffer's samples and gives the gradients of
``RecurrentPPO.train``'s loss on the buffer's minibatch; and the training learns a task only
memory solves.
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
from .ppo import NETWORK_DTYPES, SB3LikePPO, actor_loss, masked_mean  # noqa: E402

#: where this training differs from sb3-contrib's RecurrentPPO (besides SB3LikePPO's own,
#: none): nothing since the minibatches are ``RecurrentRolloutBuffer.get``'s
UNMATCHED: tuple[str, ...] = ()


class RecurrentTrajectory(struct.PyTreeNode):
    """One rollout, time first (``(num_steps, num_envs, ...)``): rejax's ``Trajectory``, each
    step's episode-start flag (the LSTMs' carries are cleared before that step) and the
    actor's and the critic's carries ``(h, c)`` before that step, as the rollout had them
    (before the clearing): ``RecurrentRolloutBuffer``'s ``hidden_states_pi``,
    ``cell_states_pi``, ``hidden_states_vf`` and ``cell_states_vf``."""

    obs: jax.Array
    action: jax.Array
    log_prob: jax.Array
    reward: jax.Array
    value: jax.Array
    done: jax.Array
    start: jax.Array
    actor_carry: Any
    critic_carry: Any


class Rollout(struct.PyTreeNode):
    """A rollout with its advantages and value targets (each ``(num_steps, num_envs)``): what
    ``RecurrentRolloutBuffer`` holds once ``compute_returns_and_advantage`` has run."""

    trajectories: RecurrentTrajectory
    advantages: jax.Array
    targets: jax.Array


class SequenceMinibatch(Rollout):
    """One minibatch as rows of whole sequences, time first (``(num_steps, rows, ...)``):
    ``mask`` marks the minibatch's samples (sb3-contrib's padding is the rest), ``begin`` the
    steps where a sequence begins from the carries stored there (``_get_samples``'
    ``lstm_states``) rather than from the replay's own."""

    mask: jax.Array
    begin: jax.Array


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
        """One rollout (module docstring): ``(ts, trajectory)``, each step's carries before
        the step stored in the trajectory."""
        def env_step(ts: Any, unused: Any) -> Any:
            ts, rng_steps, rng_action = self.step_keys(ts)
            start = ts.last_done
            stored = (ts.actor_carry, ts.critic_carry)     # sb3-contrib's _last_lstm_states
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
                                             value, done, start, *stored)
            ts = ts.replace(env_state=env_state, last_obs=next_obs, last_done=done,
                            global_step=ts.global_step + self.num_envs)
            return ts, transition

        return jax.lax.scan(env_step, ts, None, self.num_steps)

    # ------------------------------------------------------------------ the update
    def train_iteration(self, ts: Any) -> Any:
        ts, trajectories = self.collect_trajectories(ts)
        _, last_val = self.critic_step(ts.critic_ts.params, ts.critic_carry, ts.last_obs,
                                       ts.last_done)
        last_val = jnp.where(ts.last_done, 0, last_val)
        advantages, targets = self.calculate_gae(trajectories, last_val)
        rollout = Rollout(trajectories, advantages, targets)

        def update_epoch(ts: Any, unused: Any) -> Any:
            # one RecurrentRolloutBuffer.get: one split, its slices in order
            rng, split_rng = jax.random.split(ts.rng)
            ts = ts.replace(rng=rng)
            firsts = self.slice_starts(self.split_index(split_rng))

            def update_slice(ts: Any, first: Any) -> Any:
                return self.update(ts, self.minibatch(rollout, first)), None

            ts, _ = jax.lax.scan(update_slice, ts, firsts)
            return ts, None

        ts, _ = jax.lax.scan(update_epoch, ts, None, self.num_epochs)
        return ts

    @property
    def envs_per_minibatch(self) -> int:
        """``k``: the recipe's ``batch_size`` is ``k · num_steps`` samples."""
        if self.num_envs % self.num_minibatches:
            raise ValueError(f"RecurrentPPO needs batch_size = k x num_steps: num_envs "
                             f"({self.num_envs}) divisible by num_minibatches "
                             f"({self.num_minibatches})")
        return self.num_envs // self.num_minibatches

    def split_index(self, rng: Any) -> Any:
        """``RecurrentRolloutBuffer.get``'s ``split_index``: uniform over the rollout's
        ``num_envs · num_steps`` samples (``np.random.randint``), drawn from ``rng``."""
        return jax.random.randint(rng, (), 0, self.num_envs * self.num_steps)

    def slice_starts(self, split: Any) -> Any:
        """``(num_minibatches,)``: the env-major flat index where each of ``get``'s slices
        begins when the indices are rotated by ``split`` (``indices[split:] +
        indices[:split]``, cut every ``batch_size``)."""
        batch_size = self.envs_per_minibatch * self.num_steps
        return (split + batch_size * jnp.arange(self.num_minibatches)) % (
            self.num_envs * self.num_steps)

    def minibatch(self, rollout: Rollout, first: Any) -> SequenceMinibatch:
        """``get``'s slice of ``batch_size = k · T`` samples from env-major flat index
        ``first`` on, as ``_get_samples`` cuts it into sequences (module docstring): env ``e0 =
        first // T`` from ``t0 = first % T`` on, envs ``e0+1 … e0+k−1`` whole, env ``e0+k``
        (mod ``num_envs``) before ``t0`` — the ``k + 1`` rows of those envs' whole sequences,
        the mask of the slice's samples, and where a sequence begins from its stored carries:
        row 0 at ``t0`` (the slice's first sample), every other row at step 0 (an env
        change). The episode starts inside a row begin sequences by clearing the carry, as
        the stored carry times ``1 − episode_start`` is zero there too."""
        k, steps = self.envs_per_minibatch, self.num_steps
        e0, t0 = first // steps, first % steps
        envs = (e0 + jnp.arange(k + 1)) % self.num_envs
        t = jnp.arange(steps)[:, None]                   # (T, 1)
        row = jnp.arange(k + 1)[None, :]                 # (1, k + 1)
        mask = jnp.where(row == 0, t >= t0, jnp.where(row == k, t < t0, True))
        begin = jnp.where(row == 0, t == t0, t == 0)

        def rows(x: Any) -> Any:                         # (T, E, ...) -> (T, k + 1, ...)
            return jnp.take(x, envs, axis=1)

        return SequenceMinibatch(jax.tree.map(rows, rollout.trajectories),
                                 rows(rollout.advantages), rows(rollout.targets), mask, begin)

    def actor_objective(self, params: Any, batch: Any) -> Any:
        """``RecurrentPPO.train``'s policy loss on the minibatch (:func:`fir_gym.jax.ppo.
        actor_loss` with its mask), its sequences replayed through the actor's LSTM from their
        stored carries."""
        t = batch.trajectories
        latent = lstm.replay(self.cell, params["lstm"], t.actor_carry, t.obs, t.start,
                             batch.begin)
        log_prob, entropy = self.actor.apply(params["head"], _flat(latent), _flat(t.action),
                                             method="log_prob_entropy")
        return actor_loss(self, log_prob, entropy, _flat(t.log_prob), _flat(batch.advantages),
                          _flat(batch.mask))

    def critic_objective(self, params: Any, batch: Any) -> Any:
        """``vf_coef`` times the values' squared error, its mean over the minibatch's mask
        (``RecurrentPPO.train``'s ``value_loss``), replayed through the critic's LSTM."""
        t = batch.trajectories
        latent = lstm.replay(self.cell, params["lstm"], t.critic_carry, t.obs, t.start,
                             batch.begin)
        value = self.critic.apply(params["head"], _flat(latent))
        return self.vf_coef * masked_mean(jnp.square(value - _flat(batch.targets)),
                                           _flat(batch.mask))


def _flat(x: Any) -> Any:
    """``(T, B, ...)`` -> ``(T·B, ...)``: the heads take one batch axis."""
    return x.reshape((x.shape[0] * x.shape[1], *x.shape[2:]))
