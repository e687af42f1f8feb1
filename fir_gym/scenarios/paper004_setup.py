"""Paper 004's setup: the documented examples its theorems are checked on, and the settings
of the checks.

Paper 004 has no numerical example (docs/papers.md#004-method): its claims are checked on
the aircraft-carrier model of paper 001 §V as ``fir_gym/CarrierMotion-v0`` samples it — the
time-invariant model (2.1) of :func:`example_model` — and on a second example with faster
filter dynamics (:data:`EXAMPLES`); the window lengths, window starts and prior scales of
the checks, and the size from which a round-off deviation counts as grown
(docs/papers.md#004-recursive-form). The checks (:mod:`.paper004`) and the report
(:mod:`.paper004_report`) import them from here; :mod:`.paper004` re-exports every name.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from fir_gym.estimators import LinearModel

from .prose import say

ENV_ID = "fir_gym/CarrierMotion-v0"
#: the two documented examples: CarrierMotion-v0 options and the number of steps simulated
EXAMPLES = {say("carrier, T = {t:g} s (paper 001)", t=0.1): ({"sample_period": 0.1}, 3000),
            say("carrier, T = {t:g} s, v = {v:g}", t=1.0, v=0.01): (
                {"sample_period": 1.0, "v": 0.01}, 300)}
GAIN_HORIZONS = {False: (3, 11, 51), True: (3, 11)}
RECURSIVE_HORIZON = 11
WINDOW_STARTS = (0, 100, 1000, 3000)
PRIOR_SCALES = (1e2, 1e4, 1e6)
#: a deviation counts as "grown" once it exceeds this (relative to the estimates' size)
GROWN = 1e-6


def example_model(**env_kwargs: Any) -> LinearModel:
    """CarrierMotion-v0's nominal model without its (zero) input matrix: paper 004's (2.1)."""
    env = gym.make(ENV_ID, **env_kwargs)
    m: Any = env.unwrapped.model                        # type: ignore[attr-defined]
    env.close()
    return LinearModel(A=m.A, C=m.C, Q=m.Q, R=m.R, G=m.G, dt=m.dt, name="carrier (paper 001)")
