"""Paper 003's setup: what the paper prints, the truth, and the experiment's cells.

The numbers the report sets ours beside (Tables 4 and 5), the true parameters ``[μ, M0]``
and the 1 kHz sample period of §5, the thresholds of the claims of §5–§6 and their reading
per run (:func:`settle_index`, docs/papers.md#003-claims), and the settings the paper does
not give, fixed by a :class:`Cell` (docs/papers.md#003-experiment-reading): the named
cells, the sensitivity sweep's axes and scorings, and the plant of a cell. The experiment
(:mod:`.paper003`), its report (:mod:`.paper003_report`) and the LSM's rows
(:mod:`.paper003_lsm`) import them from here, so none of the three imports another's
module at import time; :mod:`.paper003` re-exports every name.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import gymnasium as gym
import numpy as np

from .prose import Printed, say

ENV_ID = "fir_gym/PendulumSlider-v0"
#: Table 4: state RMSE of the UKF estimate and of the measurement
PAPER_TABLE4 = {k: tuple(map(Printed, v)) for k, v in {
    "x": ("0.0010", "0.003"), "x_dot": ("0.0063", "0.0302"), "theta": ("0.0040", "0.0294"),
    "theta_dot": ("0.0361", "0.3008")}.items()}
#: Table 5: parameter errors (UKF: RMSE; LSM: error of the estimate)
PAPER_TABLE5 = {"UKF": {"mu": Printed("0.0044"), "M0": Printed("0.0010")},
                "LSM": {"mu": Printed("-0.0119"), "M0": Printed("-0.7251")}}
TRUE = {"mu": 0.2, "M0": 0.2}
DT = 1e-3
#: the paper's claims (§5, §6): within this share of the truth, within this time
WITHIN, CONVERGED_BY = 0.03, 0.1
#: a claim about one run holds when this share of the runs meets it
CLAIM_SHARE = 0.95
#: the time of the parameter snapshot of the tests and figures (s)
HALF = 0.5
DIFFERENCES = ("backward", "forward", "central")
PARAMS = ("mu", "M0")
#: the readings of the LSM's regression window (docs/papers.md#003-lsm-window): the whole record, or
#: only the Table 5 window (the samples from the cell's Table 5 scoring start ``t5`` on)
LSM_WINDOWS = ("whole", "window")


@dataclass(frozen=True)
class Cell:
    """One experiment: input ``amplitude · sin 2π·frequency·t`` N from ``[x_rest, 0, θ₀, 0]`` for
    ``seconds``, under ``dynamics``; Table 4 scored from ``t4``, Table 5 from ``t5`` seconds."""

    amplitude: float = 5.0
    frequency: float = 1.0
    theta0: float = 0.0
    seconds: float = 1.0
    dynamics: str = "physical"
    t4: float = 0.0
    t5: float = 0.1

    @property
    def steps(self) -> int:
        return round(self.seconds / DT)

    @property
    def label(self) -> str:
        """``A5·f1·θ0·T1`` (and the equations when printed)."""
        base = say("A{a:g}·f{f:g}·θ{t:g}·T{s:g}", a=self.amplitude, f=self.frequency,
                   t=self.theta0, s=self.seconds)
        return base if self.dynamics == "physical" else say(
            "{d}·{b}", d=self.dynamics.removeprefix("printed-"), b=base)


QUIET = Cell()
LIVELY = Cell(amplitude=10.0, theta0=0.5, seconds=5.0, t4=0.5, t5=0.5)
#: the named cells of the summary: (name, cell)
CELLS = {"quiet": QUIET, "lively": LIVELY,
         "eq15·quiet": replace(QUIET, dynamics="printed-eq15"),
         "eq15·lively": replace(LIVELY, dynamics="printed-eq15"),
         "eq5·quiet": replace(QUIET, dynamics="printed-eq5"),
         "eq5·lively": replace(LIVELY, dynamics="printed-eq5")}
DEFAULT = "quiet"
#: the sensitivity sweep (physical equations), full and quick
SWEEP_AXES: dict[bool, dict[str, tuple[float, ...]]] = {
    False: {"amplitude": (5.0, 10.0), "frequency": (1.0, 2.0), "theta0": (0.0, 0.5),
            "seconds": (1.0, 5.0)},
    True: {"amplitude": (5.0, 10.0), "frequency": (1.0,), "theta0": (0.0, 0.5),
           "seconds": (1.0,)}}
#: the two scorings of every sweep cell: (t4, t5)
SCORINGS = ((0.0, 0.1), (0.5, 0.5))


def make_env(cell: Cell) -> Any:
    """The cell's PendulumSlider-v0 (unwrapped, no time limit)."""
    return gym.make(ENV_ID, max_episode_steps=None, dynamics=cell.dynamics).unwrapped


def settle_index(err: np.ndarray, within: float = WITHIN) -> np.ndarray:
    """Per run and parameter, the first step from which ``|err| ≤ within·truth`` for good
    (``K+1`` if never); ``err`` is ``(K+1, B, 2)``."""
    truth = np.array([TRUE[p] for p in PARAMS])
    outside = ~(np.abs(err) <= within * truth)
    K1 = err.shape[0]
    last = K1 - 1 - np.argmax(outside[::-1], axis=0)            # last step outside
    return np.where(outside.any(axis=0), last + 1, 0).astype(int)
