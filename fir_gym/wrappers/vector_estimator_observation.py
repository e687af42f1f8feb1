"""One batched estimator across all sub-environments of a Gymnasium vector env."""

from __future__ import annotations

import copy
from typing import Any, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from fir_gym.estimators import Estimator
from fir_gym.estimators._validation import one_of

from .estimator_observation import (
    OBSERVATION_KINDS,
    build_estimator,
    check_fits,
    estimator_class_of,
    estimator_label,
    plant_dimensions,
    plant_name,
    state_size,
)


class VectorEstimatorObservation(gym.vector.VectorWrapper):
    """Replace a vector env's measurements by the estimates of one batched estimator.

    Args:
        env: a vector env of a fir-gym plant — ``gym.make_vec(id, n, vectorization_mode=
            "sync" | "async" | "vector_entry_point")`` — in next-step (Gymnasium's
            default) or same-step autoreset mode.
        estimator: an :class:`~fir_gym.estimators.Estimator` class or registry name
            (built once, for the batch, from the plant's model with ``**options``).
        observation: ``"estimate"``, ``"estimate+covariance"`` or ``"estimate+measurement"``,
            as for :class:`~fir_gym.wrappers.EstimatorObservation`.

    System ``i`` of the estimator follows sub-env ``i``. On ``reset`` every system
    starts from the plant's initial-state distribution and consumes ``y[0]``; on
    ``step`` they consume ``y[k]`` with the applied actions (``info["action"]``).
    When a sub-env ends an episode, the next step autoresets it (returning ``y[0]``
    of a new episode): its system is then restarted (:meth:`Estimator.restart`) and
    that measurement is its first, exactly as a fresh one-env
    :class:`EstimatorObservation` would do. Where ``info["measurement_missing"]`` is True
    (:class:`~fir_gym.wrappers.VectorSensorFaults`) that system's measurement is masked: it
    predicts only. In same-step mode the sub-env returns the
    new episode's first measurement in the step that ended the old one, with the last
    one in ``info["final_obs"]``: a copy of the estimator consumes the last
    measurements (their estimates become ``info["final_obs"]``, and
    ``info["final_info"]`` is annotated with them), then the ended systems restart
    and consume the first ones. ``info`` gains ``estimate``,
    ``estimation_error`` (where ``state`` is known) and ``estimator_diverged``, each
    with Gymnasium's ``_key`` mask.

    ``render()`` returns the vector env's frames (one per sub-env, with
    ``render_mode="rgb_array"``) with each system's estimate, 2σ region and
    measurement drawn over its sub-env's frame, as
    :class:`~fir_gym.wrappers.EstimatorObservation` draws them. That needs the plant
    behind each frame: a native or a sync vector env; the frames of an async one are
    returned as they are.
    """

    def __init__(self, env: VectorEnv, estimator: type[Estimator] | str,
                 observation: str = "estimate", **options: Any) -> None:
        super().__init__(env)
        self._same_step = same_step_mode(env, type(self).__name__)
        one_of("observation", observation, OBSERVATION_KINDS)
        if isinstance(estimator, Estimator):
            raise TypeError("give VectorEstimatorObservation an estimator class or name (it "
                            "builds one batched estimator); got an instance")
        cls = estimator_class_of(estimator)
        self.estimator = build_estimator(cls, lambda name: _plant_attr(env, name), options)
        check_fits(self.estimator, plant_dimensions(lambda name: _plant_attr(env, name),
                                                    env.single_observation_space,
                                                    env.single_action_space),
                   plant_name(env))
        self._n_state = state_size(self.estimator.model)
        self.observation_kind = observation
        n = self.num_envs
        n_x = self.estimator.model.n_x
        estimate = spaces.Box(-np.inf, np.inf, shape=(n_x,), dtype=np.float64)
        if observation == "estimate":
            single: spaces.Space = estimate
        elif observation == "estimate+covariance":
            if not cls.provides_covariance:
                raise ValueError(f"{cls.__name__} has no covariance; use observation='estimate' "
                                 "or 'estimate+measurement'")
            self._triu = np.triu_indices(n_x)
            single = spaces.Dict({"estimate": estimate, "covariance": spaces.Box(
                -np.inf, np.inf, shape=(len(self._triu[0]),), dtype=np.float64)})
        else:
            single = spaces.Dict({"estimate": estimate,
                                  "measurement": env.single_observation_space})
        self.single_observation_space = single
        self.observation_space = batch_space(single, n)
        self._prev_done = np.zeros(n, dtype=bool)
        self.estimator_label = estimator_label(self.estimator)
        self._last: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None

    def reset(self, *, seed: int | list[int] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        env: Any = self.env                    # its reset takes a list of seeds too
        y, info = env.reset(seed=seed, options=options)
        self.estimator.reset(*self.estimator.prior)
        Y = self._measurements(y)
        x_hat = self.estimator.step(_masked(Y, info.get("measurement_missing")))
        self._prev_done[:] = False
        self._last = (x_hat.copy(), Y)
        return self._observe(x_hat, y), self._annotate(info, x_hat)

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        y, reward, terminated, truncated, info = self.env.step(actions)
        if self._prev_done.any():                      # those sub-envs were reset this step
            self.estimator.restart(self._prev_done)
        applied = info.get("action", actions)
        u = np.asarray(applied, dtype=np.float64).reshape(self.num_envs, -1)
        Y = self._measurements(y)
        ended = info.get("_final_obs") if self._same_step else None
        if ended is not None and ended.any():
            info = self._finish_episodes(info, ended, Y, u)
        x_hat = self.estimator.step(_masked(Y, info.get("measurement_missing")), u)
        if not self._same_step:
            self._prev_done = np.logical_or(terminated, truncated)
        self._last = (x_hat.copy(), Y)
        return self._observe(x_hat, y), reward, terminated, truncated, \
            self._annotate(info, x_hat)

    def _finish_episodes(self, info: dict[str, Any], ended: np.ndarray, Y: NDArray[np.float64],
                         u: NDArray[np.float64]) -> dict[str, Any]:
        """Same-step mode: the ended episodes' last estimates, then restart their systems."""
        last = Y.copy()
        final = info["final_obs"]          # an array, or (sync/async) an object array
        for i in np.flatnonzero(ended):
            last[i] = np.asarray(final[i], dtype=np.float64).reshape(-1)
        finisher = copy.deepcopy(self.estimator)      # the others' step is not taken twice
        final_info = info.get("final_info")
        missing = final_info.get("measurement_missing") if isinstance(final_info, dict) \
            else None
        x_last = finisher.step(_masked(last, missing), u)
        info = dict(info)
        info["final_obs"] = self._observe(x_last, last, finisher)
        if isinstance(final_info, dict):
            info["final_info"] = self._annotate(final_info, x_last, finisher)
        self.estimator.restart(ended)
        return info

    def render(self) -> Any:
        """The sub-envs' frames with each system's estimate drawn over its frame."""
        frames: Any = self.env.render()
        plants = _frame_plants(self.env, len(frames)) if isinstance(frames, (tuple, list)) \
            else None
        if plants is None or self._last is None:
            return frames
        x_hat, y = self._last
        P = self.estimator.P
        diverged = np.broadcast_to(np.asarray(self.estimator.diverged), (self.num_envs,))
        return tuple(
            plant.draw_estimate(frame, x_hat[i], None if P is None else P[i], y[i],
                                label=self.estimator_label, diverged=bool(diverged[i]),
                                view=view)
            for i, (frame, (plant, view)) in enumerate(zip(frames, plants, strict=True)))

    def _measurements(self, y: Any) -> NDArray[np.float64]:
        """The sub-envs' measurements as one fresh ``(num_envs, n_y)`` float64 array: the
        estimator's input, kept for :meth:`render` (one conversion per step, not two)."""
        return np.array(y, dtype=np.float64).reshape(self.num_envs, -1)

    def _observe(self, x_hat: NDArray[np.float64], y: Any,
                 estimator: Estimator | None = None) -> Any:
        if self.observation_kind == "estimate":
            return x_hat
        if self.observation_kind == "estimate+covariance":
            P = cast(NDArray[np.float64], (estimator or self.estimator).P)   # checked: it has one
            return {"estimate": x_hat, "covariance": P[:, self._triu[0], self._triu[1]]}
        return {"estimate": x_hat, "measurement": np.asarray(y, dtype=np.float64)}

    def _annotate(self, info: dict[str, Any], x_hat: NDArray[np.float64],
                  estimator: Estimator | None = None) -> dict[str, Any]:
        info = dict(info)
        everyone = np.ones(self.num_envs, dtype=bool)
        info["estimate"], info["_estimate"] = x_hat.copy(), everyone
        if "state" in info:
            mask = info.get("_state", everyone)
            error = np.asarray(info["state"]) - x_hat[:, :self._n_state]
            # Gymnasium's convention: entries outside the mask are zeros (never NaN)
            info["estimation_error"] = error if mask.all() else np.where(mask[:, None], error,
                                                                         0.0)
            info["_estimation_error"] = mask
        diverged = (estimator or self.estimator).diverged  # a fresh array (or a bool)
        info["estimator_diverged"] = diverged if isinstance(diverged, np.ndarray) else \
            np.full(self.num_envs, bool(diverged))
        info["_estimator_diverged"] = everyone
        return info


def _masked(Y: NDArray[np.float64], missing: Any) -> Any:
    """``Y`` with the rows of the systems whose reading is missing masked (the estimator
    predicts only there), or ``Y`` itself when none is."""
    if missing is None or not np.any(missing):
        return Y
    rows = np.asarray(missing, dtype=bool)
    return np.ma.masked_array(Y, mask=np.broadcast_to(rows[:, None], Y.shape))


def same_step_mode(env: VectorEnv, wrapper: str) -> bool:
    """Whether ``env`` autoresets in the same step (else in the next); other modes are a
    ValueError naming ``wrapper``."""
    mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
    if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
        raise ValueError(f"{wrapper} follows next-step or same-step autoreset; this vector "
                         f"env uses {mode}")
    return bool(mode == AutoresetMode.SAME_STEP)


def _plant_attr(env: VectorEnv, name: str) -> Any:
    """An attribute of the plant behind a native, sync or async vector env."""
    base = env.unwrapped
    plant = getattr(base, "plant", None)                 # fir-gym's native vector env
    if plant is not None:
        return getattr(plant, name, None)
    get_attr = getattr(base, "get_attr", None)          # sync / async: from sub-env 0
    try:
        return None if get_attr is None else get_attr(name)[0]
    except AttributeError:
        return None


def _frame_plants(env: VectorEnv, n: int) -> list[tuple[Any, Any]] | None:
    """``(plant, view)`` behind each of the ``n`` frames the vector env just rendered:
    the native env's plant with each frame's view, or a sync env's sub-env plants; None
    where they cannot be reached (an async env) or cannot draw an estimate."""
    base = env.unwrapped
    views, plant = getattr(base, "frame_views", None), getattr(base, "plant", None)
    if views is not None and plant is not None:                           # native
        pairs = [(plant, view) for view in views]
    elif hasattr(base, "envs"):                                           # sync
        plants = [sub.unwrapped for sub in base.envs]
        pairs = [(plant, getattr(plant, "frame_view", None)) for plant in plants]
    else:
        return None
    if len(pairs) != n or any(view is None or not hasattr(plant, "draw_estimate")
                              for plant, view in pairs):
        return None
    return pairs
