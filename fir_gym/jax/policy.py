"""A JAX-trained controller as a numpy policy: what plays it in the numpy envs.

:class:`JaxPolicy` holds one seed's actor of a :class:`fir_gym.jax.train.JaxTraining` (just
trained, or read from its run folder by :func:`fir_gym.jax.train.load`) and its observation
statistics, and acts as stable-baselines3's ``model.predict(obs, deterministic=True)`` behind
``VecNormalize`` does: the observation normalised with the run's final statistics (and
clipped), the Gaussian's mean clipped to the action box
(:meth:`fir_gym.jax.train.Policy.mean_action`), one jitted call per batch of observations.
A batch's actions are the batched products' (XLA's, which differ from a batch of one's in
float32's last bits), or with ``rowwise=True`` each row's computed as a batch of one in a
compiled loop over the rows: bit for bit the actions of one observation at a time.
It is the policy of ``fir-gym evaluate`` on a JAX run folder and of the JAX benchmarks
(:func:`fir_gym.jax.benchmark.play_in_numpy_env`, the robustness benchmark's learned grid).
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np


class JaxPolicy:
    """Seed number ``index`` (a position in ``result.seeds``) of ``result``'s policies.

    ``policy(obs, episode_start, state)`` is the robustness benchmark's policy signature
    (:data:`fir_gym.robustness.closed_loop.Policy`), for one observation or a batch
    (``(n, n_obs)``): float32 actions of the same leading shape, and the state to pass with
    the next observations — ``None`` for a feed-forward policy, the LSTMs' carry for the
    ``recurrent`` kind (:mod:`fir_gym.jax.recurrent_ppo`; ``state=None`` starts from zeros,
    and ``episode_start`` clears the carry of the envs starting an episode, as sb3-contrib's
    ``predict`` does). :meth:`actions` is the feed-forward shortcut; :meth:`episode` a
    one-argument policy for one episode (``fir-gym watch``). :meth:`every_seed` gives one per
    seed sharing one network and one compiled act (``acting``: what an earlier policy of the
    same result built). ``rowwise``: a batch's rows acted on one at a time (module
    docstring): the same actions, bit for bit, whatever batch an observation comes in (a
    given ``acting`` keeps the mode it was built with).
    """

    def __init__(self, result: Any, index: int, acting: Any = None,
                 rowwise: bool = False) -> None:
        ts = result.train_state
        if ts is None:
            raise ValueError(f"{result.env_id} {result.kind}: the result has no train state (a "
                             "run folder's policies are read by fir_gym.jax.train.load)")
        if not 0 <= index < len(result.seeds):
            raise ValueError(f"index must be in [0, {len(result.seeds)}) for the run's seeds "
                             f"{result.seeds}; got {index!r}")
        self.seed = result.seeds[index]
        self.kind = result.kind
        self.actor = jax.tree.map(lambda x: x[index], ts.actor_ts.params)
        self.rms = jax.tree.map(lambda x: x[index], ts.obs_rms_state)
        self._act, self._carry = _acting(result, rowwise) if acting is None else acting
        #: whether the policy carries a state from step to step (the ``recurrent`` kind)
        self.recurrent = self._carry(1) is not None

    @classmethod
    def every_seed(cls, result: Any, rowwise: bool = False) -> list[JaxPolicy]:
        """One policy per seed of ``result``, in its order, the network built and the act
        compiled once; ``rowwise`` as the class's."""
        acting = _acting(result, rowwise)
        return [cls(result, i, acting) for i in range(len(result.seeds))]

    def __call__(self, obs: Any, episode_start: Any = None, state: Any = None
                 ) -> tuple[np.ndarray, Any]:
        x = np.asarray(obs, dtype=np.float64)
        batch = x if x.ndim > 1 else x[None]
        n = len(batch)
        start = (np.full(n, state is None) if episode_start is None
                 else np.asarray(episode_start, dtype=bool).reshape(n))
        if state is None:
            state = self._carry(n)
        state, out = self._act(self.actor, self.rms, state, batch, start)
        actions = np.asarray(out, dtype=np.float32)
        return (actions if x.ndim > 1 else actions[0]), state

    def actions(self, obs: Any) -> np.ndarray:
        """The deterministic actions for ``obs`` (one observation, or a batch) of a
        feed-forward policy; a recurrent one needs its state (``policy(obs, start, state)``)."""
        if self.recurrent:
            raise ValueError(f"the {self.kind} policy carries its LSTM state from step to step: "
                             "call policy(obs, episode_start, state), or policy.episode()")
        return self(obs)[0]

    def episode(self) -> Any:
        """A one-argument policy for one episode: ``act(obs) -> action``, the state carried
        from call to call (the first call starts the episode)."""
        memory: dict[str, Any] = {"state": None, "start": True}

        def act(obs: Any) -> np.ndarray:
            n = len(np.asarray(obs)) if np.ndim(obs) > 1 else 1
            start = np.full(n, memory["start"])
            action, memory["state"] = self(obs, start, memory["state"])
            memory["start"] = False
            return action

        return act


def _acting(result: Any, rowwise: bool = False) -> tuple[Any, Any]:
    """``(act, carry)`` of ``result``'s network (its env and algorithm rebuilt from the run's
    keywords): the jitted ``(actor params, obs statistics, state, observations, starts) ->
    (state, actions)`` (:meth:`fir_gym.jax.train.SB3LikePPO.policy_action`) — over the
    batch, or with ``rowwise`` over each row as a batch of one (``lax.map``) — and the state
    a batch of ``n`` episodes starts from (``None`` for a feed-forward policy)."""
    from .train import make_algorithm, make_env

    env, params = make_env(result.env_id, result.kind, dict(result.env_kwargs),
                           result.kind_kwargs)
    algo = make_algorithm(env, params, result.recipe)

    def act(actor: Any, rms: Any, state: Any, obs: Any, start: Any) -> Any:
        seen = algo.normalize_obs(rms, obs) if algo.normalize_observations else obs
        return algo.policy_action(actor, state, seen, start)

    def one_row_at_a_time(actor: Any, rms: Any, state: Any, obs: Any, start: Any) -> Any:
        def row(inputs: Any) -> Any:
            carry, x, first = jax.tree.map(lambda leaf: leaf[None], inputs)
            carry, action = act(actor, rms, carry, x, first)
            return jax.tree.map(lambda leaf: leaf[0], (carry, action))

        return jax.lax.map(row, (state, obs, start))

    return jax.jit(one_row_at_a_time if rowwise else act), algo.policy_carry
