"""rejax's PPO made stable-baselines3's: the algorithm of :mod:`fir_gym.jax.train`.

**rejax as used here.** rejax 0.1.3 is written for gymnax 0.0.x, whose ``step`` returned
``(obs, state, reward, done, info)``; gymnax 1.0 returns ``terminated`` and ``truncated``
apart. :class:`Gymnax0` adapts the environment (``done = terminated | truncated``).
:class:`SB3LikePPO` subclasses ``rejax.PPO`` where it differs from stable-baselines3's
PPO in a way that changes learning: one gradient-norm clip over the actor's and the critic's
gradients together, as SB3's ``clip_grad_norm_`` over all the policy's parameters
(:func:`clip_jointly`; rejax clips each gradient *element* with ``optax.clip``), Adam's
``eps = 1e-5`` (SB3's),
an initial ``log_std`` of the recipe's ``log_std_init`` (rejax: 0), SB3's orthogonal
initialisation (gains √2, 0.01 for the mean, 1 for the value; rejax: flax's LeCun normal,
which starts the mean action far from 0), the value loss
unclipped (SB3's ``clip_range_vf=None``; rejax clips it with ``clip_eps``), each
minibatch's advantages normalised by their unbiased standard deviation (SB3's ``th.std``;
rejax: the biased one; :func:`actor_loss`), observations
(and rewards) normalised then clipped to ``±clip_obs`` (``±clip_reward``) as
``VecNormalize`` does, and the bootstrap of episodes cut by the time limit
(:meth:`SB3LikePPO.collect_trajectories`; rejax ends the return there): SB3's
``OnPolicyAlgorithm.collect_rollouts`` adds ``γ V(terminal observation)`` to the normalised
reward of a step that is ``TimeLimit.truncated`` (truncated and not terminated), the terminal
observation normalised as ``VecNormalize.step_wait`` does (with the statistics after that
step's update); gymnax 1.0's ``info["final_observation"]``, ``info["truncated"]`` and
``info["terminated"]`` give the same here.

**What still differs from stable-baselines3** (:data:`UNMATCHED`): nothing in what is
trained. The actor and the critic keep separate Adam states, which is SB3's one Adam over
both networks (Adam is elementwise and the networks share no parameter), with the one clip
above; the recipe refuses minibatches that do not divide the rollout (``n_steps · n_envs /
batch_size`` an integer: SB3 allows a short last one). Two
differences of rejax's normalisation are matched too: the running discounted return behind
the reward statistics restarts one step after an episode's last (``VecNormalize.
_update_reward``, then ``returns[dones] = 0``; rejax's ``update_rew_rms``, ``r + (1 − done)
γ R``, restarts it at the last step: :meth:`SB3LikePPO.update_rew_rms`), and the first
observations of training are counted in the statistics and normalised, as
``VecNormalize.reset`` does (:meth:`SB3LikePPO.init_state`).
"""

from __future__ import annotations

import math
from typing import Any

from fir_gym._extras import require

require("jax", "gymnax", "rejax")

import gymnax.environments.environment as gymnax_env  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import optax  # noqa: E402
from flax import linen as nn  # noqa: E402
from flax import struct  # noqa: E402
from flax.linen.initializers import constant  # noqa: E402
from flax.training.train_state import TrainState  # noqa: E402
from rejax import PPO  # noqa: E402
from rejax.algos.algorithm import register_init  # noqa: E402
from rejax.algos.mixins import RewardRMSState, RMSState, update_rms  # noqa: E402
from rejax.algos.ppo import Trajectory  # noqa: E402
from rejax.networks import GaussianPolicy  # noqa: E402

from .permutation import permutation  # noqa: E402

#: the parts of the recipe not matched (the module docstring says why): none since the
#: gradient-norm clip is one over both networks (:func:`clip_jointly`)
UNMATCHED: tuple[str, ...] = ()
#: stable-baselines3's Adam epsilon
ADAM_EPS = 1e-5
#: the networks' arithmetic (``Recipe.network_dtype``): float32 by default, as PyTorch's
#: modules compute in stable-baselines3; the plants, the filters, the normalisation
#: statistics, the returns and the advantages stay float64
NETWORK_DTYPES = {"float32": jnp.float32, "float64": jnp.float64}


class Gymnax0(gymnax_env.Environment):
    """A gymnax 1.0 environment seen through gymnax 0.0.x's ``step`` (what rejax unpacks):
    ``(obs, state, reward, terminated | truncated, info)``."""

    def __init__(self, env: Any) -> None:
        super().__init__()
        self.env = env

    def __hash__(self) -> int:               # a static argument of jit: by the wrapped env
        return hash((Gymnax0, id(self.env)))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Gymnax0) and other.env is self.env

    @property
    def default_params(self) -> Any:
        return self.env.default_params

    def step(self, key: Any, state: Any, action: Any, params: Any = None) -> Any:
        obs, state, reward, terminated, truncated, info = self.env.step(key, state, action,
                                                                         params)
        return obs, state, reward, terminated | truncated, info

    def reset(self, key: Any, params: Any = None) -> Any:
        return self.env.reset(key, params)

    def observation_space(self, params: Any) -> Any:
        return self.env.observation_space(params)

    def action_space(self, params: Any = None) -> Any:
        return self.env.action_space(params)


def _dense(features: int, gain: float, dtype: Any) -> nn.Dense:
    """A layer initialised as stable-baselines3's ``ortho_init``: orthogonal weights of
    ``gain``, zero biases; parameters and arithmetic in ``dtype``."""
    return nn.Dense(features, kernel_init=nn.initializers.orthogonal(gain),
                    bias_init=nn.initializers.zeros, dtype=dtype, param_dtype=dtype)


class Features(nn.Module):
    """SB3's MLP extractor: hidden layers with orthogonal weights of gain √2, computing in
    ``dtype`` (the input is cast to it first: :data:`NETWORK_DTYPES`)."""

    hidden_layer_sizes: tuple[int, ...]
    activation: Any
    dtype: Any = jnp.float32

    @nn.compact
    def __call__(self, x: Any) -> Any:
        x = x.reshape((x.shape[0], -1)).astype(self.dtype)
        for size in self.hidden_layer_sizes:
            x = self.activation(_dense(size, math.sqrt(2.0), self.dtype)(x))
        return x


class Critic(nn.Module):
    """The value network: :class:`Features`, then one output of gain 1 (SB3's), computing in
    ``dtype``; the value is returned in float64, the rewards', in which the returns and the
    advantages are computed."""

    hidden_layer_sizes: tuple[int, ...]
    activation: Any
    dtype: Any = jnp.float32

    @nn.compact
    def __call__(self, obs: Any) -> Any:
        x = Features(self.hidden_layer_sizes, self.activation, self.dtype)(obs)
        return _dense(1, 1.0, self.dtype)(x).squeeze(1).astype(jnp.float64)


class Policy(GaussianPolicy):
    """rejax's Gaussian policy initialised as SB3's (:class:`Features`, the mean's layer of
    gain 0.01, ``log_std`` = ``log_std_init``), with a deterministic action, computing in
    ``dtype`` (its actions and log-probabilities are of that dtype)."""

    log_std_init: float = 0.0
    dtype: Any = jnp.float32

    def setup(self) -> None:
        self.features = Features(tuple(self.hidden_layer_sizes), self.activation, self.dtype)
        self.action_mean = _dense(self.action_dim, 0.01, self.dtype)
        self.action_log_std = self.param("action_log_std", constant(self.log_std_init),
                                         (self.action_dim,), self.dtype)

    def mean_action(self, obs: Any) -> Any:
        mean = self.action_mean(self.features(obs))
        return jnp.clip(mean, self.action_range[0], self.action_range[1])


class SB3LikePPO(PPO):
    """``rejax.PPO`` closer to stable-baselines3's (module docstring)."""

    clip_obs: float = struct.field(pytree_node=False, default=math.inf)
    clip_reward: float = struct.field(pytree_node=False, default=math.inf)
    #: the networks' arithmetic, a key of :data:`NETWORK_DTYPES`
    network_dtype: str = struct.field(pytree_node=False, default="float32")

    @register_init
    def initialize_network_params(self, rng: Any) -> dict[str, Any]:
        rng, rng_actor, rng_critic = jax.random.split(rng, 3)
        obs = jnp.empty([1, *self.env.observation_space(self.env_params).shape])
        return self.train_states(self.actor.init(rng_actor, obs, rng_actor),
                                 self.critic.init(rng_critic, obs))

    def train_states(self, actor_params: Any, critic_params: Any) -> dict[str, Any]:
        """The actor's and the critic's train states: each its own Adam (SB3's ``eps``), given
        the gradients :meth:`update` has clipped together."""
        tx = optax.adam(learning_rate=self.learning_rate, eps=ADAM_EPS)
        return {"actor_ts": TrainState.create(apply_fn=(), params=actor_params, tx=tx),
                "critic_ts": TrainState.create(apply_fn=(), params=critic_params, tx=tx)}

    @register_init
    def initialize_obs_rms_state(self, rng: Any) -> dict[str, Any]:
        # float64 (VecNormalize's RunningMeanStd; rejax's float32 breaks the scan under x64)
        shape = self.env.observation_space(self.env_params).shape
        return {"obs_rms_state": RMSState(mean=jnp.zeros(shape), var=jnp.ones(shape),
                                          count=jnp.asarray(1e-4))}

    @register_init
    def initialize_reward_rms_state(self, rng: Any) -> dict[str, Any]:
        return {"rew_rms_state": RewardRMSState(
            mean=jnp.zeros(()), var=jnp.ones(()), count=jnp.asarray(1e-4),
            returns=jnp.zeros(self.num_envs))}

    def init_state(self, rng: Any) -> Any:
        """rejax's initial state, its first observations counted in the statistics and
        normalised, as ``VecNormalize.reset`` does (rejax leaves them raw and uncounted)."""
        ts = super().init_state(rng)
        if self.normalize_observations:
            rms, first = self.update_and_normalize_obs(ts.obs_rms_state, ts.last_obs)
            ts = ts.replace(obs_rms_state=rms, last_obs=first)
        return ts

    def update_rew_rms(self, rms_state: Any, rewards: Any, dones: Any, batched: bool = True
                       ) -> Any:
        """``VecNormalize._update_reward`` and its reset of the finished envs' returns: the
        running discounted return ``R ← γ R + r`` counted in the statistics, then set to 0
        where an episode ended (rejax's ``r + (1 − done) γ R`` restarts it one step early)."""
        returns = self.reward_normalization_discount * rms_state.returns + rewards
        rms_state = update_rms(rms_state.replace(returns=returns), returns, batched=batched)
        return rms_state.replace(returns=jnp.where(dones, 0.0, returns))

    def normalize_obs(self, rms_state: Any, x: Any) -> Any:
        return jnp.clip(super().normalize_obs(rms_state, x), -self.clip_obs, self.clip_obs)

    def normalize_rew(self, rms_state: Any, r: Any) -> Any:
        return jnp.clip(super().normalize_rew(rms_state, r), -self.clip_reward,
                        self.clip_reward)

    def truncation_bootstrap(self, ts: Any, info: dict[str, Any], obs_rms_state: Any
                             ) -> Any:
        """What stable-baselines3's PPO adds to a step's (normalised) reward: ``γ V(final
        obs)`` where the episode ended by its time limit and not by termination, else 0.

        SB3's ``OnPolicyAlgorithm.collect_rollouts`` ("Handle timeout by bootstrapping with
        value function") adds ``gamma * predict_values(terminal_observation)`` where a step
        is ``done`` with ``infos["TimeLimit.truncated"]`` (``DummyVecEnv.step_wait``:
        ``truncated and not terminated``), the value of the rollout's policy (the critic
        before this iteration's update). The terminal observation is normalised as
        ``VecNormalize.step_wait`` normalises ``infos["terminal_observation"]``: with the
        observation statistics *after* that step's update (an update by the step's returned
        observations, which at a reset are the next episode's first, never the terminal
        one), then clipped. gymnax 1.0's ``step`` returns the terminal observation as
        ``info["final_observation"]`` and the flags as ``info["truncated"]`` and
        ``info["terminated"]``; ``obs_rms_state`` is the statistics after the step's update.
        """
        final = info["final_observation"].astype(float)   # as rejax's FloatObsWrapper
        if self.normalize_observations:
            final = self.normalize_obs(obs_rms_state, final)
        by_time_limit = info["truncated"] & ~info["terminated"]
        return jnp.where(by_time_limit, self.gamma * self.final_value(ts, final), 0.0)

    def final_value(self, ts: Any, final: Any) -> Any:
        """The critic's value of the (normalised) terminal observations ``final``."""
        return self.critic.apply(ts.critic_ts.params, final)

    def collect_trajectories(self, ts: Any) -> Any:
        """rejax's ``PPO.collect_trajectories`` with stable-baselines3's bootstrap of episodes
        cut by the time limit (:meth:`truncation_bootstrap`) added to the normalised reward,
        as ``OnPolicyAlgorithm.collect_rollouts`` adds it before ``rollout_buffer.add``; the
        rest is rejax's, line for line (the ``done`` of a truncation still ends the return
        in :meth:`calculate_gae`, as SB3's ``episode_starts`` do)."""
        def env_step(ts: Any, unused: Any) -> Any:
            ts, rng_steps, rng_action = self.step_keys(ts)
            unclipped_action, log_prob = self.actor.apply(
                ts.actor_ts.params, ts.last_obs, rng_action, method="action_log_prob")
            value = self.critic.apply(ts.critic_ts.params, ts.last_obs)
            ts, next_obs, env_state, reward, done = self.step_envs(ts, rng_steps,
                                                                   unclipped_action)
            transition = Trajectory(ts.last_obs, unclipped_action, log_prob, reward, value,
                                    done)
            ts = ts.replace(env_state=env_state, last_obs=next_obs, last_done=done,
                            global_step=ts.global_step + self.num_envs)
            return ts, transition

        return jax.lax.scan(env_step, ts, None, self.num_steps)

    def step_keys(self, ts: Any) -> tuple[Any, Any, Any]:
        """``(ts, the envs' step keys, the action's key)``: one rollout step's keys from
        ``ts.rng`` (rejax's splits)."""
        rng, new_rng = jax.random.split(ts.rng)
        rng_steps, rng_action = jax.random.split(new_rng, 2)
        return ts.replace(rng=rng), jax.random.split(rng_steps, self.num_envs), rng_action

    def step_envs(self, ts: Any, rng_steps: Any, unclipped_action: Any
                  ) -> tuple[Any, Any, Any, Any, Any]:
        """The envs' part of a rollout step, after the policy acted: the action clipped to
        the box, every env stepped, the observation and reward statistics updated and both
        normalised, the time-limit bootstrap added (:meth:`truncation_bootstrap`, the critic
        as ``ts`` has it). Returns ``(ts, next observations, env states, rewards, dones)``."""
        space = self.env.action_space(self.env_params)
        action = jnp.clip(unclipped_action, space.low, space.high)
        next_obs, env_state, reward, done, info = self.vmap_step(
            rng_steps, ts.env_state, action, self.env_params)
        if self.normalize_observations:
            obs_rms_state, next_obs = self.update_and_normalize_obs(ts.obs_rms_state, next_obs)
            ts = ts.replace(obs_rms_state=obs_rms_state)
        if self.normalize_rewards:
            rew_rms_state, reward = self.update_and_normalize_rew(ts.rew_rms_state, reward,
                                                                  done)
            ts = ts.replace(rew_rms_state=rew_rms_state)
        reward = reward + self.truncation_bootstrap(ts, info, ts.obs_rms_state)
        return ts, next_obs, env_state, reward, done

    def shuffle_and_split(self, data: Any, rng: Any) -> Any:
        """rejax's ``shuffle_and_split``: the iteration's samples permuted, then cut into the
        minibatches — the permutation ``jax.random.permutation(rng, n)``'s integers, drawn by
        :func:`fir_gym.jax.permutation.permutation` (XLA's CPU backend sorted the samples
        in about a quarter of PPO's own time; this sort is 4.7 times as fast)."""
        order = permutation(rng, self.iteration_size)

        def split(x: Any) -> Any:
            x = jnp.take(x.reshape((self.iteration_size, *x.shape[2:])), order, axis=0)
            return x.reshape(self.num_minibatches, -1, *x.shape[1:])

        return jax.tree.map(split, data)

    def update(self, ts: Any, batch: Any) -> Any:
        """One minibatch's step, as SB3's ``PPO.train``: the gradients of the policy loss
        (:meth:`actor_objective`) and of the value loss (:meth:`critic_objective`) — SB3's
        one summed loss, whose gradient splits so over the two networks — clipped together
        (:func:`clip_jointly`), then each network's Adam step."""
        actor_grads = jax.grad(self.actor_objective)(ts.actor_ts.params, batch)
        critic_grads = jax.grad(self.critic_objective)(ts.critic_ts.params, batch)
        actor_grads, critic_grads = clip_jointly((actor_grads, critic_grads),
                                                 self.max_grad_norm)
        return ts.replace(actor_ts=ts.actor_ts.apply_gradients(grads=actor_grads),
                          critic_ts=ts.critic_ts.apply_gradients(grads=critic_grads))

    def actor_objective(self, params: Any, batch: Any) -> Any:
        """SB3's policy loss on ``batch`` (:func:`actor_loss`)."""
        log_prob, entropy = self.actor.apply(params, batch.trajectories.obs,
                                             batch.trajectories.action,
                                             method="log_prob_entropy")
        return actor_loss(self, log_prob, entropy, batch.trajectories.log_prob,
                          batch.advantages)

    def critic_objective(self, params: Any, batch: Any) -> Any:
        """SB3's value loss on ``batch``: ``vf_coef`` times the mean squared error, no value
        clipping."""
        value = self.critic.apply(params, batch.trajectories.obs)
        return self.vf_coef * jnp.mean(jnp.square(value - batch.targets))

    # the deterministic policy, as the evaluations play it (a recurrent one carries a state)
    def policy_carry(self, batch: int) -> Any:
        """What the deterministic policy carries from step to step: nothing (feed-forward)."""
        return None

    def policy_action(self, actor_params: Any, carry: Any, obs: Any, start: Any
                      ) -> tuple[Any, Any]:
        """``(carry, actions)``: the Gaussian's mean clipped to the action box for the
        (normalised) observations ``obs (batch, n)``; ``start`` marks an episode's first step."""
        return carry, self.actor.apply(actor_params, obs, method="mean_action")


def clip_jointly(grads: Any, max_norm: float) -> Any:
    """``grads`` (any tree: here the actor's and the critic's) scaled by one factor so that
    their global norm is at most ``max_norm``, as ``torch.nn.utils.clip_grad_norm_`` does over
    all of SB3's policy's parameters: ``min(1, max_norm / (‖g‖ + 1e-6))``."""
    norm = optax.global_norm(grads)
    scale = jnp.minimum(1.0, max_norm / (norm + 1e-6))
    return jax.tree.map(lambda g: (g * scale).astype(g.dtype), grads)


def actor_loss(algo: Any, log_prob: Any, entropy: Any, old_log_prob: Any, advantages: Any,
               mask: Any = None) -> Any:
    """stable-baselines3's PPO policy loss on a minibatch: the clipped surrogate of the
    advantages normalised with the minibatch's mean and *unbiased* standard deviation
    (``th.std``; rejax's ``update_actor`` divides by the biased one), minus ``ent_coef`` times
    the mean entropy. With ``mask`` (sb3-contrib's ``RecurrentPPO.train``, whose minibatches
    are padded sequences) every mean and the normalisation are over the masked samples only
    (``x[mask]``), and a padded sample's ratio is 1: the exponential of a log-ratio that is
    masked out could overflow and, times its zero weight, give a NaN gradient."""
    mask = jnp.ones(advantages.shape, bool) if mask is None else mask
    n = jnp.sum(mask)
    mean = masked_mean(advantages, mask)
    std = jnp.sqrt(jnp.sum(jnp.where(mask, jnp.square(advantages - mean), 0.0)) / (n - 1))
    advantages = (advantages - mean) / (std + 1e-8)
    ratio = jnp.exp(jnp.where(mask, log_prob - old_log_prob, 0.0))
    clipped = jnp.clip(ratio, 1 - algo.clip_eps, 1 + algo.clip_eps)
    surrogate = -masked_mean(jnp.minimum(ratio * advantages, clipped * advantages), mask)
    return surrogate - algo.ent_coef * masked_mean(entropy, mask)


def masked_mean(x: Any, mask: Any) -> Any:
    """``th.mean(x[mask])``: the mean of ``x`` over the samples where ``mask`` is set."""
    return jnp.sum(jnp.where(mask, x, 0.0)) / jnp.sum(mask)
