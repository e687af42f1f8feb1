"""A JAX-trained controller as a numpy policy: what plays it in the numpy envs.

:class:`JaxPolicy` holds one seed's actor of a :class:`fir_gym.jax.train.JaxTraining` (just
trained, or read from its run folder by :func:`fir_gym.jax.train.load`) and its observation
statistics, and acts as stable-baselines3's ``model.predict(obs, deterministic=True)`` behind
``VecNormalize`` does: the observation normalised with the run's final statistics (and
clipped), the Gaussian's mean clipped to the action box
(:meth:`fir_gym.jax.train.Policy.mean_action`), one jitted call per batch of observations.
It is the policy of ``fir-gym evaluate`` on a JAX run folder and of the JAX benchmarks
(:func:`fir_gym.jax.benchmark.play_in_numpy_env`, the robustness benchmark's learned grid).
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np


class JaxPolicy:
    """Seed number ``index`` (a position in ``result.seeds``) of ``result``'s policies.

    ``policy(obs)`` acts on one observation or a batch (``(n, n_obs)``), returning float32
    actions of the same leading shape; ``policy(obs, episode_start, state)`` is the
    robustness benchmark's policy signature (:data:`fir_gym.robustness.closed_loop.Policy`:
    a feed-forward policy carries no state). :meth:`every_seed` gives one per seed sharing
    one network and one compiled act (``acting``: what an earlier policy of the same result
    built).
    """

    def __init__(self, result: Any, index: int, acting: Any = None) -> None:
        ts = result.train_state
        if ts is None:
            raise ValueError(f"{result.env_id} {result.kind}: the result has no train state (a "
                             "run folder's policies are read by fir_gym.jax.train.load)")
        if not 0 <= index < len(result.seeds):
            raise ValueError(f"index must be in [0, {len(result.seeds)}) for the run's seeds "
                             f"{result.seeds}; got {index!r}")
        self.seed = result.seeds[index]
        self.actor = jax.tree.map(lambda x: x[index], ts.actor_ts.params)
        self.rms = jax.tree.map(lambda x: x[index], ts.obs_rms_state)
        self._act = _acting(result) if acting is None else acting

    @classmethod
    def every_seed(cls, result: Any) -> list[JaxPolicy]:
        """One policy per seed of ``result``, in its order, the network built and the act
        compiled once."""
        acting = _acting(result)
        return [cls(result, i, acting) for i in range(len(result.seeds))]

    def actions(self, obs: Any) -> np.ndarray:
        """The deterministic actions for ``obs`` (one observation, or a batch)."""
        x = np.asarray(obs, dtype=np.float64)
        batch = x if x.ndim > 1 else x[None]
        out = np.asarray(self._act(self.actor, self.rms, batch), dtype=np.float32)
        return out if x.ndim > 1 else out[0]

    def __call__(self, obs: Any, episode_start: Any = None, state: Any = None
                 ) -> tuple[np.ndarray, Any]:
        return self.actions(obs), None


def _acting(result: Any) -> Any:
    """The jitted ``(actor params, obs statistics, observations) -> actions`` of
    ``result``'s network (its env and algorithm rebuilt from the run's keywords)."""
    from .train import make_algorithm, make_env

    env, params = make_env(result.env_id, result.kind, dict(result.env_kwargs),
                           result.kind_kwargs)
    algo = make_algorithm(env, params, result.recipe)

    def act(actor: Any, rms: Any, obs: Any) -> Any:
        seen = algo.normalize_obs(rms, obs) if algo.normalize_observations else obs
        return algo.actor.apply(actor, seen, method="mean_action")

    return jax.jit(act)
