"""The plant side of the robustness conditions: per-episode parameter draws and bursts.

Every plant built on :class:`~fir_gym.envs._base.PlantEnv` takes two constructor
arguments (docs/robustness.md#plant-conditions):

* ``randomize={"mu": 0.02, ...}`` — at every ``reset`` the *true* value of each named
  parameter is drawn around the nominal one (the value the filter's model believes),
  ``θ = θ_nominal (1 + s ξ)`` with ``ξ ~ U(−1, 1)`` and the relative spread ``s`` in
  ``[0, 1)`` (so a positive parameter stays positive). The names must be among the
  plant's :attr:`~fir_gym.envs._base.PlantEnv.randomizable` parameters. The model is not
  touched: the filter keeps the nominal values. The drawn values are in
  ``info["true_params"]`` at ``reset`` and every step.
* ``burst=((k_first, k_last, δ), ...)`` — a scheduled multiplicative perturbation of the
  dynamics: for the transitions ``x[k] → x[k+1]`` with ``k_first <= k <= k_last``
  (inclusive; overlapping windows add) the state's path over the step is stretched by
  ``1 + δ`` about its start, so that ``x[k+1] = x[k] + (1 + δ) (x̃[k+1] − x[k])``, where
  ``x̃[k+1]`` is the plant's own transition (process noise included). This is paper 000's
  temporary model uncertainty in its "rate" reading, eq (29) (docs/papers.md#000-eq-29-readings),
  generalised to any plant: the dynamics run ``1 + δ`` times as fast for the window. A
  plant whose measurement is a functional of the path over the step (Van der Pol's interval
  average) stretches it the same way; UncertainOscillator-v0 adds the burst to its own δ
  schedule (its reading of eq (29)). ``info["burst"]`` is the step's ``δ`` (0 outside).

Draws come from a generator of the plant's own, separate from the one that draws the
plant's noise (``np_random``), so that an episode with a condition and one without, on
the same seed, see the same noise: their returns can be compared pair by pair. It is
seeded from ``reset(seed=...)`` (:func:`condition_generator`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: one burst window: ``(k_first, k_last, δ)``, inclusive
Window = tuple[int, int, float]

#: the tag that makes a condition generator's seed sequence differ from ``np_random``'s
CONDITION_STREAM = 0xC0D17


def condition_generator(seed: int | None) -> np.random.Generator:
    """The generator condition draws come from, for ``reset(seed=seed)``: PCG64 on the seed
    sequence ``[seed, CONDITION_STREAM]`` (fresh OS entropy for ``None``). Gymnasium seeds
    ``np_random`` from ``SeedSequence(seed)``, so the two streams are independent."""
    if seed is None:
        return np.random.Generator(np.random.PCG64(np.random.SeedSequence()))
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed),
                                                                       CONDITION_STREAM])))


def check_randomize(randomize: Mapping[str, Any] | None, randomizable: Iterable[str],
                    plant: str) -> dict[str, float]:
    """``randomize`` as ``{name: spread}``, names sorted; ValueError/TypeError naming it."""
    if randomize is None:
        return {}
    if not isinstance(randomize, Mapping):
        raise TypeError(f"randomize must be a mapping of parameter names to relative spreads, "
                        f"e.g. {{'mu': 0.02}}; got {type(randomize).__name__}")
    allowed = tuple(randomizable)
    unknown = sorted(str(k) for k in set(randomize) - set(allowed))
    if unknown:
        known = ", ".join(allowed) if allowed else "none"
        raise ValueError(f"randomize names {unknown}, which {plant} cannot randomize; its "
                         f"randomizable parameters: {known}")
    out: dict[str, float] = {}
    for name in sorted(randomize):
        value = randomize[name]
        ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer,
                                                                  np.floating))
        spread = float(value) if ok else float("nan")
        if not (0.0 <= spread < 1.0):
            raise ValueError(f"randomize[{name!r}] must be a relative spread in [0, 1); got "
                             f"{value!r}")
        out[name] = spread
    return out


def draw_params(rng: Any, nominal: Mapping[str, Any], spreads: Mapping[str, float],
                n: int | None = None) -> dict[str, Any]:
    """One draw (``n`` None: floats) or ``n`` draws (``(n,)`` arrays) of each randomized
    parameter, ``nominal (1 + s ξ)``, ``ξ ~ U(−1, 1)``, in the sorted order of the names
    (one ``uniform`` call per parameter)."""
    out: dict[str, Any] = {}
    for name in sorted(spreads):
        xi = rng.uniform(-1.0, 1.0, size=n)
        out[name] = float(nominal[name]) * (1.0 + spreads[name] * xi)
        if n is None:
            out[name] = float(out[name])
    return out


def check_burst(burst: Sequence[Window] | None, name: str = "burst") -> tuple[Window, ...]:
    """``burst`` as a tuple of ``(k_first, k_last, δ)``: integers ``0 <= k_first <= k_last``
    and a finite ``δ > −1``; ValueError naming ``name`` otherwise."""
    if burst is None:
        return ()
    out = []
    try:
        for first, last, delta in burst:
            first_, last_, delta_ = int(first), int(last), float(delta)
            if first_ != first or last_ != last or first_ < 0 or last_ < first_:
                raise ValueError
            if isinstance(delta, bool) or not np.isfinite(delta_) or delta_ <= -1.0:
                raise ValueError
            out.append((first_, last_, delta_))
    except (TypeError, ValueError):
        raise ValueError(
            f"{name} must be a sequence of (k_first, k_last, delta) with integer "
            f"0 <= k_first <= k_last and finite delta > -1; got {burst!r}") from None
    return tuple(out)


def burst_delta(windows: Sequence[Window], k: Any) -> Any:
    """The ``δ`` of the transition from ``x[k]`` (``k`` an int: a float; an array: per entry);
    overlapping windows add."""
    if isinstance(k, (int, np.integer)):
        return float(sum(d for first, last, d in windows if first <= k <= last))
    k_ = np.asarray(k)
    total = np.zeros(k_.shape)
    for first, last, d in windows:
        total = total + d * ((first <= k_) & (k_ <= last))
    return total


def stretch(x: FloatArray, x_next: FloatArray, delta: Any) -> FloatArray:
    """``x + (1 + δ) (x_next − x)`` — one system, or a batch with one ``δ`` per row."""
    d = np.asarray(delta, dtype=np.float64)
    scale = 1.0 + (d[..., None] if d.ndim else d)
    return x + scale * (x_next - x)


def entry(value: Any, i: int) -> float:
    """A true parameter's value for system ``i``: the number itself, or the ``i``-th of an
    array of one value per system (a native vector env's randomized parameter)."""
    return float(value) if not isinstance(value, np.ndarray) else float(value.reshape(-1)[i])


def column(value: Any) -> FloatArray:
    """A true parameter as the compiled interval loops take it: ``(1,)`` for a number, the
    ``(B,)`` array of one value per system otherwise."""
    return np.ascontiguousarray(np.atleast_1d(np.asarray(value, dtype=np.float64)))


def per_system(*values: Any) -> bool:
    """Whether any of the parameters holds one value per system (an array)."""
    return any(isinstance(v, np.ndarray) for v in values)
