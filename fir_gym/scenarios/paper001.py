"""Paper 001: performance bounds of the continuous optimal FIR filter (Table 1, §V's claims).

The aircraft-carrier model of §V (Sidar & Doolin): ``ẋ = [[0, 1], [−0.36, −0.06 + Δ22]] x
+ [0.6, −0.036]ᵀ w``, ``z = [1 + Δc, 0] x + v``, ``q = 0.035``, ``v = 1``; noise
uncertainty ``|Δq| ≤ 0.01``, ``|Δv| ≤ 0.1`` (Δπ₁, Theorem 3.1) and model uncertainty
``|Δ22| ≤ 0.006``, ``|Δc| ≤ 0.1`` (Δπ₂, Theorem 4.1), evaluated "with the upper
bounds substituted" — here on every corner of each box, reporting the largest.

Two ambiguities, both run (:data:`READINGS`; docs/papers.md#001-true-vs-nominal and
docs/papers.md#001-eq-3-3-transition):

* which system is true: ``"perturbed"`` — the data come from the paper's values and
  the filter is designed with the perturbed ones (§II's ``A_M = A + ΔA``);
  ``"paper"`` — the filter uses the paper's values and the truth is perturbed (§V
  writes the Δ into the plant);
* which transition eq 3.2 integrates: ``Φ_F(T, τ)`` (eq 3.7, the derivation) or
  ``Φ_F(τ, 0)`` (eq 3.3 as printed, integrated from the window start;
  :func:`~fir_gym.estimators.bounds.delta_pi1_from_start`).

Beside the bounds: the exact worst-corner degradation ``tr(R_r − R)`` and the
valid Lemma-1 bound; and §V's two claims (the FIR bounds are below the Kalman
filter's; the FIR filter is the more robust) tested on every reading.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fir_gym.envs.carrier_motion import PAPER_A21, PAPER_A22, PAPER_NOISE_INPUT, carrier_continuous
from fir_gym.estimators._validation import one_of
from fir_gym.estimators.bounds import (
    corners,
    delta_pi1,
    delta_pi1_from_start,
    delta_pi2,
    worst_case,
)
from fir_gym.estimators.continuous import ContinuousModel
from fir_gym.estimators.continuous_fir import STEPS_PER_SECOND, fir_riccati, kalman_bucy

from .plan import Stage, Task, run_plan
from .prose import Printed, join, say
from .report import Report, claim, number_verdict
from .runner import Runner

#: Table 1 of paper 001 as printed: columns FIR T = 1, 5, 7 and the Kalman filter
PAPER_TABLE1 = {"dpi1": tuple(map(Printed, ("0.0013", "0.0031", "0.0081", "0.0173"))),
                "dpi2": tuple(map(Printed, ("0.0143", "0.0250", "0.0369", "0.0480")))}
HORIZONS: tuple[float | None, ...] = (1.0, 5.0, 7.0, None)   # None: steady-state Kalman–Bucy
NOISE_BOX = {"dq": 0.01, "dv": 0.1}
MODEL_BOX = {"delta22": 0.006, "delta_c": 0.1}
PAPER_VALUES = {"q": 0.035, "v": 1.0}
NOMINAL_READINGS = ("perturbed", "paper")
TRANSITIONS = ("end", "start")
#: reading codes of the summary: (nominal, transition) -> code; the first is the default
READINGS = {("perturbed", "end"): "pert·Φ(T,τ)", ("perturbed", "start"): "pert·Φ(τ,0)",
            ("paper", "end"): "paper·Φ(T,τ)", ("paper", "start"): "paper·Φ(τ,0)"}
DEFAULT = ("perturbed", "end")
#: further horizons (full run only, default reading) for the bounds-vs-T figure
CURVE_HORIZONS: tuple[float, ...] = (0.5, 2.0, 3.0, 10.0)
PARTS = ("noise", "model")
QUICK_STEPS = 100


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


def _largest(box: Mapping[str, float], fn: Any) -> tuple[float, dict[str, float]]:
    vals = [(float(fn(c)), c) for c in corners(box)]
    return max(vals, key=lambda vc: vc[0])


def column(task: tuple[float | None, str, str, int | None]) -> dict[str, Any]:
    """One part of Table 1's column for horizon ``h`` (None: Kalman–Bucy); a runner task.

    ``task = (h, nominal, part, steps)``: ``part="noise"`` gives Δπ₁ under both
    transitions, the Lemma-1 bound, the exact noise-box degradation and ``tr R``;
    ``"model"`` gives Δπ₂ and the exact model-box degradation. Deterministic.
    """
    h, nominal, part, steps = task
    one_of("part", part, PARTS)
    out: dict[str, Any] = {}
    if part == "noise":
        pi1 = {tuple(c.items()): delta_pi1(*pair(c, nominal), h, steps) for c in corners(NOISE_BOX)}
        out["dpi1_end"], out["corner_end"] = _largest(NOISE_BOX,
                                                      lambda c: pi1[tuple(c.items())].paper)
        out["dpi1_start"], out["corner_start"] = _largest(
            NOISE_BOX, lambda c: delta_pi1_from_start(*pair(c, nominal), h, steps))
        out["lemma1"] = _largest(NOISE_BOX, lambda c: pi1[tuple(c.items())].lemma1)[0]
        wc = worst_case(lambda c: pair(c, nominal), NOISE_BOX, h, steps)
        out["exact1"], out["exact1_corner"] = wc.value, wc.corner
        paper_sys = carrier_model()
        out["trR"] = float(np.trace(kalman_bucy(paper_sys) if h is None
                                    else fir_riccati(paper_sys, h, steps).R[-1]))
    else:
        out["dpi2"], out["dpi2_corner"] = _largest(
            MODEL_BOX, lambda c: delta_pi2(*pair(c, nominal), h, steps).value)
        wc = worst_case(lambda c: pair(c, nominal), MODEL_BOX, h, steps)
        out["exact2"], out["exact2_corner"] = wc.value, wc.corner
    return out


def _cost(h: float | None, part: str, quick: bool) -> float:
    length = 3.0 if h is None else h
    return (0.02 if quick else 0.1) * (1.0 + length) * (1.5 if part == "model" else 1.0)


def plan(seed: int = 0, quick: bool = False, runs: int | None = None) -> Stage:
    """Table 1 under every reading, one task per (horizon, nominal reading, part). No randomness.

    ``seed`` and ``runs`` are accepted for a uniform scenario interface; ``quick`` uses
    coarse grids (:data:`QUICK_STEPS` per window). The full run adds the horizons of
    :data:`CURVE_HORIZONS` (default reading) for the bounds-vs-T figure.
    """
    steps = QUICK_STEPS if quick else None
    keys = [(h, nom, part) for h in HORIZONS for nom in NOMINAL_READINGS for part in PARTS]
    keys += [] if quick else [(h, DEFAULT[0], part) for h in CURVE_HORIZONS for part in PARTS]
    tasks = [Task(column, (h, nom, part, steps), _cost(h, part, quick)) for h, nom, part in keys]

    def then(results: list[dict[str, Any]]) -> Report:
        merged: dict[tuple[float | None, str], dict[str, Any]] = {}
        for (h, nom, _), res in zip(keys, results, strict=True):
            merged.setdefault((h, nom), {}).update(res)
        return _assemble(merged, quick)

    return Stage(tasks, then, desc="paper 001")


def run(seed: int = 0, quick: bool = False, runs: int | None = None,
        runner: Runner | None = None) -> Report:
    """Table 1 recomputed under every reading (:func:`plan` on ``runner``)."""
    return run_plan(plan(seed, quick, runs), runner)


def _label(h: float | None) -> str:
    return "Kalman" if h is None else say("FIR T={h:g}", h=h)


def _values(res: dict[tuple[float | None, str], dict[str, Any]], key: str, nominal: str
            ) -> list[float]:
    return [res[(h, nominal)][key] for h in HORIZONS]


def _assemble(res: dict[tuple[float | None, str], dict[str, Any]], quick: bool) -> Report:
    report = Report("001", "Performance bounds of the continuous optimal FIR filter under model "
                    "uncertainty")
    grid = say("{n} grid steps per window", n=QUICK_STEPS) if quick else say(
        "{n} grid steps per second of window", n=STEPS_PER_SECOND)
    setup = say("§V's carrier, q = {q:g}, v = {v:g}; noise box |Δq| ≤ {dq}, |Δv| ≤ {dv}; model box "
                "|Δ22| ≤ {d22}, |Δc| ≤ {dc}; the largest value over the box's corners; {grid}",
                q=PAPER_VALUES["q"], v=PAPER_VALUES["v"], dq=NOISE_BOX["dq"], dv=NOISE_BOX["dv"],
                d22=MODEL_BOX["delta22"], dc=MODEL_BOX["delta_c"], grid=grid)
    legend = {
        "pert": "data from the paper's values, filter designed with the perturbed ones",
        "paper": "filter designed with the paper's values, data from the perturbed system",
        "Φ(T,τ)": "eq 3.2 integrates the transition to the window's end (eq 3.7)",
        "Φ(τ,0)": "eq 3.2 integrates the transition from the window start (eq 3.3 as printed)",
    }

    s1 = report.summary("Table 1, Δπ₁ (noise uncertainty, Theorem 3.1)", setup, legend)
    for i, h in enumerate(HORIZONS):
        for (nom, trans), code in READINGS.items():
            if h is None and trans == "start":
                continue                         # both transitions are e^{F τ} at steady state
            r = res[(h, nom)]
            ours = r[f"dpi1_{trans}"]
            name = code if h is not None else code.split("·")[0]
            verdict = number_verdict(PAPER_TABLE1["dpi1"][i], ours, otherwise="ambiguous",
                                     reading=None if (nom, trans) == DEFAULT else name)
            s1.compare(say("Δπ₁, {col}", col=_label(h)), PAPER_TABLE1["dpi1"][i], ours, name,
                       verdict, _dpi1_note(r, nom, trans, h))
    s2 = report.summary("Table 1, Δπ₂ (model uncertainty, Theorem 4.1)", setup,
                        {k: legend[k] for k in ("pert", "paper")})
    for i, h in enumerate(HORIZONS):
        for nom in NOMINAL_READINGS:
            r = res[(h, nom)]
            code = READINGS[(nom, "end")].split("·")[0]
            s2.compare(say("Δπ₂, {col}", col=_label(h)), PAPER_TABLE1["dpi2"][i], r["dpi2"], code,
                       number_verdict(PAPER_TABLE1["dpi2"][i], r["dpi2"], otherwise="ambiguous",
                                      reading=None if nom == DEFAULT[0] else code),
                       say("Theorem 4.1 is garbled in print: our reconstruction is a valid bound "
                           "(exact worst-corner tr(R_r − R) = {e:.2g}); the printed equations do "
                           "not determine the paper's value", e=r["exact2"]))
    _claims(report, res, setup, legend)
    _tables(report, res, quick)
    _notes(report, res)
    return report


def _dpi1_note(r: dict[str, Any], nominal: str, transition: str, h: float | None) -> str:
    if transition == "start":
        return say("eq 3.2 with Φ_F(τ, 0), which is not a bound (exact tr(R_r − R) = {e:.2g}); "
                   "worst corner Δq = {dq:+g}, Δv = {dv:+g}", e=r["exact1"],
                   dq=r["corner_start"]["dq"], dv=r["corner_start"]["dv"])
    if nominal == "perturbed":
        return say("with one output and true V = {v:g} eq 3.2 is the exact tr(R_r − R) "
                   "(= {e:.2g}); the text allows a norm bound on ΔK (Patel and Toda) that it "
                   "does not give", v=PAPER_VALUES["v"], e=r["exact1"])
    return say("true V ≠ {v:g}: eq 3.2 is the trace of ∫Φ_F ΔK ΔKᵀ Φ_Fᵀ, not tr(R_r − R) = "
               "{e:.2g}; the text allows a norm bound on ΔK that it does not give",
               v=PAPER_VALUES["v"], e=r["exact1"])


def _ratios(vals: list[float]) -> str:
    return join([say("{r:.2f}", r=v / vals[-1]) for v in vals[:-1]], " / ")


def _claims(report: Report, res: dict[tuple[float | None, str], dict[str, Any]],
            setup: str, legend: dict[str, str]) -> None:
    s = report.summary("§V's claims: the FIR filter against the Kalman filter", setup, legend)
    cols = join([_label(h) for h in HORIZONS[:-1]], " / ")
    paper1 = [float(v) for v in PAPER_TABLE1["dpi1"]]
    paper2 = [float(v) for v in PAPER_TABLE1["dpi2"]]
    for key, vals in (("Δπ₁", paper1), ("Δπ₂", paper2)):
        s.compare(say("{q} of every FIR T below the Kalman filter's (Table 1 as printed)", q=key),
                  "claim (Table 1)", _ratios(vals), "paper's numbers",
                  claim(all(v < vals[-1] for v in vals[:-1])),
                  say("FIR ÷ Kalman for {cols}", cols=cols))
    for (nom, trans), code in READINGS.items():
        vals = [res[(h, nom)]["dpi1_" + (trans if h is not None else "end")] for h in HORIZONS]
        s.compare("Δπ₁ of every FIR T below the Kalman filter's", "claim (Table 1)",
                  _ratios(vals), code, claim(all(v < vals[-1] for v in vals[:-1])),
                  say("FIR ÷ Kalman for {cols}", cols=cols))
    for nom in NOMINAL_READINGS:
        code = READINGS[(nom, "end")].split("·")[0]
        vals = _values(res, "dpi2", nom)
        s.compare("Δπ₂ of every FIR T below the Kalman filter's", "claim (Table 1)",
                  _ratios(vals), code, claim(all(v < vals[-1] for v in vals[:-1])),
                  say("FIR ÷ Kalman for {cols}", cols=cols))
    for key, box in (("exact1", "noise"), ("exact2", "model")):
        for nom in NOMINAL_READINGS:
            code = READINGS[(nom, "end")].split("·")[0]
            vals = _values(res, key, nom)
            s.compare(say("FIR more robust: exact {box}-box tr(R_r − R) below the Kalman "
                          "filter's", box=box),
                      "claim (text)", _ratios(vals), code,
                      claim(all(v < vals[-1] for v in vals[:-1])),
                      say("FIR ÷ Kalman for {cols}; the exact worst-corner degradation (§V "
                          "concludes from its bounds that the FIR filter is the more robust)",
                          cols=cols))


def _tables(report: Report, res: dict[tuple[float | None, str], dict[str, Any]],
            quick: bool) -> None:
    rows: list[list[Any]] = [["Δπ₁ paper (Table 1)", "", *PAPER_TABLE1["dpi1"]]]
    for (nom, trans), code in READINGS.items():
        rows.append(["Δπ₁ eq 3.2", code,
                     *[res[(h, nom)][f"dpi1_{trans if h is not None else 'end'}"]
                       for h in HORIZONS]])
    for nom in NOMINAL_READINGS:
        code = READINGS[(nom, "end")].split("·")[0]
        rows += [["Δπ₁ valid bound (Lemma 1)", code, *_values(res, "lemma1", nom)],
                 ["exact tr(R_r − R), noise box", code, *_values(res, "exact1", nom)]]
    rows.append(["Δπ₂ paper (Table 1)", "", *PAPER_TABLE1["dpi2"]])
    for nom in NOMINAL_READINGS:
        code = READINGS[(nom, "end")].split("·")[0]
        rows += [["Δπ₂ reconstructed (valid bound)", code, *_values(res, "dpi2", nom)],
                 ["exact tr(R_r − R), model box", code, *_values(res, "exact2", nom)]]
    rows.append(["tr R (optimal filter, paper's values)", "",
                 *_values(res, "trR", NOMINAL_READINGS[0])])
    report.add_table("Table 1 under every reading", ["quantity", "reading",
                                                     *[_label(h) for h in HORIZONS]], rows,
                     setup=say("largest over the box's corners; readings as in the summaries{q}",
                               q=say(" (coarse {n}-step grids)", n=QUICK_STEPS) if quick else ""))
    curve = sorted(h for h, nom in res if h is not None and nom == DEFAULT[0])
    report.figures.update({
        "res": res, "readings": READINGS,
        "curve": {"T": curve, **{k: [res[(h, DEFAULT[0])][k] for h in curve]
                                 for k in ("dpi1_end", "dpi1_start", "lemma1", "exact1", "dpi2",
                                           "exact2", "trR")}},
        "kalman": res[(None, DEFAULT[0])],
    })


def _notes(report: Report, res: dict[tuple[float | None, str], dict[str, Any]]) -> None:
    r1 = res[(HORIZONS[0], "perturbed")]
    matches = [(code, _label(h)) for i, h in enumerate(HORIZONS)
               for (nom, trans), code in READINGS.items()
               if number_verdict(PAPER_TABLE1["dpi1"][i], res[(h, nom)][
                   "dpi1_" + (trans if h is not None else "end")]).startswith("reproduced")]
    by_reading = {code: [col for c, col in matches if c == code] for code in READINGS.values()}
    which = join([say("{code} at {cols}", code=c, cols=join(cols, ", "))
                  for c, cols in by_reading.items() if cols], "; ")
    most = max(len(cols) for cols in by_reading.values())
    valid2 = all(res[k]["dpi2"] >= res[k]["exact2"] for k in res)
    report.notes += [
        say("Δπ₁ entries reproduced to the paper's two figures: {which}. {single}; at T = {h:g} "
            "(default reading) the worst corner is Δq = {dq:+g}, Δv = {dv:+g}.",
            which=which or "none", h=HORIZONS[0], dq=r1["corner_end"]["dq"],
            dv=r1["corner_end"]["dv"],
            single=say("No reading gives more than {n} of the {m} entries", n=most, m=len(HORIZONS))
            if most < len(HORIZONS) else "One reading gives every entry"),
        "Eq 3.2 with the Frobenius norm is not an upper bound in general (for PSD X, ‖X‖_F ≤ tr "
        "X: with several outputs it falls below tr(R_r − R)); Lemma 1 (eq 1.5) gives the valid "
        "∫‖Φ_FᵀΦ_F‖ ‖ΔK V ΔKᵀ‖ dτ of the detail table.",
        say("Theorem 4.1 is garbled; the reconstruction (estimators/bounds.py, delta_pi2) closes "
            "its integral inequalities by small-gain arguments. It {valid} the exact "
            "worst-corner degradation under every reading and horizon.",
            valid="exceeds" if valid2 else "does NOT everywhere exceed"),
    ]


def plot(report: Report, out_dir: str | Path) -> None:
    """The bounds and the exact degradations against the horizon T, with Table 1's entries."""
    from ._plotting import MARKERS, coincidence_note, coincident, legend_outside, new_figure, save

    c, kal = report.figures["curve"], report.figures["kalman"]
    fig, ax = new_figure(1, 2, width=11.0, height=4.0)
    finite = [h for h in HORIZONS if h is not None]
    for a, key, label, exact, bound in (
            (ax[0], "dpi1", "Δπ₁ (noise uncertainty)", "exact1", "lemma1"),
            (ax[1], "dpi2", "Δπ₂ (model uncertainty)", "exact2", None)):
        ours = "dpi1_end" if key == "dpi1" else key
        # (curve, marker and line style, colour, label); a curve hidden under an earlier one
        # is named as such in the legend and drawn with a smaller marker on top
        curves = [(c[ours], "o-", "C0", "ours (pert, Φ(T,τ))")]
        if key == "dpi1":
            curves.append((c["dpi1_start"], "d-.", "C4", "ours, Φ(τ,0) reading"))
        if bound:
            curves.append((c[bound], "s--", "C2", "valid bound via Lemma 1"))
        curves.append((c[exact], "^:", "C1", "exact worst-corner tr(R_r − R)"))
        same = coincident({name: values for values, _, _, name in curves})
        for j, (values, style, colour, name) in enumerate(curves):
            size = 4.0 if name in same else 6.0
            marker = MARKERS[j] if name in same else style[0]
            a.semilogy(c["T"], values, marker + style[1:], ms=size, color=colour,
                       label=coincidence_note(name, same))
        paper = [float(v) for v in PAPER_TABLE1[key]]
        a.semilogy(finite, paper[:-1], "kx", ms=9, label="paper, Table 1")
        levels = {"paper, Kalman": paper[-1], "ours, Kalman": kal[ours],
                  "exact, Kalman": kal[exact]}
        same = coincident({name: [value] for name, value in levels.items()})
        for (name, value), colour, ls in zip(levels.items(), ("k", "C0", "C1"),
                                             ("--", "--", ":"), strict=True):
            a.axhline(value, color=colour, ls=ls, lw=0.8, label=coincidence_note(name, same))
        a.set_xlabel("FIR horizon T (s)")
        a.set_ylabel(f"{label.split()[0]}: increase of the error\ncovariance trace (state units²)")
        a.set_title(f"Paper 001: {label}", fontsize=9)
        legend_outside(a, below=True, ncol=2)
    save(report, out_dir, "bounds_vs_T", fig, "Paper 001: bounds and exact degradation vs T")
