"""fir_gym.jax.recurrent_ppo: the ``recurrent`` kind's PPO, against sb3-contrib's RecurrentPPO.

Oracles that cannot share its bugs:
* ``torch.nn.LSTM`` for the cell (:mod:`fir_gym.jax.lstm`), in float64;
* sb3-contrib's ``RecurrentActorCriticPolicy`` built with the shipped recipe's policy keywords
  (``ppo_lstm.yml``), in float64, its parameters copied into ours: the same actions,
  log-probabilities, entropies and values over sequences crossing episode starts, step by step
  (the rollout, ``predict``) and as whole sequences (``evaluate_actions``, what the update
  replays), and the same gradients of SB3's PPO loss (torch's autograd through its LSTM);
* the rollout replayed by that torch policy: each stored value, log-probability and LSTM
  state, the episode-start flags, and the bootstrap of an episode cut by its time limit;
* sb3-contrib's own ``RecurrentRolloutBuffer``, filled and its split index chosen: each of our
  minibatches holds its minibatch's samples, and our update's gradients are those of
  ``RecurrentPPO.train``'s masked loss on it (torch's autograd through its padded sequences
  begun from the stored states, then ``clip_grad_norm_``);
* a task only memory solves (:class:`Cue`): the recurrent PPO learns it, the feed-forward PPO
  on the same observations cannot.

The comparisons with torch run our networks in float64 (``network_dtype="float64"``) against
torch's double-precision modules, where agreement to 1e-12 tells a wrong formula from
round-off; the shipped float32 networks are compared with sb3-contrib's float32 policy as it
is built, to float32's round-off.
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
pytest.importorskip("torch")
pytest.importorskip("sb3_contrib")

import gymnasium as gym
import jax
import jax.numpy as jnp
import torch
from flax import struct
from gymnax.environments import environment, spaces
from jax_runs import ORBIT
from sb3_contrib.common.recurrent.buffers import RecurrentRolloutBuffer
from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy
from sb3_contrib.common.recurrent.type_aliases import RNNStates
from sb3_in_double import in_double
from ticker import Ticker, TickerParams
from update_gradients import update_gradients

from fir_gym.jax import lstm
from fir_gym.jax import train as jt
from fir_gym.jax.recurrent_ppo import (
    RecurrentPPO,
    RecurrentTrajectory,
    Rollout,
    SequenceMinibatch,
)

H = 64                       # the shipped recipe's lstm_hidden_size


# ---------------------------------------------------------------------------- the torch twin
def recurrent_algorithm(env: Any, params: Any, **changes: Any
                        ) -> tuple[RecurrentPPO, jt.Recipe]:
    """The shipped recurrent recipe (``changes`` applied) on ``env``."""
    rec = dataclasses.replace(jt.recipe(ORBIT, kind="recurrent"), **changes)
    algo = jt.make_algorithm(env, params, rec)
    assert isinstance(algo, RecurrentPPO)
    return algo, rec


def torch_policy(n_obs: int, seed: int = 0, double: bool = True) -> Any:
    """sb3-contrib's policy as the SB3 backend builds it for ``recurrent`` (ppo_lstm.yml's
    policy keywords), in float64 (``double=False``: in float32, as built)."""
    torch.manual_seed(seed)
    policy = RecurrentActorCriticPolicy(
        gym.spaces.Box(-np.inf, np.inf, (n_obs,), np.float64),
        gym.spaces.Box(-1.0, 1.0, (1,), np.float32), lambda _: 1e-3,
        log_std_init=-1.0, lstm_hidden_size=H, enable_critic_lstm=True)
    return in_double(policy) if double else policy


def t(x: Any) -> Any:
    return torch.tensor(np.array(x, dtype=np.float64))


def ours_from_torch(policy: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """The torch policy's parameters in our layout: ``(actor params, critic params)``."""
    p = {k: v.detach().numpy() for k, v in policy.state_dict().items()}

    def cell(prefix: str) -> dict[str, Any]:
        return {"params": {name: jnp.asarray(p[f"{prefix}.{name}_l0"])
                           for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")}}

    def dense(name: str) -> dict[str, Any]:
        return {"kernel": jnp.asarray(p[f"{name}.weight"].T),
                "bias": jnp.asarray(p[f"{name}.bias"])}

    actor = {"lstm": cell("lstm_actor"), "head": {"params": {
        "features": {"Dense_0": dense("mlp_extractor.policy_net.0"),
                     "Dense_1": dense("mlp_extractor.policy_net.2")},
        "action_mean": dense("action_net"), "action_log_std": jnp.asarray(p["log_std"])}}}
    critic = {"lstm": cell("lstm_critic"), "head": {"params": {
        "Features_0": {"Dense_0": dense("mlp_extractor.value_net.0"),
                       "Dense_1": dense("mlp_extractor.value_net.2")},
        "Dense_0": dense("value_net")}}}
    return actor, critic


def torch_states(actor: lstm.Carry, critic: lstm.Carry) -> Any:
    def one(carry: lstm.Carry) -> tuple[Any, Any]:
        return t(carry[0])[None].contiguous(), t(carry[1])[None].contiguous()

    return RNNStates(pi=one(actor), vf=one(critic))


def sequences(rng: np.random.Generator, steps: int, batch: int, n_obs: int
              ) -> tuple[np.ndarray, np.ndarray, lstm.Carry, lstm.Carry]:
    """Observations ``(T, B, n)``, episode starts ``(T, B)`` (each env starts episodes at
    other steps, the first step included for one), and random carries to begin from."""
    obs = (rng.normal(size=(steps, batch, n_obs)) * 2.0).astype(np.float32).astype(float)
    starts = np.zeros((steps, batch), dtype=bool)
    starts[0, 0] = True
    starts[3, 1] = starts[7, 1] = True
    starts[1:, 2] = rng.random(steps - 1) < 0.3

    def carry() -> lstm.Carry:
        return (jnp.asarray(rng.normal(size=(batch, H)) * 0.3),
                jnp.asarray(rng.normal(size=(batch, H)) * 0.3))

    return obs, starts, carry(), carry()


def seq_major(x: np.ndarray) -> Any:
    """``(T, B, ...)`` -> sb3-contrib's sequence-major batch ``(B·T, ...)``."""
    x = np.swapaxes(np.asarray(x), 0, 1)
    return t(x.reshape((-1, *x.shape[2:])))


# ---------------------------------------------------------------------------- the cell
def test_the_lstm_cell_is_torch_nn_lstm() -> None:
    rng = np.random.default_rng(1)
    torch.manual_seed(1)
    layer = torch.nn.LSTM(3, 5).double()
    xs = rng.normal(size=(9, 4, 3))
    h0, c0 = rng.normal(size=(4, 5)), rng.normal(size=(4, 5))
    out, (h, c) = layer(t(xs), (t(h0)[None], t(c0)[None]))
    params = {"params": {name: jnp.asarray(getattr(layer, f"{name}_l0").detach().numpy())
                         for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")}}
    cell = lstm.LSTMCell(5, jnp.float64)
    (h_, c_), outs = lstm.unroll(cell, params, (jnp.asarray(h0), jnp.asarray(c0)),
                                 jnp.asarray(xs), jnp.zeros((9, 4), dtype=bool))
    assert np.max(np.abs(np.asarray(outs) - out.detach().numpy())) < 1e-14
    assert np.max(np.abs(np.asarray(c_) - c[0].detach().numpy())) < 1e-14
    assert np.max(np.abs(np.asarray(h_) - h[0].detach().numpy())) < 1e-14


def test_the_cell_is_cleared_at_an_episode_start_and_initialised_as_torch() -> None:
    cell = lstm.LSTMCell(4)
    params = cell.init(jax.random.PRNGKey(0), lstm.zeros(1, 4), jnp.zeros((1, 2)))
    x = jnp.ones((2, 2))
    carry = (jnp.full((2, 4), 7.0), jnp.full((2, 4), -3.0))
    cleared = lstm.step(cell, params, carry, x, jnp.array([True, False]))
    fresh = lstm.step(cell, params, lstm.zeros(2, 4), x, jnp.array([False, False]))
    kept = cell.apply(params, carry, x)
    assert np.array_equal(np.asarray(cleared[0][0]), np.asarray(fresh[0][0]))
    assert np.array_equal(np.asarray(cleared[1][1]), np.asarray(kept[1][1]))
    leaves = jax.tree.leaves(params)
    assert all(np.max(np.abs(np.asarray(v))) <= 0.5 for v in leaves)      # U(±1/√4)
    assert min(np.max(np.abs(np.asarray(v))) for v in leaves) > 0.2       # not all zeros


# ---------------------------------------------------------------------------- the networks
@pytest.fixture(scope="module")
def orbit() -> tuple[RecurrentPPO, Any]:
    env, params = jt.make_env(ORBIT, "recurrent")
    return (recurrent_algorithm(env, params, network_dtype="float64")[0],
            env.observation_space(params).shape[0])


def test_our_parameters_have_sb3_contribs_shapes(orbit: tuple[RecurrentPPO, Any]) -> None:
    algo, n_obs = orbit
    ts = algo.init_state(jax.random.PRNGKey(0))
    actor, critic = ours_from_torch(torch_policy(n_obs))
    for ours, theirs in ((ts.actor_ts.params, actor), (ts.critic_ts.params, critic)):
        assert jax.tree.structure(ours) == jax.tree.structure(theirs)
        assert jax.tree.map(np.shape, ours) == jax.tree.map(np.shape, theirs)
    assert np.array_equal(np.asarray(ts.actor_ts.params["head"]["params"]["action_log_std"]),
                          [-1.0])


def test_sequences_give_sb3_contribs_values_log_probs_and_entropies(
        orbit: tuple[RecurrentPPO, Any]) -> None:
    algo, n_obs = orbit
    policy = torch_policy(n_obs)
    actor, critic = ours_from_torch(policy)
    rng = np.random.default_rng(2)
    obs, starts, actor0, critic0 = sequences(rng, 12, 3, n_obs)
    actions = rng.normal(size=(12, 3, 1)) * 0.5
    values, log_prob, entropy = policy.evaluate_actions(
        seq_major(obs), seq_major(actions), torch_states(actor0, critic0), seq_major(starts))

    _, latent = lstm.unroll(algo.cell, actor["lstm"], actor0, jnp.asarray(obs),
                            jnp.asarray(starts))
    ours_lp, ours_ent = algo.actor.apply(actor["head"], latent.reshape(36, H),
                                         jnp.asarray(actions).reshape(36, 1),
                                         method="log_prob_entropy")
    _, latent_v = lstm.unroll(algo.cell, critic["lstm"], critic0, jnp.asarray(obs),
                              jnp.asarray(starts))
    ours_v = algo.critic.apply(critic["head"], latent_v.reshape(36, H))

    def as_seq_major(x: Any) -> np.ndarray:
        return np.swapaxes(np.asarray(x).reshape(12, 3), 0, 1).reshape(-1)

    assert np.max(np.abs(as_seq_major(ours_lp) - log_prob.detach().numpy())) < 1e-12
    assert np.max(np.abs(as_seq_major(ours_v) - values.detach().numpy()[:, 0])) < 1e-12
    assert np.max(np.abs(np.asarray(ours_ent) - entropy.detach().numpy())) < 1e-12


def test_step_by_step_gives_sb3_contribs_deterministic_actions(
        orbit: tuple[RecurrentPPO, Any]) -> None:
    algo, n_obs = orbit
    policy = torch_policy(n_obs, seed=5)
    actor, _ = ours_from_torch(policy)
    rng = np.random.default_rng(3)
    obs, starts, _, _ = sequences(rng, 10, 3, n_obs)
    # predict()'s own lines, but for its cast of the LSTM state to float32: zeros to begin,
    # _predict, the action clipped to the box
    theirs_state = (torch.zeros(1, 3, H, dtype=torch.float64),) * 2
    ours_carry = algo.policy_carry(3)
    for step in range(10):
        with torch.no_grad():
            theirs, theirs_state = policy._predict(t(obs[step]), lstm_states=theirs_state,
                                                   episode_starts=t(starts[step]),
                                                   deterministic=True)
        theirs = np.clip(theirs.numpy(), -1.0, 1.0)
        ours_carry, ours = algo.policy_action(actor, ours_carry, jnp.asarray(obs[step]),
                                              jnp.asarray(starts[step]))
        assert np.max(np.abs(np.asarray(ours) - theirs)) < 1e-12
        assert np.max(np.abs(np.asarray(ours_carry[1]) - theirs_state[1][0].numpy())) < 1e-12


def test_in_float32_the_networks_are_sb3_contribs_float32_policy() -> None:
    """The shipped networks (float32 parameters, carries and arithmetic) against sb3-contrib's
    policy as it is built (float32), its parameters copied: values, log-probabilities and
    entropies over sequences with episode starts, and the deterministic actions step by step,
    to float32's round-off (a few units of 1e-7 of each quantity's scale, through 12 LSTM
    steps); the values come out in float64, the rewards' dtype."""
    env, params = jt.make_env(ORBIT, "recurrent")
    algo, _ = recurrent_algorithm(env, params)
    n_obs = env.observation_space(params).shape[0]
    ts = algo.init_state(jax.random.PRNGKey(0))
    networks = jax.tree.leaves((ts.actor_ts.params, ts.actor_ts.opt_state, ts.critic_ts.params,
                                ts.critic_ts.opt_state, ts.actor_carry, ts.critic_carry))
    assert {np.asarray(x).dtype for x in networks
            if np.issubdtype(np.asarray(x).dtype, np.floating)} == {np.dtype(np.float32)}
    policy = torch_policy(n_obs, seed=11, double=False)
    actor, critic = jax.tree.map(lambda x: x.astype(jnp.float32), ours_from_torch(policy))
    rng = np.random.default_rng(12)
    obs, starts, actor0, critic0 = sequences(rng, 12, 3, n_obs)
    actor0, critic0 = jax.tree.map(lambda x: x.astype(jnp.float32), (actor0, critic0))
    actions = rng.normal(size=(12, 3, 1)) * 0.5

    def f32(x: Any) -> Any:
        return torch.tensor(np.array(x, dtype=np.float32))

    def states(carry: lstm.Carry) -> tuple[Any, Any]:
        return f32(carry[0])[None].contiguous(), f32(carry[1])[None].contiguous()

    def sm(x: Any) -> Any:
        x = np.swapaxes(np.asarray(x), 0, 1)
        return f32(x.reshape((-1, *x.shape[2:])))

    with torch.no_grad():
        values, log_prob, entropy = policy.evaluate_actions(
            sm(obs), sm(actions), RNNStates(pi=states(actor0), vf=states(critic0)), sm(starts))
    _, latent = lstm.unroll(algo.cell, actor["lstm"], actor0, jnp.asarray(obs),
                            jnp.asarray(starts))
    ours_lp, ours_ent = algo.actor.apply(actor["head"], latent.reshape(36, H),
                                         jnp.asarray(actions, jnp.float32).reshape(36, 1),
                                         method="log_prob_entropy")
    _, latent_v = lstm.unroll(algo.cell, critic["lstm"], critic0, jnp.asarray(obs),
                              jnp.asarray(starts))
    ours_v = algo.critic.apply(critic["head"], latent_v.reshape(36, H))
    assert ours_lp.dtype == jnp.float32 and ours_v.dtype == jnp.float64

    def close(ours: Any, theirs: Any) -> None:
        ours = np.swapaxes(np.asarray(ours, dtype=float).reshape(12, 3), 0, 1).reshape(-1)
        theirs = theirs.numpy().astype(float).reshape(-1)
        assert np.max(np.abs(ours - theirs)) < 2e-6 * max(1.0, np.max(np.abs(theirs)))

    close(ours_lp, log_prob)
    close(ours_v, values)
    assert np.max(np.abs(np.asarray(ours_ent) - entropy.numpy())) < 2e-6
    carry, theirs_state = algo.policy_carry(3), (torch.zeros(1, 3, H),) * 2
    for step in range(12):
        with torch.no_grad():
            theirs, theirs_state = policy._predict(f32(obs[step]), lstm_states=theirs_state,
                                                   episode_starts=f32(starts[step]),
                                                   deterministic=True)
        carry, ours = algo.policy_action(actor, carry, jnp.asarray(obs[step]),
                                         jnp.asarray(starts[step]))
        assert np.max(np.abs(np.asarray(ours) - np.clip(theirs.numpy(), -1, 1))) < 2e-6


def sb3_loss(policy: Any, algo: RecurrentPPO, batch: dict[str, Any]) -> Any:
    """RecurrentPPO.train's loss on one minibatch of whole sequences (sb3-contrib's lines: the
    advantages normalised with th.std, the clipped surrogate, the entropy, vf_coef · mse)."""
    values, log_prob, entropy = policy.evaluate_actions(
        seq_major(batch["obs"]), seq_major(batch["action"]),
        torch_states(batch["actor0"], batch["critic0"]), seq_major(batch["start"]))
    advantages = seq_major(batch["advantages"])
    advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    ratio = torch.exp(log_prob - seq_major(batch["log_prob"]))
    surrogate = -torch.min(advantages * ratio,
                           advantages * torch.clamp(ratio, 1 - algo.clip_eps,
                                                    1 + algo.clip_eps)).mean()
    value_loss = torch.mean((seq_major(batch["targets"]) - values.flatten()) ** 2)
    return surrogate - algo.ent_coef * entropy.mean() + algo.vf_coef * value_loss


def torch_gradients(policy: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """The torch policy's gradients in our layout: ``(actor, critic)``."""
    return ours_from_torch(type("Grads", (), {"state_dict": lambda self: {
        k: v.grad for k, v in policy.named_parameters()}})())


def gradient_difference(captured: dict[str, Any], theirs_actor: Any, theirs_critic: Any
                        ) -> float:
    """The largest difference of our captured gradients from torch's, relative to each
    parameter's largest gradient (at least 1)."""
    worst = 0.0
    for name, theirs in (("actor", theirs_actor), ("critic", theirs_critic)):
        for ours_leaf, theirs_leaf in zip(jax.tree.leaves(captured[name]),
                                          jax.tree.leaves(theirs), strict=True):
            scale = max(1.0, float(np.max(np.abs(theirs_leaf))))
            worst = max(worst, float(np.max(np.abs(np.asarray(ours_leaf) - theirs_leaf)))
                        / scale)
    return worst


def test_the_gradients_are_those_of_sb3_contribs_loss(orbit: tuple[RecurrentPPO, Any]) -> None:
    algo, n_obs = orbit
    algo = algo.replace(ent_coef=0.01)              # the entropy term counts too
    policy = torch_policy(n_obs, seed=7)
    actor, critic = ours_from_torch(policy)
    rng = np.random.default_rng(4)
    obs, starts, actor0, critic0 = sequences(rng, 12, 3, n_obs)
    batch = {"obs": obs, "start": starts, "actor0": actor0, "critic0": critic0,
             "action": rng.normal(size=(12, 3, 1)) * 0.5,
             "log_prob": rng.normal(size=(12, 3)) * 0.2 - 1.0,
             "advantages": rng.normal(size=(12, 3)), "targets": rng.normal(size=(12, 3))}
    sb3_loss(policy, algo, batch).backward()
    # PPO.train's clip over all the policy's parameters at once (active here: the norm is
    # above max_grad_norm, so both networks' gradients shrink by one factor)
    norm = torch.nn.utils.clip_grad_norm_(policy.parameters(), algo.max_grad_norm)
    assert float(norm) > algo.max_grad_norm
    theirs_actor, theirs_critic = torch_gradients(policy)

    # whole sequences: every sample in the minibatch, each row begun at step 0 from the
    # carry stored there; the carries stored at later steps must not count (noise here)
    def stored(first: lstm.Carry) -> lstm.Carry:
        return tuple(jnp.asarray(rng.normal(size=(12, 3, H))).at[0].set(part)
                     for part in first)

    mb = SequenceMinibatch(
        RecurrentTrajectory(jnp.asarray(obs), jnp.asarray(batch["action"]),
                            jnp.asarray(batch["log_prob"]), None, None, None,
                            jnp.asarray(starts), stored(actor0), stored(critic0)),
        jnp.asarray(batch["advantages"]), jnp.asarray(batch["targets"]),
        jnp.ones((12, 3), dtype=bool), jnp.zeros((12, 3), dtype=bool).at[0].set(True))
    captured = update_gradients(algo, actor, critic, mb)
    worst = gradient_difference(captured, theirs_actor, theirs_critic)
    assert worst < 1e-12, worst


# ---------------------------------------------------------------------------- the minibatches
BUFFER_STEPS, BUFFER_ENVS = 8, 4          # T, E; batch_size = 2 T: k = 2, two minibatches
#: split indices: 0; one inside env 1 (t0 = 5); one whose first slice wraps from the last env
#: to env 0 (env 3 from t0 = 3, env 0 whole, env 1 before 3); one at an env's step 0 that
#: wraps (env 3 whole, env 0 whole: the third row empty)
SPLITS = (0, 13, 27, 24)


def filled_buffer(n_obs: int, rng: np.random.Generator
                  ) -> tuple[RecurrentRolloutBuffer, dict[str, np.ndarray]]:
    """A real ``RecurrentRolloutBuffer`` of ``T = 8`` steps of ``E = 4`` envs, filled through
    its ``add`` with float32-representable numbers: episode starts scattered (at the rollout's
    first step, inside envs, at the split indices' slice starts), a distinct stored LSTM state
    per step and env, random advantages and returns. Also returns the same rollout time first
    (``(T, E, ...)``), in float64."""
    steps, envs = BUFFER_STEPS, BUFFER_ENVS

    def f32(*shape: int, scale: float = 1.0, shift: float = 0.0) -> np.ndarray:
        return (rng.normal(size=shape) * scale + shift).astype(np.float32).astype(float)

    data = {"obs": f32(steps, envs, n_obs, scale=2.0), "action": f32(steps, envs, 1, scale=0.5),
            "log_prob": f32(steps, envs, scale=0.2, shift=-1.0), "value": f32(steps, envs),
            "advantages": f32(steps, envs), "targets": f32(steps, envs)}
    start = rng.random((steps, envs)) < 0.2
    start[0, 2] = start[4, 1] = start[6, 3] = start[5, 1] = True   # (env 1 at t0 of split 13)
    start[0, 0] = False                        # env 0's first stored state is not cleared
    data["start"] = start
    for name in ("actor_h", "actor_c", "critic_h", "critic_c"):
        data[name] = f32(steps, envs, H, scale=0.3)
    buffer = RecurrentRolloutBuffer(
        steps, gym.spaces.Box(-np.inf, np.inf, (n_obs,), np.float64),
        gym.spaces.Box(-1.0, 1.0, (1,), np.float32), (steps, 1, envs, H), device="cpu",
        n_envs=envs)
    for step in range(steps):
        def state(name: str, step: int = step) -> Any:
            return torch.tensor(data[name][step], dtype=torch.float32)[None]

        buffer.add(data["obs"][step], data["action"][step], np.zeros(envs),
                   data["start"][step].astype(np.float32), t(data["value"][step]),
                   t(data["log_prob"][step]),
                   lstm_states=RNNStates(pi=(state("actor_h"), state("actor_c")),
                                         vf=(state("critic_h"), state("critic_c"))))
    buffer.advantages[:] = data["advantages"]     # as compute_returns_and_advantage leaves
    buffer.returns[:] = data["targets"]
    return buffer, data


def our_rollout(data: dict[str, np.ndarray]) -> Rollout:
    """The buffer's rollout as ours holds it; the reward (unused by the update) tags each
    sample with its env-major flat index ``e T + t``, the buffer's index."""
    steps, envs = data["start"].shape
    tag = np.arange(envs)[None, :] * steps + np.arange(steps)[:, None]
    a = jnp.asarray
    trajectories = RecurrentTrajectory(
        a(data["obs"]), a(data["action"]), a(data["log_prob"]), a(tag.astype(float)),
        a(data["value"]), a(np.zeros((steps, envs), dtype=bool)), a(data["start"]),
        (a(data["actor_h"]), a(data["actor_c"])), (a(data["critic_h"]), a(data["critic_c"])))
    return Rollout(trajectories, a(data["advantages"]), a(data["targets"]))


def sb3_contrib_minibatches(buffer: RecurrentRolloutBuffer, split: int, batch_size: int,
                            monkeypatch: pytest.MonkeyPatch) -> list[tuple[Any, np.ndarray]]:
    """``buffer.get(batch_size)`` with its ``split_index`` made ``split``: each minibatch's
    samples and the flat indices ``_get_samples`` was given."""
    drawn: list[np.ndarray] = []
    get_samples = buffer._get_samples

    def recorded(batch_inds: np.ndarray, env_change: np.ndarray) -> Any:
        drawn.append(np.array(batch_inds))
        return get_samples(batch_inds, env_change)

    def randint(high: int) -> int:
        assert high == buffer.buffer_size * buffer.n_envs
        return split

    with monkeypatch.context() as patch:
        patch.setattr(buffer, "_get_samples", recorded)
        patch.setattr(np.random, "randint", randint)
        samples = list(buffer.get(batch_size))
    return list(zip(samples, drawn, strict=True))


def sb3_contrib_train_loss(policy: Any, algo: RecurrentPPO, data: Any) -> Any:
    """``RecurrentPPO.train``'s loss on one of the buffer's minibatches, its lines (the mask,
    the advantages normalised over it, the masked means), the buffer's float32 tensors cast to
    the double policy's float64."""
    def d(x: Any) -> Any:
        return x.double()

    mask = data.mask > 1e-8
    states = RNNStates(pi=tuple(d(x) for x in data.lstm_states.pi),
                       vf=tuple(d(x) for x in data.lstm_states.vf))
    values, log_prob, entropy = policy.evaluate_actions(
        d(data.observations), d(data.actions), states, d(data.episode_starts))
    values = values.flatten()
    advantages = d(data.advantages)
    advantages = (advantages - advantages[mask].mean()) / (advantages[mask].std() + 1e-8)
    ratio = torch.exp(log_prob - d(data.old_log_prob))
    policy_loss_1 = advantages * ratio
    policy_loss_2 = advantages * torch.clamp(ratio, 1 - algo.clip_eps, 1 + algo.clip_eps)
    policy_loss = -torch.mean(torch.min(policy_loss_1, policy_loss_2)[mask])
    value_loss = torch.mean(((d(data.returns) - values) ** 2)[mask])
    entropy_loss = -torch.mean(entropy[mask])
    return policy_loss + algo.ent_coef * entropy_loss + algo.vf_coef * value_loss


@pytest.fixture(scope="module")
def small() -> tuple[RecurrentPPO, int]:
    """The recurrent recipe on Orbit-v0 with ``T = 8`` steps of ``E = 4`` envs and two
    minibatches (``batch_size = 2 T``), float64 networks, the entropy term counted."""
    env, params = jt.make_env(ORBIT, "recurrent")
    algo, _ = recurrent_algorithm(env, params, num_envs=BUFFER_ENVS, num_steps=BUFFER_STEPS,
                                  num_minibatches=2, network_dtype="float64", ent_coef=0.01)
    return algo, env.observation_space(params).shape[0]


@pytest.mark.parametrize("split", SPLITS)
def test_minibatches_are_sb3_contribs_and_give_its_gradients(
        small: tuple[RecurrentPPO, int], split: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """sb3-contrib's own ``RecurrentRolloutBuffer``, its split index made ``split``: each of
    our minibatches of that split holds the buffer's minibatch's samples, the slices cover
    every sample once, and our update's gradients (after the joint clip) are those of
    ``RecurrentPPO.train``'s loss on the buffer's minibatch after ``clip_grad_norm_``
    (torch's autograd through sb3-contrib's padded sequences from the stored states)."""
    algo, n_obs = small
    batch_size = BUFFER_ENVS * BUFFER_STEPS // algo.num_minibatches
    buffer, data = filled_buffer(n_obs, np.random.default_rng(21))
    rollout = our_rollout(data)
    policy = torch_policy(n_obs, seed=13)
    actor, critic = ours_from_torch(policy)
    theirs = sb3_contrib_minibatches(buffer, split, batch_size, monkeypatch)
    firsts = np.asarray(algo.slice_starts(split))
    assert len(theirs) == len(firsts) == algo.num_minibatches
    covered = []
    for first, (samples, indices) in zip(firsts, theirs, strict=True):
        mb = algo.minibatch(rollout, first)
        ours = np.asarray(mb.trajectories.reward)[np.asarray(mb.mask)]
        assert sorted(ours) == sorted(indices)                    # the same samples
        covered += list(ours)

        policy.zero_grad()
        sb3_contrib_train_loss(policy, algo, samples).backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), algo.max_grad_norm)
        worst = gradient_difference(update_gradients(algo, actor, critic, mb),
                                    *torch_gradients(policy))
        assert worst < 1e-12, (split, first, worst)
    assert sorted(covered) == list(range(BUFFER_ENVS * BUFFER_STEPS))   # each sample once


def test_the_split_index_is_uniform_over_the_samples(small: tuple[RecurrentPPO, int]
                                                     ) -> None:
    """One split per epoch, uniform over the ``E T = 32`` samples as ``np.random.randint``:
    4000 draws, each value's count within 5 standard deviations of 125, every value drawn."""
    algo, _ = small
    draws = np.asarray(jax.vmap(algo.split_index)(jax.random.split(jax.random.PRNGKey(0),
                                                                   4000)))
    counts = np.bincount(draws, minlength=33)
    assert counts[32] == 0 and counts[:32].min() > 0
    expected = 4000 / 32
    assert np.max(np.abs(counts[:32] - expected)) < 5 * np.sqrt(expected * (1 - 1 / 32))


# ---------------------------------------------------------------------------- the rollout
def test_the_rollout_is_what_the_torch_policy_computes_step_by_step() -> None:
    """Ticker: three-step episodes cut by the time limit, two envs, seven steps. No
    normalisation, so the stored reward is the plant's plus the bootstrap, computable here;
    the stored carries are the torch policy's LSTM states before each step, as
    ``collect_rollouts`` gives ``RecurrentRolloutBuffer.add`` its ``_last_lstm_states``."""
    env, params = Ticker(), TickerParams()
    algo, _ = recurrent_algorithm(env, params, num_envs=2, num_steps=7, num_minibatches=1,
                                  normalize_observations=False, normalize_rewards=False,
                                  network_dtype="float64")
    ts = algo.init_state(jax.random.PRNGKey(3))
    policy = torch_policy(2, seed=9)
    actor, critic = ours_from_torch(policy)
    ts = ts.replace(actor_ts=ts.actor_ts.replace(params=actor),
                    critic_ts=ts.critic_ts.replace(params=critic))
    _, traj = jax.jit(algo.collect_trajectories)(ts)
    began = jax.tree.map(lambda x: x[0], (traj.actor_carry, traj.critic_carry))
    assert not any(np.any(np.asarray(x)) for x in jax.tree.leaves(began))   # zeros
    done = np.asarray(traj.done)
    start = np.asarray(traj.start)
    assert not start[0].any() and np.array_equal(start[1:], done[:-1])
    assert np.array_equal(np.flatnonzero(done[:, 0]), [2, 5])

    states = torch_states(began[0], began[1])
    x = 0.5
    for step in range(7):
        obs = np.asarray(traj.obs[step])
        assert np.allclose(obs[:, 0], x)
        # the stored carries: the torch policy's LSTM states before this step (not cleared)
        for ours, theirs in ((traj.actor_carry, states.pi), (traj.critic_carry, states.vf)):
            for part in (0, 1):
                assert np.max(np.abs(np.asarray(ours[part][step])
                                     - theirs[part][0].numpy())) < 1e-12
        with torch.no_grad():
            _, log_prob, _ = policy.evaluate_actions(t(obs), t(traj.action[step]), states,
                                                     t(start[step]))
            _, values, _, states = policy(t(obs), states, t(start[step]))
            bootstrap = np.zeros(2)
            if done[step, 0]:           # sb3-contrib: V(terminal obs), the critic's LSTM on
                final = np.stack([x + 1.0, (x + 1.0) ** 2 / 4.0])   # from after the step
                v = policy.predict_values(t(np.tile(final, (2, 1))), states.vf,
                                          torch.zeros(2, dtype=torch.float64))
                bootstrap = algo.gamma * v.numpy()[:, 0]
        assert np.max(np.abs(np.asarray(traj.value[step]) - values.numpy()[:, 0])) < 1e-12
        assert np.max(np.abs(np.asarray(traj.log_prob[step]) - log_prob.numpy())) < 1e-12
        expected = -(x + 1.0) + bootstrap
        assert np.max(np.abs(np.asarray(traj.reward[step]) - expected)) < 1e-12
        x = 0.5 if done[step, 0] else x + 1.0


# ---------------------------------------------------------------------------- learning
CUE_STEPS = 6


@struct.dataclass
class CueState(environment.EnvState):
    cue: jax.Array


@struct.dataclass
class CueParams(environment.EnvParams):
    max_steps_in_episode: int = CUE_STEPS


class Cue(environment.Environment):
    """A task only memory solves: a cue ``c = ±1`` is shown at an episode's first step and
    never again (the observation is 0 after it); every step pays ``-(a - c)²``.

    A recurrent policy can return 0. A feed-forward one sees the same 0 at steps 1..5 whatever
    the cue, so its action there is one number ``a`` for both cues and each such step pays at
    best ``-(1 - m²)`` on episodes whose cues average ``m`` (at ``a = m``): over the episodes
    below, ``-5 (1 - m²)`` at best (:func:`feed_forward_ceiling`).
    """

    @property
    def default_params(self) -> CueParams:
        return CueParams()

    def reset_env(self, key: jax.Array, params: CueParams) -> Any:
        cue = jnp.where(jax.random.bernoulli(key), 1.0, -1.0)
        return jnp.stack([cue]), CueState(time=0, cue=cue)

    def step_env(self, key: jax.Array, state: CueState, action: Any, params: CueParams
                 ) -> Any:
        reward = -jnp.square(jnp.squeeze(action) - state.cue)
        new = CueState(time=state.time + 1, cue=state.cue)
        return jnp.zeros(1), new, reward, jnp.asarray(False), {}

    def observation_space(self, params: CueParams) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (1,), jnp.float64)

    def action_space(self, params: Any = None) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (1,), jnp.float32)


def feed_forward_ceiling(keys: Any) -> float:
    """The best mean return of any feed-forward deterministic policy on these episodes."""
    # evaluate_policy resets episode i with the first half of its key's split
    cues = np.array([float(Cue().reset(jax.random.split(k)[0], CueParams())[1].cue)
                     for k in keys])
    return -(CUE_STEPS - 1) * (1.0 - cues.mean() ** 2)


def test_recurrent_ppo_learns_what_only_memory_solves() -> None:
    algo, rec = recurrent_algorithm(Cue(), CueParams(), num_envs=16, num_steps=36,
                                    num_minibatches=4, num_epochs=5, steps=36 * 16 * 30)
    keys = jax.random.split(jax.random.PRNGKey(10_000), 40)
    program = jax.jit(jt.training_program(algo, rec, checkpoints=1,
                                          curve_episodes=1, episodes=40, eval_seed=10_000))
    _, _, returns = program(algo.init_state(jax.random.PRNGKey(0)))
    ceiling = feed_forward_ceiling(keys)
    assert ceiling < -4.0
    assert float(np.mean(returns)) > -0.5, (float(np.mean(returns)), ceiling)
