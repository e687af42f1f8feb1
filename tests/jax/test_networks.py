"""fir_gym.jax.ppo's networks and update against stable-baselines3's ``ActorCriticPolicy``.

Oracles that cannot share their bugs: SB3's policy built with the shipped recipe's policy
keywords (``ppo.yml``), its parameters copied into ours —

* in float64 (``network_dtype="float64"`` against the policy made double): the same values,
  log-probabilities, entropies and deterministic actions to 1e-12, and the same gradients of
  SB3's PPO loss on one minibatch (``PPO.train``'s lines, torch's autograd);
* in float32, the shipped arithmetic, against the policy as SB3 builds it: the same numbers to
  float32's round-off, every network leaf and Adam's moments float32, the values float64.
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
pytest.importorskip("stable_baselines3")

import gymnasium as gym
import jax
import jax.numpy as jnp
import torch
from jax_runs import ORBIT
from rejax.algos.ppo import AdvantageMinibatch, Trajectory
from sb3_in_double import in_double
from stable_baselines3.common.policies import ActorCriticPolicy
from update_gradients import update_gradients

from fir_gym.jax import train as jt
from fir_gym.training.run import RunConfig

N_OBS, BATCH = 2, 48


def algorithm(network_dtype: str) -> jt.SB3LikePPO:
    env, params = jt.make_env(ORBIT, "ekf")
    rec = dataclasses.replace(jt.recipe(ORBIT, kind="ekf"), network_dtype=network_dtype)
    return jt.make_algorithm(env, params, rec)


def sb3_policy(double: bool, seed: int = 0) -> Any:
    """SB3's ``MlpPolicy`` as the SB3 backend builds it for Orbit-v0 (ppo.yml's
    ``policy_kwargs``), float32 as built or made double."""
    torch.manual_seed(seed)
    kwargs = RunConfig(ORBIT, "ekf", algo="ppo").settings()["algo_kwargs"]["policy_kwargs"]
    policy = ActorCriticPolicy(gym.spaces.Box(-np.inf, np.inf, (N_OBS,), np.float32),
                               gym.spaces.Box(-1.0, 1.0, (1,), np.float32), lambda _: 1e-3,
                               **kwargs)
    with torch.no_grad():                 # a log_std away from its initial value counts too
        policy.log_std.add_(0.3)
    return in_double(policy) if double else policy


def ours_from_sb3(named: dict[str, Any], dtype: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """SB3's parameters (or their gradients), by name, in our layout: ``(actor, critic)``."""
    p = {k: jnp.asarray(v.detach().numpy(), dtype) for k, v in named.items()}

    def dense(name: str) -> dict[str, Any]:
        return {"kernel": p[f"{name}.weight"].T, "bias": p[f"{name}.bias"]}

    actor = {"params": {"features": {"Dense_0": dense("mlp_extractor.policy_net.0"),
                                     "Dense_1": dense("mlp_extractor.policy_net.2")},
                        "action_mean": dense("action_net"), "action_log_std": p["log_std"]}}
    critic = {"params": {"Features_0": {"Dense_0": dense("mlp_extractor.value_net.0"),
                                        "Dense_1": dense("mlp_extractor.value_net.2")},
                         "Dense_0": dense("value_net")}}
    return actor, critic


def inputs(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    obs = (rng.normal(size=(BATCH, N_OBS)) * 2.0).astype(np.float32).astype(float)
    actions = (rng.normal(size=(BATCH, 1)) * 0.5).astype(np.float32).astype(float)
    return obs, actions


@pytest.mark.parametrize(("network_dtype", "tol"), [("float64", 1e-12), ("float32", 2e-6)])
def test_the_networks_are_sb3s_policy(network_dtype: str, tol: float) -> None:
    double = network_dtype == "float64"
    dtype = jnp.float64 if double else jnp.float32
    tdtype = torch.float64 if double else torch.float32
    algo = algorithm(network_dtype)
    policy = sb3_policy(double)
    actor, critic = ours_from_sb3(dict(policy.named_parameters()), dtype)
    obs, actions = inputs(1)
    with torch.no_grad():
        values, log_prob, entropy = policy.evaluate_actions(
            torch.tensor(obs, dtype=tdtype), torch.tensor(actions, dtype=tdtype))
        mean = policy._predict(torch.tensor(obs, dtype=tdtype), deterministic=True)
    ours_lp, ours_ent = algo.actor.apply(actor, jnp.asarray(obs),
                                         jnp.asarray(actions, dtype),
                                         method="log_prob_entropy")
    ours_v = algo.critic.apply(critic, jnp.asarray(obs))
    ours_mean = algo.actor.apply(actor, jnp.asarray(obs), method="mean_action")
    assert ours_v.dtype == jnp.float64
    assert ours_lp.dtype == dtype and ours_mean.dtype == dtype
    for ours, theirs in ((ours_lp, log_prob), (ours_v, values[:, 0]), (ours_ent, entropy),
                         (ours_mean, np.clip(mean.numpy(), -1.0, 1.0))):
        theirs = np.asarray(theirs, dtype=float).reshape(-1)
        ours = np.broadcast_to(np.asarray(ours, dtype=float).reshape(-1), theirs.shape)
        assert np.max(np.abs(ours - theirs)) < tol * max(1.0, float(np.max(np.abs(theirs))))


def test_float32_is_the_default_and_every_network_leaf_is_float32() -> None:
    algo = algorithm(jt.recipe(ORBIT).network_dtype)
    assert jt.recipe(ORBIT).network_dtype == "float32"
    ts = algo.init_state(jax.random.PRNGKey(0))
    leaves = jax.tree.leaves((ts.actor_ts.params, ts.actor_ts.opt_state,
                              ts.critic_ts.params, ts.critic_ts.opt_state))
    assert {np.asarray(x).dtype for x in leaves
            if np.issubdtype(np.asarray(x).dtype, np.floating)} == {np.dtype(np.float32)}
    assert np.asarray(ts.obs_rms_state.mean).dtype == np.float64       # the statistics: float64
    with pytest.raises(ValueError, match="network_dtype must be one of"):
        jt.recipe(ORBIT, network_dtype="bfloat16")


def test_the_gradients_are_those_of_sb3s_ppo_loss() -> None:
    """``PPO.train``'s loss on one minibatch (advantages normalised with ``th.std``, the clipped
    surrogate, ``ent_coef`` times the entropy, ``vf_coef`` times the values' mean squared
    error), differentiated by torch and clipped by ``clip_grad_norm_`` over all the policy's
    parameters, against the gradients our update hands to Adam."""
    algo = algorithm("float64").replace(ent_coef=0.01)
    policy = sb3_policy(True, seed=3)
    actor, critic = ours_from_sb3(dict(policy.named_parameters()), jnp.float64)
    obs, actions = inputs(2)
    rng = np.random.default_rng(5)
    old_log_prob = rng.normal(size=BATCH) * 0.2 - 1.0
    advantages, targets = rng.normal(size=BATCH), rng.normal(size=BATCH)

    def d(x: Any) -> Any:
        return torch.tensor(np.asarray(x), dtype=torch.float64)

    values, log_prob, entropy = policy.evaluate_actions(d(obs), d(actions))
    adv = (d(advantages) - d(advantages).mean()) / (d(advantages).std() + 1e-8)
    ratio = torch.exp(log_prob - d(old_log_prob))
    surrogate = -torch.min(adv * ratio, adv * torch.clamp(ratio, 1 - algo.clip_eps,
                                                          1 + algo.clip_eps)).mean()
    loss = (surrogate - algo.ent_coef * entropy.mean()
            + algo.vf_coef * torch.mean((d(targets) - values.flatten()) ** 2))
    loss.backward()
    # PPO.train's clip over all the policy's parameters at once (active here: the norm is
    # above max_grad_norm, so both networks' gradients shrink by one factor)
    norm = torch.nn.utils.clip_grad_norm_(policy.parameters(), algo.max_grad_norm)
    assert float(norm) > algo.max_grad_norm
    theirs = ours_from_sb3({k: v.grad for k, v in policy.named_parameters()}, jnp.float64)

    batch = AdvantageMinibatch(
        Trajectory(jnp.asarray(obs), jnp.asarray(actions), jnp.asarray(old_log_prob), None,
                   None, None), jnp.asarray(advantages), jnp.asarray(targets))
    captured = update_gradients(algo, actor, critic, batch)
    worst = 0.0
    for name, want in zip(("actor", "critic"), theirs, strict=True):
        for got, leaf in zip(jax.tree.leaves(captured[name]), jax.tree.leaves(want),
                             strict=True):
            scale = max(1.0, float(np.max(np.abs(leaf))))
            worst = max(worst, float(np.max(np.abs(np.asarray(got) - leaf))) / scale)
    assert worst < 1e-12, worst
