"""The robustness conditions: named, seeded, documented, and applicable to every plant.

A condition is a way the world differs from what the estimator and the controller were
designed for, at a *strength* (docs/robustness.md#conditions):

* ``nominal`` — nothing: the plant, its model and a clean sensor;
* ``mismatch`` (a relative spread ``s`` in ``[0, 1)``) — every randomizable parameter of
  the plant drawn per episode as ``θ_nominal (1 + s ξ)``, ``ξ ~ U(−1, 1)``; the model
  keeps the nominal values;
* ``burst`` (``δ > −1``) — paper 000's temporary model uncertainty on any plant: the
  state's increment stretched by ``1 + δ`` for a tenth of the episode from its middle;
* ``dropout`` (a probability) — each reading lost;
* ``outliers`` (a probability) — a reading gets an extra 20 standard deviations of the
  measurement noise (ε-contamination);
* ``stuck`` (a probability per step) — a working sensor freezes, 10 steps on average
  (detected: the reading is missing);
* ``bias`` (standard deviations) — from the episode's middle, an undetected offset of that
  many measurement-noise standard deviations on every channel;
* ``delay`` (steps, an integer ≥ 1) — readings arrive that many steps late; the estimator
  is told (it filters ``y[k − d]`` and predicts ahead);
* ``multirate`` (steps, an integer ≥ 2) — the sensor samples every that many steps.

:func:`condition_setup` turns ``(name, strength)`` and a plant into what to build: the
plant's keyword arguments (``randomize``, ``burst``), the arguments of
:class:`~fir_gym.wrappers.SensorFaults` and the estimator's (``delay``). Every draw a
condition makes comes from a generator of the plant's or of the sensor's own, seeded from
the episode's seed, so the same seed gives the same perturbed episode everywhere and the
plant's own noise is the same under every condition (paired comparisons).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

#: the outliers' size, in standard deviations of the measurement noise
OUTLIER_SCALE = 20.0
#: a stuck sensor's mean number of stuck steps
STUCK_STEPS = 10
#: the burst's window: from this fraction of the episode, for this fraction of it
BURST_START, BURST_LENGTH = 0.5, 0.1
#: the bias starts at this fraction of the episode
BIAS_START = 0.5


@dataclass(frozen=True)
class Condition:
    """One named condition: its strength's meaning and range, and the benchmark's strengths.

    ``low``/``high`` bound the strength (``low_open``/``high_open``: the bound itself is
    excluded); ``integer`` strengths are whole numbers of steps.
    """

    name: str
    summary: str
    strength_meaning: str
    strengths: tuple[float, ...]
    low: float = 0.0
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    integer: bool = False
    acts_on: str = "sensor"
    #: whether some steps carry no reading (a filter that needs every measurement cannot
    #: run under it: ``Estimator.accepts_missing``)
    misses_readings: bool = False

    def check(self, strength: Any) -> float:
        """``strength`` as a number in range; ValueError naming the condition otherwise."""
        if self.name == "nominal":
            if strength not in (None, 0, 0.0):
                raise ValueError(f"condition 'nominal' takes no strength; got {strength!r}")
            return 0.0
        ok = not isinstance(strength, bool) and isinstance(strength, (int, float)) \
            and math.isfinite(float(strength))
        value = float(strength) if ok else math.nan
        inside = ok and (value > self.low if self.low_open else value >= self.low) and (
            value < self.high if self.high_open else value <= self.high)
        if inside and self.integer and value != int(value):
            inside = False
        if not inside:
            raise ValueError(f"condition {self.name!r}: strength must be {self.range_text()} "
                             f"({self.strength_meaning}); got {strength!r}")
        return value

    def range_text(self) -> str:
        if self.integer:
            return f"an integer >= {int(self.low)}"
        left = "(" if self.low_open else "["
        right = ")" if self.high_open or math.isinf(self.high) else "]"
        high = "inf" if math.isinf(self.high) else f"{self.high:g}"
        return f"in {left}{self.low:g}, {high}{right}"


@dataclass
class ConditionSetup:
    """What a condition at a strength builds on one plant: the plant's keyword arguments, the
    sensor faults (``SensorFaults`` keywords; empty: no wrapper) and the estimator's."""

    name: str
    strength: float
    plant_kwargs: dict[str, Any] = field(default_factory=dict)
    sensor_faults: dict[str, Any] = field(default_factory=dict)
    estimator_kwargs: dict[str, Any] = field(default_factory=dict)


CONDITIONS: dict[str, Condition] = {c.name: c for c in (
    Condition("nominal", "the plant, its model and a clean sensor", "none", (), acts_on="—"),
    Condition("mismatch", "true parameters drawn per episode around the model's",
              "relative spread of every randomizable parameter", (0.05, 0.1, 0.2),
              high=1.0, high_open=True, acts_on="plant"),
    Condition("burst", "the dynamics run 1+δ times as fast for a tenth of the episode",
              "δ", (0.05, 0.15, 0.3), low=-1.0, low_open=True, acts_on="plant"),
    Condition("dropout", "readings lost", "probability of a lost reading", (0.1, 0.3, 0.6),
              high=1.0, misses_readings=True),
    Condition("outliers", f"readings hit by {OUTLIER_SCALE:g}σ outliers",
              "probability of an outlier", (0.01, 0.05, 0.1), high=1.0),
    Condition("stuck", f"the sensor freezes ({STUCK_STEPS} steps on average)",
              "probability per step that a working sensor freezes", (0.005, 0.02, 0.05),
              high=1.0, misses_readings=True),
    Condition("bias", "an undetected offset from the episode's middle",
              "measurement-noise standard deviations", (1.0, 3.0, 10.0)),
    Condition("delay", "readings arrive late (the estimator is told)", "steps of delay",
              (1, 2, 5), low=1, integer=True, misses_readings=True),
    Condition("multirate", "the sensor samples every few steps", "steps between samples",
              (2, 5, 10), low=2, integer=True, misses_readings=True),
)}


def condition_names() -> list[str]:
    return list(CONDITIONS)


def get_condition(name: str) -> Condition:
    """The condition called ``name``; ValueError listing the names otherwise."""
    if name not in CONDITIONS:
        raise ValueError(f"unknown condition {name!r}; conditions are "
                         f"{', '.join(CONDITIONS)}")
    return CONDITIONS[name]


def condition_setup(name: str, strength: Any, plant: Any,
                    episode_steps: int | None = None) -> ConditionSetup:
    """What condition ``name`` at ``strength`` builds on ``plant`` (a fir-gym plant:
    ``env.unwrapped``), for episodes of ``episode_steps`` (default: the plant's
    ``max_episode_steps``)."""
    import numpy as np

    condition = get_condition(name)
    s = condition.check(strength)
    steps = int(episode_steps or plant.max_episode_steps)
    setup = ConditionSetup(name, s)
    if name == "mismatch":
        names = tuple(getattr(plant, "randomizable", ()))
        if not names:
            raise ValueError(f"condition 'mismatch': {type(plant).__name__} has no randomizable "
                             "parameters")
        setup.plant_kwargs["randomize"] = {p: s for p in names}
    elif name == "burst":
        first = int(BURST_START * steps)
        last = first + max(1, int(BURST_LENGTH * steps)) - 1
        setup.plant_kwargs["burst"] = ((first, last, s),)
    elif name == "dropout":
        setup.sensor_faults["dropout"] = s
    elif name == "outliers":
        setup.sensor_faults["outliers"] = (s, OUTLIER_SCALE)
    elif name == "stuck":
        setup.sensor_faults["stuck"] = (s, STUCK_STEPS)
    elif name == "bias":
        std = np.sqrt(np.diag(np.asarray(plant.measurement_cov, dtype=np.float64)))
        setup.sensor_faults["bias"] = (int(BIAS_START * steps), (s * std).tolist())
    elif name == "delay":
        d = int(s)
        if d >= steps:
            raise ValueError(f"condition 'delay': {d} steps is not shorter than an episode "
                             f"({steps} steps)")
        setup.sensor_faults["delay"] = d
        setup.estimator_kwargs["delay"] = d
    elif name == "multirate":
        setup.sensor_faults["every"] = int(s)
    if setup.sensor_faults:
        from fir_gym.wrappers.faulty_sensor import check_faults

        check_faults(n_y=len(plant.measurement_names), episode_steps=steps,
                     **setup.sensor_faults)
    return setup


def describe_conditions() -> list[list[str]]:
    """Rows ``[name, strength, benchmark strengths, what it does]`` for ``fir-gym list``."""
    rows = []
    for c in CONDITIONS.values():
        strengths = ", ".join(f"{v:g}" for v in c.strengths) or "—"
        meaning = "—" if c.name == "nominal" else f"{c.strength_meaning}, {c.range_text()}"
        rows.append([c.name, meaning, strengths, c.summary])
    return rows
