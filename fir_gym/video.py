"""Recording an episode with an estimator in the loop as a video: ``fir-gym watch``.

:func:`watch` runs one episode of a plant with ``render_mode="rgb_array"``, the
estimator's marker, 2σ region and the measurement drawn over every frame
(:meth:`fir_gym.wrappers.EstimatorObservation.render`), driven by a policy:

* ``"zero"`` — no action (the plant's free motion);
* ``"lqg"`` — :class:`fir_gym.controllers.LQGController`: the LQR of the plant's nominal
  model, designed at its operating point, acting on the estimate it is drawn with (the
  classical baseline of ``fir-gym compare-controllers``);
* a run folder written by ``fir-gym train`` (``run.json``, ``model.zip``,
  ``vecnormalize.pkl``) — the trained controller, fed the observation it was trained
  on, normalised with the run's statistics. A run that observes an estimator is
  watched with that estimator; one that observes the true state or the raw
  measurement is watched with ``estimator`` running beside it
  (:class:`~fir_gym.wrappers.ShadowEstimator`).

One frame is drawn every ``every`` steps; by default (:func:`default_every`) as many
steps as play in real time — one frame per ``1 / fps`` seconds of the plant's time — and
more where the clip would last longer than :data:`CLIP_SECONDS`. Frames go to the file
as they are drawn, so memory stays that of one frame: ``.gif`` through
:class:`fir_gym._gif.GifStream` (Pillow, imageio's own dependency), ``.mp4`` through the
ffmpeg binary of the ``imageio-ffmpeg`` wheel. Both come with the ``video`` extra:
``pip install ".[video]"``.

Making a clip costs one ``render()`` per frame — about 2 ms for the numpy drawings and
30–50 ms for the MuJoCo pendulum under software OpenGL (``MUJOCO_GL=egl`` without a
GPU), plus encoding — and one step per step (well under a millisecond): the default
PendulumSlider-v0 GIF (5 000 steps, 251 frames) takes about 14 s of CPU, an Orbit-v0 GIF
(1 000 steps, 501 frames) about 5 s. A progress bar of the steps shows on stderr.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from ._extras import INSTALL, MissingExtra
from .episode_policy import POLICIES, Policy, classical_policy, run_config, trained_policy
from .wrappers import ShadowEstimator, wrap_observation

#: the file types :func:`watch` writes
VIDEO_SUFFIXES = (".gif", ".mp4")
#: seconds: the longest clip the default ``every`` makes, played at its frame rate
CLIP_SECONDS = 20.0
#: frames per second: the fastest a GIF plays (browsers show a delay under 20 ms as 100 ms)
GIF_MAX_FPS = 50.0
EXTRA = INSTALL["video"]


@dataclass(frozen=True)
class Recording:
    """What :func:`watch` wrote: the file, its frames, the steps and the episode's return,
    the playback rate and the steps between frames."""

    path: Path
    frames: int
    steps: int
    episode_return: float
    fps: float
    every: int = 1

    @property
    def seconds(self) -> float:
        """How long the clip plays (s)."""
        return self.frames / self.fps


def default_every(fps: float, dt: float | None, steps: int | None) -> int:
    """The steps between frames that :func:`watch` takes by default.

    Real time first: ``round(1 / (fps · dt))`` steps (at least 1), so a frame shows
    ``1 / fps`` seconds of a plant sampled every ``dt`` seconds. Where the episode's
    ``steps`` would then make a clip longer than :data:`CLIP_SECONDS`, more: the fewest
    that keep its ``1 + ceil(steps / every)`` frames within ``CLIP_SECONDS · fps`` (the
    clip then plays faster than real time). Without ``dt`` the real-time stride is 1,
    without ``steps`` the length is not capped.
    """
    every = max(1, round(1.0 / (fps * dt))) if dt is not None and dt > 0 else 1
    if steps is not None:
        frames = max(int(CLIP_SECONDS * fps), 2)
        every = max(every, math.ceil(steps / (frames - 1)))
    return every


def watch(
    env_id: str | None,
    out: str | Path,
    *,
    estimator: str | None = None,
    policy: str | Path = "zero",
    steps: int | None = None,
    seed: int = 0,
    fps: float | None = None,
    every: int | None = None,
    estimator_kwargs: Mapping[str, Any] | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    progress: bool = True,
) -> Recording:
    """Record one episode of ``env_id`` with ``estimator`` drawn over it to ``out``.

    Args:
        env_id: the environment id (``None`` with a run folder: the run's).
        out: the video file, ``.gif`` or ``.mp4``.
        estimator: the estimator drawn (a registry name); with a run that observes an
            estimator, ``None`` or that estimator.
        policy: ``"zero"``, ``"lqg"`` or a run folder of ``fir-gym train``.
        steps: at most this many steps (default: the episode's length).
        seed: the episode's seed (``reset(seed=...)``).
        fps: frames per second of the video (default: the plant's ``render_fps``, at most
            :data:`GIF_MAX_FPS` for a GIF).
        every: draw every ``every``-th step's frame (the first frame is ``reset``'s, the
            last the episode's end). Default (:func:`default_every`): the steps of one
            frame in real time, more where the clip would play longer than
            :data:`CLIP_SECONDS` — PendulumSlider-v0 (1 ms steps): 20 for a GIF at 50 fps,
            10 for an MP4 at 100 fps; Orbit-v0 (10 ms): 2; CarrierMotion-v0 (100 s at
            10 fps): 6.
        estimator_kwargs, env_kwargs: options of the estimator and of ``gym.make``.
        progress: show a progress bar of the steps on stderr (with tqdm, when installed).

    Returns:
        A :class:`Recording`. Raises ``ValueError`` naming the argument for bad input
        and :class:`MissingExtra` when the ``video`` extra (or, for a run, ``rl``) is
        missing.
    """
    path = Path(out)
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise ValueError(f"out must end in {' or '.join(VIDEO_SUFFIXES)}; got {str(out)!r}")
    for name, value in (("steps", steps), ("every", every)):
        if value is not None and (isinstance(value, bool) or int(value) != value or value < 1):
            raise ValueError(f"{name} must be a positive integer; got {value!r}")
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number; got {fps!r}")
    writer_factory = _writer_for(path)                  # a missing extra fails before the run
    env, act = _env_and_policy(env_id, estimator, policy, dict(estimator_kwargs or {}),
                               dict(env_kwargs or {}))
    rate = float(fps or _default_fps(env, path))
    limit = steps if steps is not None else (env.spec.max_episode_steps if env.spec else None)
    path.parent.mkdir(parents=True, exist_ok=True)
    obs, _ = env.reset(seed=seed)
    first = _frame(env)
    stride = int(every) if every is not None else default_every(rate, _sample_time(env), limit)
    total, k, frames = 0.0, 0, 1
    bar = _progress_bar(limit, path.name) if progress else None
    try:
        with writer_factory(rate) as write:
            write(first)
            del first
            while limit is None or k < limit:
                obs, reward, terminated, truncated, _ = env.step(act(obs))
                k += 1
                total += float(reward)
                if bar is not None:
                    bar.update(1)
                if k % stride == 0 or terminated or truncated:
                    write(_frame(env))
                    frames += 1
                if terminated or truncated:
                    break
    finally:
        if bar is not None:
            bar.close()
        env.close()
    return Recording(path, frames, k, total, rate, stride)


def _default_fps(env: gym.Env, path: Path) -> float:
    """The plant's ``render_fps``, at most :data:`GIF_MAX_FPS` for a GIF."""
    fps = float(env.metadata.get("render_fps", 30))
    return min(fps, GIF_MAX_FPS) if path.suffix.lower() == ".gif" else fps


def _sample_time(env: gym.Env) -> float | None:
    """The plant's sample period (s), from the view of the frame it rendered last."""
    view = getattr(env.unwrapped, "frame_view", None)
    dt = getattr(view, "dt", None)
    return float(dt) if dt is not None else None


def _progress_bar(total: int | None, name: str) -> Any:
    """A tqdm bar of ``total`` steps on stderr, or ``None`` without tqdm."""
    try:
        from tqdm.auto import tqdm
    except ImportError:  # tqdm is a dependency; a stripped install just shows no bar
        return None
    return tqdm(total=total, desc=f"watch {name}", unit="step", leave=False)


def _frame(env: gym.Env) -> NDArray[np.uint8]:
    frame = env.render()
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"the env rendered {type(frame).__name__}, not an rgb_array frame")
    return frame


# ---------------------------------------------------------------------- policies
def _env_and_policy(env_id: str | None, estimator: str | None, policy: str | Path,
                    estimator_kwargs: dict[str, Any], env_kwargs: dict[str, Any]
                    ) -> tuple[gym.Env, Policy]:
    """The env to record (rendering ``rgb_array``) and the policy that drives it."""
    if str(policy) in POLICIES:
        if env_id is None:
            raise ValueError("env is needed unless the policy is a run folder")
        if estimator is None:
            raise ValueError("estimator is needed: the video draws its estimate")
        env = gym.make(env_id, render_mode="rgb_array", estimator=estimator,
                       estimator_kwargs=estimator_kwargs, **env_kwargs)
        return env, classical_policy(env, str(policy))
    return _run_env_and_policy(Path(policy), env_id, estimator, estimator_kwargs, env_kwargs)


def _run_env_and_policy(run: Path, env_id: str | None, estimator: str | None,
                        estimator_kwargs: dict[str, Any], env_kwargs: dict[str, Any]
                        ) -> tuple[gym.Env, Policy]:
    """A trained run's controller on the env it was trained on, rendering its frames."""
    from .training import make_env

    config = run_config(run, env_id)
    kind = config.observation_kind
    kwargs = {**config.env_kwargs, **env_kwargs, "render_mode": "rgb_array"}
    if kind in ("true", "measurement"):
        if estimator is None:
            raise ValueError(f"estimator is needed: the run's controller observes {kind!r}; "
                             "the video draws an estimator running beside it")
        plant = gym.make(config.env_id, **kwargs)
        env = wrap_observation(ShadowEstimator(plant, estimator, **estimator_kwargs), kind)
    else:
        if estimator is not None and estimator != kind:
            raise ValueError(f"estimator is {estimator!r} but the run's controller observes "
                             f"{kind!r}: leave estimator out (or give {kind!r})")
        if estimator_kwargs:
            raise ValueError("estimator_kwargs cannot change the estimator the run was "
                             "trained with")
        env = make_env(dataclasses.replace(config, env_kwargs=kwargs))
    return env, trained_policy(run, config.algo_name, env)


# ---------------------------------------------------------------------- writers
class _Writer:
    """A context manager that appends frames to a GIF or an MP4 file as they come (neither
    keeps the frames: the GIF is encoded frame by frame, ffmpeg reads them from a pipe)."""

    def __init__(self, path: Path, fps: float) -> None:
        self.path, self.fps = path, fps
        self._writer: Any = None

    def __enter__(self) -> Callable[[NDArray[np.uint8]], None]:
        if self.path.suffix.lower() == ".gif":
            from ._gif import GifStream

            self._writer = GifStream(self.path, self.fps)          # loops forever
            return self._writer.append
        import imageio.v2 as imageio

        # ffmpeg (imageio-ffmpeg's binary): H.264 in yuv420p, which wants even sizes
        self._writer = imageio.get_writer(self.path, fps=self.fps, codec="libx264",
                                          pixelformat="yuv420p", macro_block_size=2,
                                          ffmpeg_log_level="error")
        return self._append_mp4

    def _append_mp4(self, frame: NDArray[np.uint8]) -> None:
        self._writer.append_data(_even(frame))

    def __exit__(self, *exc: object) -> None:
        self._writer.close()


def _even(frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """``frame`` padded by edge pixels to even height and width (H.264 in yuv420p)."""
    h, w = frame.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return frame
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def _writer_for(path: Path) -> Callable[[float], _Writer]:
    """A writer factory for ``path``'s type, once its packages are known to be there."""
    try:
        import imageio  # noqa: F401
    except ModuleNotFoundError:
        raise MissingExtra(f"writing {path.suffix} needs imageio: {EXTRA}") from None
    if path.suffix.lower() == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ModuleNotFoundError:
            raise MissingExtra(f"writing .mp4 needs imageio-ffmpeg (its ffmpeg binary): "
                               f"{EXTRA}, or write a .gif") from None
    return lambda fps: _Writer(path, fps)
