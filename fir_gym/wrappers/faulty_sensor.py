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

Random numbers: every step draws, per system and in this order, one uniform for the stuck
chain (with ``stuck``), one uniform and ``n_y`` normals for the outliers (with
``outliers``) and one uniform for the dropout (with ``dropout``) — whatever the outcome, so
that the stream does not depend on the faults' history. With one generator per system each
system draws scalars from its own generator (a single env is a batch of one), so system
``i`` of a batch equals a single env with that generator; with one shared generator the
batch draws arrays (the same distributions, other numbers).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: the per-step flags, in the order of ``FaultySensor.flags``' columns
FLAGS = ("dropped", "stuck", "outlier", "biased", "unsampled", "late")
#: the mean number of steps a stuck sensor stays stuck when ``stuck`` is a probability alone
DEFAULT_STUCK_STEPS = 10
#: the tag that makes the fault generator's seed sequence differ from the plant's streams
FAULT_STREAM = 0x5E4505


def fault_generator(seed: int | None) -> np.random.Generator:
    """The sensor faults' generator for ``reset(seed=seed)``: PCG64 on ``[seed, FAULT_STREAM]``
    (fresh entropy for ``None``), independent of the plant's noise and condition streams."""
    if seed is None:
        return np.random.Generator(np.random.PCG64(np.random.SeedSequence()))
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed),
                                                                       FAULT_STREAM])))


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
    """``B`` faulty sensors in lock-step (module docstring): :meth:`read` one step's
    measurements, :meth:`restart` some systems (a new episode: working sensor, empty
    line, time 0). The state is plain arrays, so copies and pickles are exact."""

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

    def restart(self, rows: NDArray[np.bool_]) -> None:
        """A new episode for the systems ``rows``: time 0, a working sensor, nothing on the
        line, the prior's reading held."""
        self.k[rows] = 0
        self.stuck[rows] = False
        self.output[rows] = self.hold0
        self.held[rows] = self.hold0
        self.line[:, rows] = 0.0
        self.line_flags[:, rows] = False

    def read(self, y: FloatArray, rngs: Sequence[np.random.Generator]
             ) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
        """One step: the plant's measurements ``y (B, n_y)`` go in; out come what is delivered
        ``(B, n_y)`` (the held reading where missing), the ``missing (B,)`` mask and the flags
        ``(B, len(FLAGS))``. ``rngs``: one generator per system, or one for the batch."""
        spec, n_b = self.spec, self.n_b
        u_stuck, u_out, z_out, u_drop = self._draws(rngs)
        k = self.k
        flags = np.zeros((n_b, len(FLAGS)), dtype=bool)
        reading = np.array(y, dtype=np.float64).reshape(n_b, self.n_y)
        if spec.stuck_probability:
            self.stuck = np.where(self.stuck, u_stuck >= 1.0 / spec.stuck_steps,
                                  u_stuck < spec.stuck_probability)
            flags[:, 1] = self.stuck
        if spec.bias_step is not None and spec.bias_value is not None:
            biased = k >= spec.bias_step
            reading = reading + np.where(biased[:, None], spec.bias_value, 0.0)
            flags[:, 3] = biased
        if spec.outlier_probability:
            hit = u_out < spec.outlier_probability
            reading = reading + np.where(hit[:, None], spec.outlier_scale * (
                z_out @ self.noise_sqrt.T), 0.0)
            flags[:, 2] = hit
        reading = np.where(self.stuck[:, None], self.output, reading)
        self.output = reading
        if spec.every > 1:
            flags[:, 4] = k % spec.every != 0
        if spec.dropout:
            flags[:, 0] = u_drop < spec.dropout
        slot = k % (spec.delay + 1) if spec.delay else np.zeros(n_b, dtype=np.int64)
        rows = np.arange(n_b)
        self.line[slot, rows] = reading
        self.line_flags[slot, rows] = flags
        due = k - spec.delay
        late = due < 0
        out_slot = np.where(late, 0, due % (spec.delay + 1))
        delivered = self.line[out_slot, rows].copy()
        delivered_flags = np.where(late[:, None], False, self.line_flags[out_slot, rows])
        delivered_flags[:, 5] = late
        missing = late | delivered_flags[:, [0, 1, 4]].any(axis=1)
        delivered = np.where(missing[:, None], self.held, delivered)
        self.held = delivered.copy()
        self.k = k + 1
        return delivered, missing, delivered_flags

    def _draws(self, rngs: Sequence[np.random.Generator]
               ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """This step's random numbers, in the documented order (module docstring)."""
        spec, n_b, n_y = self.spec, self.n_b, self.n_y
        u_stuck, u_out, u_drop = np.zeros(n_b), np.zeros(n_b), np.zeros(n_b)
        z_out = np.zeros((n_b, n_y))
        if len(rngs) == 1 and n_b > 1:                # one generator for the batch
            rng = rngs[0]
            if spec.stuck_probability:
                u_stuck = rng.random(n_b)
            if spec.outlier_probability:
                u_out = rng.random(n_b)
                z_out = rng.standard_normal((n_b, n_y))
            if spec.dropout:
                u_drop = rng.random(n_b)
            return u_stuck, u_out, z_out, u_drop
        for i, rng in enumerate(rngs):                # one generator per system
            if spec.stuck_probability:
                u_stuck[i] = rng.random()
            if spec.outlier_probability:
                u_out[i] = rng.random()
                z_out[i] = rng.standard_normal(n_y)
            if spec.dropout:
                u_drop[i] = rng.random()
        return u_stuck, u_out, z_out, u_drop


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
