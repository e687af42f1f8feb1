"""A batch of faulty sensors: what :class:`~fir_gym.wrappers.SensorFaults` puts between a
plant's measurement and whoever reads it (docs/robustness.md#sensor-faults).

At every time ``k`` the sensor of each system reads the plant's measurement ``y[k]`` and

1. **stuck** — a working sensor freezes with probability ``p`` and a frozen one recovers
   with probability ``1 / mean_steps`` (a two-state Markov chain; a frozen sensor repeats
   its last output exactly, which the receiver detects: a reading equal bit for bit to the
   previous one never comes from a noisy sensor);
2. **bias** — from time ``k_bias`` on, ``value`` is added (an undetected calibration
   fault: it reaches the filter as a number);
3. **outliers** — with probability ``p`` the reading gets an extra ``scale · L z``,
   ``z ~ N(0, I)``, ``L Lᵀ`` the plant's measurement noise covariance (Huber's
   ε-contaminated Gaussian: an outlier of ``scale`` standard deviations);
4. **every** — a multi-rate sensor samples only at ``k = 0, every, 2·every, …``;
5. **dropout** — the reading is lost in transmission with probability ``p``;
6. **delay** — what is transmitted at ``k`` arrives at ``k + delay`` (``y[k − d]`` is
   delivered at ``k``; nothing has arrived for ``k < d``).

A reading that is dropped, stuck, not sampled or not yet due is **missing**: the filter
takes a prediction step (``step(None)``), never a number. A controller that reads the
sensor directly sees the last reading delivered (a zero-order hold; before the first, the
measurement the plant's prior predicts, ``h(initial_state)`` — no value ever comes from the
truth). Per system and step the flags say which faults acted on what was delivered:
``dropped``, ``stuck``, ``outlier``, ``biased``, ``unsampled``, ``late`` (nothing due yet).

Random numbers: four streams per system — the stuck chain's uniforms, the outliers'
uniforms, the outliers' normals (``n_y`` a step) and the dropout's uniforms — from four
generators spawned from the seed sequence ``[seed, FAULT_STREAM]`` of the system's episode
(:func:`fault_generators`). A stream is drawn once every step while its fault is on,
whatever the outcome, and never otherwise, so one fault's numbers do not depend on which
others are on or on the faults' history. Every system has its own streams (served a block
at a time by :class:`~fir_gym.envs._streams.RowStreams`, bit for bit the scalar draws), so
system ``i`` of a batch seeded ``seed + i`` equals a single env seeded ``seed + i``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fir_gym.envs._streams import RowStreams

FloatArray = NDArray[np.float64]

#: the per-step flags, in the order of ``FaultySensor.flags``' columns
FLAGS = ("dropped", "stuck", "outlier", "biased", "unsampled", "late")
#: the mean number of steps a stuck sensor stays stuck when ``stuck`` is a probability alone
DEFAULT_STUCK_STEPS = 10
#: the tag that makes the fault generator's seed sequence differ from the plant's streams
FAULT_STREAM = 0x5E4505


#: the streams of one system, in the order they are spawned, and their kind
STREAMS = (("stuck", "uniform"), ("outlier", "uniform"), ("outlier_size", "normal"),
           ("dropout", "uniform"))


def fault_generators(seed: int | None) -> list[np.random.Generator]:
    """One system's four fault generators for an episode seeded ``seed`` (:data:`STREAMS`):
    PCG64 on the children of the seed sequence ``[seed, FAULT_STREAM]`` (fresh entropy for
    ``None``), independent of the plant's noise and condition streams."""
    root = np.random.SeedSequence() if seed is None else \
        np.random.SeedSequence([int(seed), FAULT_STREAM])
    return [np.random.Generator(np.random.PCG64(child)) for child in root.spawn(len(STREAMS))]


@dataclass(frozen=True)
class FaultSpec:
    """The checked arguments of :class:`~fir_gym.wrappers.SensorFaults` (see the module)."""

    dropout: float = 0.0
    outlier_probability: float = 0.0
    outlier_scale: float = 0.0
    stuck_probability: float = 0.0
    stuck_steps: float = DEFAULT_STUCK_STEPS
    bias_step: int | None = None
    bias_value: FloatArray | None = None
    delay: int = 0
    every: int = 1

    @property
    def active(self) -> bool:
        """Whether any fault is configured."""
        return bool(self.dropout or self.outlier_probability or self.stuck_probability
                    or self.bias_step is not None or self.delay or self.every > 1)

    def describe(self) -> dict[str, Any]:
        """The arguments as given to the wrapper (JSON-friendly)."""
        out: dict[str, Any] = {}
        if self.dropout:
            out["dropout"] = self.dropout
        if self.outlier_probability:
            out["outliers"] = [self.outlier_probability, self.outlier_scale]
        if self.stuck_probability:
            out["stuck"] = [self.stuck_probability, self.stuck_steps]
        if self.bias_step is not None and self.bias_value is not None:
            out["bias"] = [self.bias_step, self.bias_value.tolist()]
        if self.delay:
            out["delay"] = self.delay
        if self.every > 1:
            out["every"] = self.every
        return out


def check_faults(*, n_y: int, episode_steps: int | None, dropout: Any = 0.0,
                 outliers: Any = None, stuck: Any = None, bias: Any = None, delay: Any = 0,
                 every: Any = 1) -> FaultSpec:
    """The wrapper's arguments as a :class:`FaultSpec`; ValueError naming the argument and
    what it must be (a ``delay`` or ``every`` as long as an episode is refused)."""
    spec: dict[str, Any] = {"dropout": _probability("dropout", dropout)}
    if outliers is not None:
        p, scale = _pair("outliers", outliers, "(probability, scale in standard deviations)")
        spec["outlier_probability"] = _probability("outliers' probability", p)
        scale_ = _number("outliers' scale", scale)
        if not scale_ > 0:
            raise ValueError(f"outliers' scale must be a positive number of standard "
                             f"deviations; got {scale!r}")
        spec["outlier_scale"] = scale_
    if stuck is not None:
        if isinstance(stuck, (tuple, list)):
            p, steps = _pair("stuck", stuck, "(probability, mean stuck steps)")
        else:
            p, steps = stuck, DEFAULT_STUCK_STEPS
        spec["stuck_probability"] = _probability("stuck's probability", p)
        steps_ = _number("stuck's mean steps", steps)
        if not steps_ >= 1:
            raise ValueError(f"stuck's mean number of steps must be >= 1; got {steps!r}")
        spec["stuck_steps"] = steps_
    if bias is not None:
        k, value = _pair("bias", bias, "(step, value)")
        spec["bias_step"] = _integer("bias' step", k, 0)
        v = np.asarray(value, dtype=np.float64) if not isinstance(value, (str, bool)) \
            else np.array(np.nan)
        v = np.broadcast_to(v, (n_y,)).copy() if v.ndim == 0 else v
        if v.shape != (n_y,) or not np.all(np.isfinite(v)):
            raise ValueError(f"bias' value must be a finite number or {n_y} finite numbers "
                             f"(one per measured channel); got {value!r}")
        spec["bias_value"] = v
    spec["delay"] = _integer("delay", delay, 0)
    spec["every"] = _integer("every", every, 1)
    if episode_steps is not None:
        for name in ("delay", "every"):
            if spec[name] >= episode_steps:
                raise ValueError(f"{name}={spec[name]} is not shorter than an episode "
                                 f"({episode_steps} steps): no measurement would ever arrive")
    return FaultSpec(**spec)


class FaultySensor:
    """``B`` faulty sensors in lock-step (module docstring): :meth:`seed` their random streams,
    :meth:`read` one step's measurements (of all systems or some), :meth:`restart` some
    systems (a new episode: working sensor, empty line, time 0). The state is plain arrays
    and generators, so copies and pickles continue exactly."""

    def __init__(self, spec: FaultSpec, n_y: int, n_b: int, noise_sqrt: FloatArray,
                 hold: FloatArray) -> None:
        self.spec, self.n_y, self.n_b = spec, n_y, n_b
        self.noise_sqrt = np.asarray(noise_sqrt, dtype=np.float64)
        self.hold0 = np.asarray(hold, dtype=np.float64).reshape(n_y)
        d = spec.delay
        #: the time of each system's next reading
        self.k = np.zeros(n_b, dtype=np.int64)
        self.stuck = np.zeros(n_b, dtype=bool)
        #: each system's last sensor output (what a stuck sensor repeats)
        self.output = np.tile(self.hold0, (n_b, 1))
        #: the last reading delivered (what a direct reader holds)
        self.held = np.tile(self.hold0, (n_b, 1))
        #: the transmission line, a ring of ``delay + 1`` slots: readings and their flags
        self.line = np.zeros((d + 1, n_b, n_y))
        self.line_flags = np.zeros((d + 1, n_b, len(FLAGS)), dtype=bool)
        #: each stream of :data:`STREAMS`, one generator per system
        self.streams: dict[str, RowStreams] | None = None

    def seed(self, seeds: Sequence[int | None]) -> None:
        """New generators for the systems whose seed is given (fresh entropy for ``None`` where
        they have none yet; a system with ``None`` keeps its streams)."""
        if len(seeds) != self.n_b:
            raise ValueError(f"seeds must have {self.n_b} entries; got {len(seeds)}")
        if self.streams is None:
            per_system = [fault_generators(s) for s in seeds]
            self.streams = {name: RowStreams([g[j] for g in per_system], kind)
                            for j, (name, kind) in enumerate(STREAMS)}
            return
        for i, s in enumerate(seeds):
            if s is not None:
                for (name, _), g in zip(STREAMS, fault_generators(s), strict=True):
                    self.streams[name].replace(i, g)

    def restart(self, rows: NDArray[np.bool_]) -> None:
        """A new episode for the systems ``rows``: time 0, a working sensor, nothing on the
        line, the prior's reading held."""
        self.k[rows] = 0
        self.stuck[rows] = False
        self.output[rows] = self.hold0
        self.held[rows] = self.hold0
        self.line[:, rows] = 0.0
        self.line_flags[:, rows] = False

    def read(self, y: FloatArray, rows: NDArray[np.bool_] | None = None
             ) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
        """One step of the systems ``rows`` (all for ``None``): their measurements ``y (n,
        n_y)`` go in; out come what is delivered ``(n, n_y)`` (the held reading where
        missing), the ``missing (n,)`` mask and the flags ``(n, len(FLAGS))``."""
        if self.streams is None:
            self.seed([None] * self.n_b)
        assert self.streams is not None
        spec, streams = self.spec, self.streams
        idx = np.arange(self.n_b) if rows is None else np.flatnonzero(rows)
        n = len(idx)
        k = self.k[idx]
        stuck = self.stuck[idx]
        flags = np.zeros((n, len(FLAGS)), dtype=bool)
        reading = np.array(y, dtype=np.float64).reshape(n, self.n_y)
        if spec.stuck_probability:
            u = streams["stuck"].draw(rows, 1)[:, 0]
            stuck = np.where(stuck, u >= 1.0 / spec.stuck_steps, u < spec.stuck_probability)
            flags[:, 1] = stuck
        if spec.bias_step is not None and spec.bias_value is not None:
            biased = k >= spec.bias_step
            reading = reading + np.where(biased[:, None], spec.bias_value, 0.0)
            flags[:, 3] = biased
        if spec.outlier_probability:
            hit = streams["outlier"].draw(rows, 1)[:, 0] < spec.outlier_probability
            size = streams["outlier_size"].draw(rows, self.n_y)
            reading = reading + np.where(hit[:, None], spec.outlier_scale * (
                size @ self.noise_sqrt.T), 0.0)
            flags[:, 2] = hit
        if spec.dropout:
            flags[:, 0] = streams["dropout"].draw(rows, 1)[:, 0] < spec.dropout
        reading = np.where(stuck[:, None], self.output[idx], reading)
        if spec.every > 1:
            flags[:, 4] = k % spec.every != 0
        ring = spec.delay + 1
        slot = k % ring
        self.line[slot, idx] = reading
        self.line_flags[slot, idx] = flags
        due = k - spec.delay
        late = due < 0
        out_slot = np.where(late, 0, due % ring)
        delivered = self.line[out_slot, idx].copy()
        delivered_flags = np.where(late[:, None], False, self.line_flags[out_slot, idx])
        delivered_flags[:, 5] = late
        missing = late | delivered_flags[:, [0, 1, 4]].any(axis=1)
        delivered = np.where(missing[:, None], self.held[idx], delivered)
        self.stuck[idx] = stuck
        self.output[idx] = reading
        self.held[idx] = delivered
        self.k[idx] = k + 1
        return delivered, missing, delivered_flags


def flag_dict(flags: NDArray[np.bool_], single: bool) -> dict[str, Any]:
    """The flags as ``{name: bool}`` (one system) or ``{name: (B,) array}``."""
    if single:
        return {name: bool(flags[0, j]) for j, name in enumerate(FLAGS)}
    return {name: flags[:, j].copy() for j, name in enumerate(FLAGS)}


def _probability(name: str, value: Any) -> float:
    p = _number(name, value)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"{name} must be a probability in [0, 1]; got {value!r}")
    return p


def _number(name: str, value: Any) -> float:
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    number = float(value) if ok else float("nan")
    if not np.isfinite(number):
        raise ValueError(f"{name} must be a finite number; got {value!r}")
    return number


def _integer(name: str, value: Any, minimum: int) -> int:
    ok = not isinstance(value, bool) and isinstance(value, (int, np.integer))
    if not ok or int(value) < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def _pair(name: str, value: Any, what: str) -> tuple[Any, Any]:
    if isinstance(value, Mapping) or not isinstance(value, (tuple, list)) or len(value) != 2:
        raise ValueError(f"{name} must be a pair {what}; got {value!r}")
    return value[0], value[1]
