"""Paper 003's least-squares baseline (LSM) in the report: Table 5's LSM rows under both
readings of the regression window, and the errors-in-variables law that explains them.

The paper does not say which samples its LSM regresses (docs/papers.md#003-lsm-window): the
whole record (``0 ≤ t ≤ T``, our default), or only the Table 5 window (``t ≥ t5``, the
cell's Table 5 scoring start — the reading ``<cell>·window``). Both are run on every
named cell and sweep cell, each with its own rows and verdicts. The law is evaluated on
the window it explains: ``E[θ̇²]`` over the same samples the regression reads.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .paper003_setup import (
    DEFAULT,
    DT,
    LSM_WINDOWS,
    PAPER_TABLE5,
    PARAMS,
    SCORINGS,
    TRUE,
    Cell,
    make_env,
)
from .prose import say
from .report import Report, Summary, number_verdict

__all__ = ["LSM_WINDOWS", "attenuation", "bias_law", "energy_for_bias", "errors",
           "hinge_inertia", "law", "measurement_variance", "reading", "row", "start_of",
           "sweep_table", "sweep_value", "window_note", "window_phrase"]


def start_of(cell: Cell, window: str, t5: float | None = None) -> float:
    """The first time (s) the LSM regresses under ``window``: ``0`` for ``"whole"``, the
    Table 5 scoring start (``t5``, default the cell's) for ``"window"``."""
    if window not in LSM_WINDOWS:
        raise ValueError(f"window must be one of {LSM_WINDOWS}; got {window!r}")
    return 0.0 if window == "whole" else (cell.t5 if t5 is None else t5)


def reading(name: str, window: str) -> str:
    """The reading of a row: the cell's name, ``·window`` for the Table 5 window."""
    return name if window == "whole" else say("{n}·window", n=name)


def window_phrase(start: float) -> str:
    """``"over the whole record"`` or ``"over t ≥ 0.5 s"``."""
    return "over the whole record" if start == 0.0 else say("over t ≥ {t:g} s", t=start)


def errors(sc: dict[str, Any], start: float, difference: str = "backward") -> np.ndarray | None:
    """The LSM's per-run errors ``(runs, 2)`` of ``[μ, M0]`` regressing from ``start`` (``None``
    when the slider left the rail in some run)."""
    return None if sc["lsm"] is None else sc["lsm"][start][difference]


def _mean_se(err: np.ndarray) -> tuple[float, float]:
    return float(err.mean()), float(np.std(err, ddof=1) / np.sqrt(len(err)))


def hinge_inertia(cell: Cell) -> float:
    """``J`` of the cell's equations (``I_c + m2 l²``; printed: ``I_c + m1 l²``)."""
    env = make_env(cell)
    J = float(env.dynamics.hinge_inertia)
    env.close()
    return J


def measurement_variance(cell: Cell) -> float:
    """The variance ``σ²`` of the measured ``θ̇``."""
    env = make_env(cell)
    v = float(env.params["R"][3, 3])
    env.close()
    return v


def law(E: float, cell: Cell) -> float:
    """The errors-in-variables bias of the backward-difference LSM estimate of M0 for a
    trajectory with ``E[θ̇²] = E``.

    With measured ``θ̇ = θ̇_true + n`` (variance ``σ²``), the regression
    ``M0 θ̇ = ... − J (θ̇_k − θ̇_{k−1}) / dt`` correlates its regressor with its target
    through ``n_k``: ``E[M0_hat] ≈ (M0 E[θ̇²] − J σ²/dt) / (E[θ̇²] + σ²)``.
    """
    J, s2 = hinge_inertia(cell), measurement_variance(cell)
    return (TRUE["M0"] * E - J * s2 / DT) / (E + s2) - TRUE["M0"]


def bias_law(sc: dict[str, Any], start: float = 0.0) -> float:
    """:func:`law` for a cell's trajectory, ``E[θ̇²]`` over the samples ``t ≥ start``."""
    return law(sc["rate_ms"][start], sc["cell"])


def attenuation(sc: dict[str, Any], start: float = 0.0) -> float:
    """What remains of the bias with central differences: the attenuation
    ``−M0 σ²/(E[θ̇²] + σ²)`` over the samples ``t ≥ start``."""
    s2 = measurement_variance(sc["cell"])
    return -TRUE["M0"] * s2 / (sc["rate_ms"][start] + s2)


def energy_for_bias(bias: float, cell: Cell) -> float:
    """Solve the law for ``E[θ̇²]``: ``(M0 E − J σ²/dt)/(E + σ²) = M0 + bias``."""
    J, s2 = hinge_inertia(cell), measurement_variance(cell)
    return (J * s2 / DT + (TRUE["M0"] + bias) * s2) / (-bias)


def row(s: Summary, quantity: str, paper: Any, name: str, sc: dict[str, Any], j: int,
        window: str) -> None:
    """The LSM row (backward differences) of parameter ``j`` on named cell ``name``."""
    start = start_of(sc["cell"], window)
    err = errors(sc, start)
    if err is None:
        s.compare(quantity, paper, "left the rail", reading(name, window),
                  "not reproduced: differs",
                  "the slider left the rail in some run: no regression")
        return
    mean, se = _mean_se(err[:, j])
    central = float(errors(sc, start, "central")[:, j].mean())   # type: ignore[index]
    if PARAMS[j] == "mu":
        note = say("± {s:.3f} over the runs {w}; central differences: {c:+.4f}",
                   s=float(np.std(err[:, j])), w=window_phrase(start), c=central)
    else:
        note = say("errors-in-variables: the law gives {law:+.3f} for E[θ̇²] = {e:.3g} {w}; "
                   "central differences: {c:+.4f}", law=bias_law(sc, start),
                   e=sc["rate_ms"][start], w=window_phrase(start), c=central)
    label = reading(name, window)
    s.compare(quantity, paper, mean, label,
              number_verdict(paper, mean, se=se, reading=None if label == DEFAULT else label,
                             otherwise="ambiguous"), note)


def sweep_value(j: int, window: str) -> Any:
    """For the sweep's nearest cell: ``(mean, se)`` of parameter ``j``'s backward LSM error of
    a sweep cell under a scoring ``(t4, t5)`` (the window from its ``t5``), or ``None``."""
    def value(sc: dict[str, Any], scoring: tuple[float, float]) -> tuple[float, float] | None:
        err = errors(sc, start_of(sc["cell"], window, scoring[1]))
        return None if err is None else _mean_se(err[:, j])
    return value


def window_note(named: dict[str, dict[str, Any]], name: str) -> str:
    """What regressing only the Table 5 window does to the backward M0 error of cell ``name``,
    and the law's account of it."""
    sc = named[name]
    m0 = PARAMS.index("M0")
    start = start_of(sc["cell"], "window")
    whole, win = errors(sc, 0.0), errors(sc, start)
    if whole is None or win is None:
        return say("LSM window ({n}): the slider left the rail; no regression.", n=name)
    r0, r1 = float(whole[:, m0].mean()), float(win[:, m0].mean())
    l0, l1 = bias_law(sc, 0.0), bias_law(sc, start)
    E0, E1 = sc["rate_ms"][0.0], sc["rate_ms"][start]
    paper = float(PAPER_TABLE5["LSM"]["M0"])
    return say(
        "LSM window ({n}): over t ≥ {t:g} s the trajectory has E[θ̇²] = {e1:.2f} rad²/s² "
        "against {e0:.2f} over the whole record ({which} lively), so the errors-in-variables "
        "law gives {l1:+.3f} against {l0:+.3f} and the regression gives {r1:+.3f} against "
        "{r0:+.3f} (backward differences, M0): the law predicts a change of {dl:+.3f}, the "
        "regression changes by {dr:+.3f}. Regressing only the Table 5 window moves the M0 "
        "error {direction} the paper's {p}.",
        n=name, t=start, e1=E1, e0=E0, which="less" if E1 < E0 else "more", l1=l1, l0=l0,
        r1=r1, r0=r0, dl=l1 - l0, dr=r1 - r0,
        direction="towards" if abs(r1 - paper) < abs(r0 - paper) else "away from",
        p=PAPER_TABLE5["LSM"]["M0"])


def sweep_table(report: Report, swept: dict[Cell, dict[str, Any]]) -> None:
    """The LSM over the sweep, one row per cell and regression start (the whole record and
    each scoring's Table 5 window), with the law on the same samples."""
    rows: list[list[Any]] = []
    for c, sc in swept.items():
        for start in sorted({start_of(c, w, t5) for w in LSM_WINDOWS for _, t5 in SCORINGS}):
            back, central = errors(sc, start), errors(sc, start, "central")
            fit = [None] * 4 if back is None or central is None else [
                *(float(v) for v in back.mean(axis=0)), *(float(v) for v in central.mean(axis=0))]
            rows.append([c.amplitude, c.frequency, c.theta0, c.seconds,
                         "whole" if start == 0.0 else say("{t:g}", t=start), *fit[:2],
                         bias_law(sc, start), sc["rate_ms"][start], *fit[2:]])
    paper = ["", "", "", "", "paper", PAPER_TABLE5["LSM"]["mu"], PAPER_TABLE5["LSM"]["M0"], "",
             "", "", ""]
    report.add_table(
        "The LSM (Table 5) over the sweep, by regression window",
        ["A (N)", "f (Hz)", "θ₀", "T (s)", "LSM from (s)", "μ", "M0", "M0 law", "E[θ̇²]",
         "μ central", "M0 central"], [paper, *rows],
        setup=say("as the table above; the LSM regresses the whole record or only the samples "
                  "from a Table 5 start on (the reading ·window); its mean errors with backward "
                  "differences (μ, M0), the errors-in-variables law for M0 on the same samples "
                  "(E[θ̇²] in rad²/s²), and the mean errors with central differences"))
