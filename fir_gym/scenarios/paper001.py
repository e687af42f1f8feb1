"""Paper 001: performance bounds of the continuous optimal FIR filter (Table 1).

The aircraft-carrier model of §V (Sidar & Doolin): ``ẋ = [[0, 1], [−0.36, −0.06 + Δ22]] x
+ [0.6, −0.036]ᵀ w``, ``z = [1 + Δc, 0] x + v``, ``q = 0.035``, ``v = 1``; noise
uncertainty ``|Δq| ≤ 0.01``, ``|Δv| ≤ 0.1`` (Δπ₁, Theorem 3.1) and model uncertainty
``|Δ22| ≤ 0.006``, ``|Δc| ≤ 0.1`` (Δπ₂, Theorem 4.1), evaluated "with the upper
bounds substituted" — here on every corner of each box, reporting the largest.

Which system is true and which nominal is ambiguous. ``nominal="perturbed"``
(default): the data come from the paper's values and the filter is designed
with the perturbed ones (§II's ``A_M = A + ΔA``); this reading reproduces Table 1's
Δπ₁ at T = 1. ``nominal="paper"``: the filter uses the paper's values and the
truth is perturbed (§V's model writes the Δ into the plant).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fir_gym.envs.carrier_motion import PAPER_A21, PAPER_A22, PAPER_NOISE_INPUT, carrier_continuous
from fir_gym.estimators._validation import one_of
from fir_gym.estimators.bounds import corners, delta_pi1, delta_pi2, worst_case
from fir_gym.estimators.continuous import ContinuousModel
from fir_gym.estimators.continuous_fir import fir_riccati, kalman_bucy

from .report import Report
from .runner import SERIAL, Runner

#: Table 1 of paper 001: columns FIR T = 1, 5, 7 and the Kalman filter
PAPER_TABLE1 = {"dpi1": (0.0013, 0.0031, 0.0081, 0.0173),
                "dpi2": (0.0143, 0.0250, 0.0369, 0.0480)}
HORIZONS: tuple[float | None, ...] = (1.0, 5.0, 7.0, None)   # None: steady-state Kalman–Bucy
NOISE_BOX = {"dq": 0.01, "dv": 0.1}
MODEL_BOX = {"delta22": 0.006, "delta_c": 0.1}
PAPER_VALUES = {"q": 0.035, "v": 1.0}
NOMINAL_READINGS = ("perturbed", "paper")
#: further horizons (full run only) for the bounds-vs-T figure
CURVE_HORIZONS: tuple[float, ...] = (0.5, 2.0, 3.0, 10.0)


def carrier_model(corner: Mapping[str, float] | None = None) -> ContinuousModel:
    """The carrier of §V with the paper's values plus the uncertainties in ``corner``.

    ``corner`` may hold ``dq``, ``dv`` (noise) and ``delta22``, ``delta_c`` (model).
    """
    c = dict(corner or {})
    params = {"a21": PAPER_A21, "a22": PAPER_A22, "noise_input": PAPER_NOISE_INPUT,
              "delta22": c.get("delta22", 0.0), "delta_c": c.get("delta_c", 0.0)}
    A, G, C = carrier_continuous(params)
    return ContinuousModel.linear(A=A, C=C, G=G, Q=PAPER_VALUES["q"] + c.get("dq", 0.0),
                                  R=PAPER_VALUES["v"] + c.get("dv", 0.0), dt=0.1,
                                  name="carrier")


def pair(corner: Mapping[str, float], nominal: str = "perturbed"
         ) -> tuple[ContinuousModel, ContinuousModel]:
    """``(true, nominal)`` systems for an uncertainty ``corner`` under a reading."""
    one_of("nominal", nominal, NOMINAL_READINGS)
    paper, perturbed = carrier_model(), carrier_model(corner)
    return (paper, perturbed) if nominal == "perturbed" else (perturbed, paper)


def _max_over(box: Mapping[str, float], fn: Any) -> tuple[float, dict[str, float]]:
    vals = [(fn(c), c) for c in corners(box)]
    value, corner = max(vals, key=lambda vc: vc[0])
    return float(value), corner


def _label(h: float | None) -> str:
    return "Kalman" if h is None else f"FIR T={h:g}"


def column(task: tuple[float | None, str, int | None]) -> dict[str, Any]:
    """Every quantity of Table 1's column for horizon ``h`` (None: Kalman–Bucy); a runner task.

    ``task = (h, nominal, steps)``; deterministic (no randomness).
    """
    h, nominal, steps = task
    other = "paper" if nominal == "perturbed" else "perturbed"
    pi1 = {tuple(c.items()): delta_pi1(*pair(c, nominal), h, steps) for c in corners(NOISE_BOX)}
    out: dict[str, Any] = {}
    out["dpi1"], out["dpi1_corner"] = _max_over(
        NOISE_BOX, lambda c: pi1[tuple(c.items())].paper)
    out["lemma1"] = _max_over(NOISE_BOX, lambda c: pi1[tuple(c.items())].lemma1)[0]
    out["dpi1_other"] = _max_over(
        NOISE_BOX, lambda c: delta_pi1(*pair(c, other), h, steps).paper)[0]
    out["exact1"] = worst_case(lambda c: pair(c, nominal), NOISE_BOX, h, steps).value
    out["dpi2"], out["dpi2_corner"] = _max_over(
        MODEL_BOX, lambda c: delta_pi2(*pair(c, nominal), h, steps).value)
    wc = worst_case(lambda c: pair(c, nominal), MODEL_BOX, h, steps)
    out["exact2"], out["exact2_corner"] = wc.value, wc.corner
    paper_sys = carrier_model()
    out["trR"] = float(np.trace(kalman_bucy(paper_sys) if h is None
                                else fir_riccati(paper_sys, h, steps).R[-1]))
    return out


def run(seed: int = 0, quick: bool = False, runs: int | None = None, runner: Runner | None = None,
        nominal: str = "perturbed") -> Report:
    """Table 1 recomputed; ``quick`` uses coarser grids (100 steps per window). No randomness.

    ``seed`` and ``runs`` are accepted for a uniform scenario interface; the table is
    deterministic. The runner computes one column (horizon) per task; the full run
    adds the horizons of :data:`CURVE_HORIZONS` for the bounds-vs-T figure.
    """
    runner = runner or SERIAL
    steps = 100 if quick else None
    other = "paper" if nominal == "perturbed" else "perturbed"
    extra = () if quick else CURVE_HORIZONS
    cols = runner.map(column, [(h, nominal, steps) for h in HORIZONS + extra],
                      desc="paper 001 columns")
    res: dict[str, Any] = {k: [c[k] for c in cols[:len(HORIZONS)]] for k in cols[0]}
    curve = sorted(((h, c) for h, c in zip(HORIZONS + extra, cols, strict=True) if h is not None),
                   key=lambda hc: hc[0])
    res["curve"] = {"T": [h for h, _ in curve],
                    **{k: [c[k] for _, c in curve] for k in ("dpi1", "lemma1", "exact1", "dpi2",
                                                             "exact2", "trR")}}
    p1, p2 = PAPER_TABLE1["dpi1"], PAPER_TABLE1["dpi2"]
    rows = [
        ["Δπ₁ paper (Table 1)", *p1, ""],
        ["Δπ₁ ours: eq 3.2, max over noise corners", *res["dpi1"], "[2][3]"],
        [f"Δπ₁ ours, other reading (nominal={other})", *res["dpi1_other"], "[1]"],
        ["Δπ₁ valid bound via Lemma 1 (1.5)", *res["lemma1"], "[4]"],
        ["exact worst-corner tr(R_r − R), noise", *res["exact1"], "[3]"],
        ["Δπ₂ paper (Table 1)", *p2, ""],
        ["Δπ₂ ours: reconstructed (valid), max over model corners", *res["dpi2"], "[5]"],
        ["exact worst-corner tr(R_r − R), model", *res["exact2"], "[6]"],
        ["tr R (optimal filter, paper's values)", *res["trR"], "[6]"],
    ]
    c1 = res["dpi1_corner"][0]
    sig2 = [f"{v:.2g}" for v in (res["dpi1"][0], res["dpi1_other"][0])]
    kalman1, kalman2 = res["exact1"][-1], res["exact2"][-1]
    worse = [_label(h) for h, e1, e2 in
             zip(HORIZONS[:-1], res["exact1"][:-1], res["exact2"][:-1], strict=True)
             if e1 >= kalman1 or e2 >= kalman2]
    described = ("the data come from the paper's values and the filter uses the perturbed ones"
                 if nominal == "perturbed" else
                 "the filter uses the paper's values and the truth is perturbed")
    exact_here = nominal == "perturbed"      # true V = 1: eq 3.2 = tr(R_r − R)
    valid2 = all(b >= e for b, e in zip(res["dpi2"], res["exact2"], strict=True))
    notes = [
        f"Reading nominal={nominal!r}: {described}. At T = 1 the two readings give "
        f"{res['dpi1'][0]:.5f} and {res['dpi1_other'][0]:.5f} ({sig2[0]} and {sig2[1]} to two "
        "significant figures), so Table 1's 0.0013 does not decide between them; in the "
        "'perturbed' reading (true V = 1) eq 3.2 is the exact tr(R_r − R).",
        f"T = 1: {res['dpi1'][0]:.5f} (corner Δq = {c1['dq']:+g}, Δv = {c1['dv']:+g}, the "
        f"largest of the four corners) against the paper's 0.0013.",
        ("With one output and true V = 1 the integrand of eq 3.2 has rank one, so eq 3.2 "
         "equals tr(R_r − R) exactly (rows 2 and 5 agree; the tests check R_r against "
         "Theorem 2.1's ODEs and a Monte Carlo). " if exact_here else
         "With one output the integrand of eq 3.2 has rank one, so eq 3.2 is the trace of "
         "∫Φ_F ΔK ΔKᵀ Φ_Fᵀ; here the true V ≠ 1 and the exact tr(R_r − R) (row 5) weighs it "
         "with V. ")
        + f"The paper's larger T = 5, 7 and Kalman entries ({p1[1]}, {p1[2]}, {p1[3]}) are "
        "not eq 3.2 with the actual ΔK under either reading; the text allows a norm bound on "
        "ΔK (Patel and Toda) instead, which it does not give, so the difference cannot be "
        "resolved from the paper.",
        "Eq 3.2 with the Frobenius norm is not an upper bound in general (‖X‖_F ≤ tr X for "
        "PSD X: with several outputs it falls below tr(R_r − R)); Lemma 1 gives the valid "
        "∫‖Φ_FᵀΦ_F‖ ‖ΔK V ΔKᵀ‖ dτ shown here.",
        "Theorem 4.1 is garbled; the reconstruction (estimators/bounds.py, delta_pi2) closes "
        "the paper's integral inequalities by small-gain arguments and is a valid bound ("
        + ("it exceeds the exact row below" if valid2 else "BUT IT FALLS BELOW THE EXACT ROW")
        + "). Its values are not the paper's, which the printed "
        "equations do not determine; compare the pattern across T and with the Kalman filter.",
        "Exact degradation, worst corner: "
        + (f"for {', '.join(worse)} the FIR filter's tr(R_r − R) is not smaller than the "
           "Kalman filter's (noise or model box), so the paper's robustness ranking is a "
           "property of its bounds rather than of the actual errors. "
           if worse else "every FIR horizon degrades less than the Kalman filter. ")
        + "The FIR filter's own tr R is larger (last row).",
    ]
    report = Report(paper="001", title="Performance bounds of the continuous optimal FIR "
                    f"filter under model uncertainty (nominal={nominal!r})",
                    notes=[f"[{i}] {note}" for i, note in enumerate(notes, 1)], figures=res)
    _compare(report, res, nominal, other)
    report.add_table("Table 1: allowable bounds (ours beside the paper's)",
                     ["quantity", *[_label(h) for h in HORIZONS], "note"], rows)
    return report


def _compare(report: Report, res: dict[str, Any], nominal: str, other: str) -> None:
    """One summary row per entry of Table 1, with the reading and the reason for a difference."""
    for i, h in enumerate(HORIZONS):
        paper, ours = PAPER_TABLE1["dpi1"][i], res["dpi1"][i]
        if float(f"{ours:.2g}") == paper:
            note = "reproduced to two significant figures"
        else:
            note = (f"not eq 3.2 with the actual ΔK under either reading ({nominal}: {ours:.2g}, "
                    f"{other}: {res['dpi1_other'][i]:.2g}); the text allows a norm bound on ΔK "
                    "it does not give [3]")
        report.compare(f"Table 1: Δπ₁, {_label(h)}", paper, ours,
                       f"nominal={nominal!r}; eq 3.2 as printed (Frobenius norm), largest over "
                       "the corners Δq = ±0.01, Δv = ±0.1",
                       f"{note}; exact tr(R_r − R) = {res['exact1'][i]:.2g}")
    for i, h in enumerate(HORIZONS):
        report.compare(f"Table 1: Δπ₂, {_label(h)}", PAPER_TABLE1["dpi2"][i], res["dpi2"][i],
                       f"nominal={nominal!r}; Theorem 4.1 reconstructed (a valid bound), largest "
                       "over the corners Δ22 = ±0.006, Δc = ±0.1",
                       "Theorem 4.1 is garbled: the printed equations do not determine the "
                       "paper's value [5]; exact worst-corner tr(R_r − R) = "
                       f"{res['exact2'][i]:.2g}")


def plot(report: Report, out_dir: str | Path) -> None:
    """The bounds and the exact degradations against the horizon T, with Table 1's entries."""
    from ._plotting import new_figure, save

    res = report.figures
    c = res["curve"]
    fig, ax = new_figure(1, 2, width=11.0, height=4.0)
    for a, key, label, exact, bound in (
            (ax[0], "dpi1", "Δπ₁ (noise uncertainty)", "exact1", "lemma1"),
            (ax[1], "dpi2", "Δπ₂ (model uncertainty)", None, None)):
        a.semilogy(c["T"], c[key], "o-", color="C0", label=f"{label}: ours")
        if bound:
            a.semilogy(c["T"], c[bound], "s--", color="C2", label="valid bound via Lemma 1")
        ex = exact or "exact2"
        a.semilogy(c["T"], c[ex], "^:", color="C1", label="exact worst-corner tr(R_r − R)")
        paper = PAPER_TABLE1[key]
        a.semilogy([h for h in HORIZONS if h is not None], paper[:-1], "kx", ms=9,
                   label="paper, Table 1")
        a.axhline(paper[-1], color="k", ls="--", lw=0.8, label="paper, Kalman")
        a.axhline(res[key][-1], color="C0", ls="--", lw=0.8, label="ours, Kalman")
        a.axhline(res[ex][-1], color="C1", ls=":", lw=0.8, label="exact, Kalman")
        a.set_xlabel("FIR horizon T (s)")
        a.set_title(f"Paper 001: {label}", fontsize=9)
        a.legend(fontsize=6)
    save(report, out_dir, "bounds_vs_T", fig, "Paper 001: bounds and exact degradation vs T")
