"""The benchmark's questions, answered from its numbers (every sentence computed).

Per plant, at each condition's middle strength (the cells of :mod:`.tables`):

1. **Does the FIR family's open-loop robustness carry into the closed loop?** The best
   FIR-family estimate (``fir``, ``efir``, ``ufir``, ``rfir``; plain or gated) against the
   best Kalman-family one (``kf``, ``ekf``, ``ukf``, ``lkf``, ``cd-ekf``, ``bpf-kf``) — by
   estimation error (the geometric mean over states of the RMSE) and by the LQG's return
   on it (the paired bootstrap difference of the two families' best returns).
2. **When is a better estimate not a better control?** The cells where the LQG row with
   the smallest estimation error is not the one with the best return, with why the data
   show: the plant's own excursion (what the condition costs the LQG on the *true* state,
   relative to its nominal return) against the estimation gaps.
3. **Does memory (stack, recurrent) or domain randomisation beat a filter?** In the
   learned grid: the best filter-fed PPO of the nominal regime against the best memory
   kind of the nominal regime, and the best controller trained with a condition on
   (``dr-…``) against the best nominal-regime one.

Two returns are compared by the 95 % interval of their paired bootstrap difference
(:func:`.tables.paired_difference`): "beats"/"loses to" when it excludes 0, "ties" when it
contains 0, "matches" when the IQMs are within :data:`MATCH` of each other.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .tables import cells, paired_difference

#: IQMs this close (relatively) count as a match
MATCH = 0.01
KALMAN = ("kf", "ekf", "ukf", "lkf", "cd-ekf", "bpf-kf")
FIR = ("fir", "efir", "ufir", "rfir")
MEMORY = ("measurement-stack", "recurrent")


def _base(kind: str) -> str:
    """An estimator's registry name from a row's kind (``lqg-efir+gate`` → ``efir``)."""
    return kind.removeprefix("lqg-").removesuffix("+gate")


def _error(row: dict[str, Any]) -> float:
    """The estimation error of a row: the geometric mean over states of its RMSE."""
    rmse = row.get("rmse")
    if not rmse:
        return math.inf
    values = np.asarray(rmse, dtype=np.float64)
    if not np.all(np.isfinite(values)) or np.any(values <= 0):
        return math.inf
    return float(np.exp(np.mean(np.log(values))))


def _compare(records: Sequence[dict[str, Any]], rows: dict[str, dict[str, Any]], a: str,
             b: str) -> str:
    ra, rb = rows[a], rows[b]
    values = f"{ra['iqm']:.4g} vs {rb['iqm']:.4g}"
    if abs(ra["iqm"] - rb["iqm"]) <= MATCH * max(abs(ra["iqm"]), abs(rb["iqm"])):
        return f"matches ({values})"
    _, low, high = paired_difference(records, a, b)
    interval = f"paired difference [{low:.3g}, {high:.3g}]"
    if low > 0:
        return f"beats ({values}, {interval})"
    if high < 0:
        return f"loses to ({values}, {interval})"
    return f"ties with ({values}, {interval})"


def _middle_cells(report: dict[str, Any], records: Sequence[dict[str, Any]]
                  ) -> list[tuple[str, str, float, list[dict[str, Any]], list[dict[str, Any]]]]:
    """``(env_id, condition, strength, rows, records)`` of each plant's nominal cell and each
    condition's middle strength."""
    grouped = cells(records)
    out = []
    for cell in report["tables"]:
        strengths = report.get("conditions", {}).get(cell["condition"], [0.0])
        middle = strengths[len(strengths) // 2] if strengths else 0.0
        if cell["condition"] != "nominal" and not math.isclose(cell["strength"], middle):
            continue
        key = (cell["env_id"], cell["condition"], float(cell["strength"]))
        out.append((*key, cell["rows"], grouped.get(key, [])))
    return out


def answers(report: dict[str, Any], records: Sequence[dict[str, Any]]) -> list[str]:
    """The three questions, answered per plant (module docstring)."""
    out: list[str] = []
    middle = _middle_cells(report, records)
    for env_id in dict.fromkeys(c[0] for c in middle):
        plant_cells = [c for c in middle if c[0] == env_id]
        name = env_id.split("/")[-1]
        out += [f"{name}: {sentence}" for sentence in
                (_fir_vs_kalman(plant_cells), _estimate_vs_control(plant_cells),
                 _memory_and_randomisation(plant_cells)) if sentence]
    return out


def _label(condition: str, strength: float) -> str:
    return "nominal" if condition == "nominal" else f"{condition} {strength:g}"


def _fir_vs_kalman(plant_cells: list[Any]) -> str:
    parts = []
    better_estimate = better_control = compared = 0
    for _, condition, strength, rows, records in plant_cells:
        by_name = {r["name"]: r for r in rows}
        lqg = [r for r in rows if r["name"].startswith("lqg-") and r["name"] != "lqg-true"]
        fir = [r for r in lqg if _base(r["kind"]) in FIR]
        kalman = [r for r in lqg if _base(r["kind"]) in KALMAN]
        if not fir or not kalman:
            continue
        compared += 1
        f_est, k_est = min(fir, key=_error), min(kalman, key=_error)
        f_ret, k_ret = max(fir, key=lambda r: r["iqm"]), max(kalman, key=lambda r: r["iqm"])
        ratio = _error(f_est) / _error(k_est) if math.isfinite(_error(k_est)) else math.nan
        better_estimate += bool(ratio < 1)
        verdict = _compare(records, by_name, f_ret["name"], k_ret["name"])
        better_control += verdict.startswith("beats")
        parts.append(f"{_label(condition, strength)}: best FIR estimate "
                     f"{f_est['kind'].removeprefix('lqg-')} at {ratio:.2g}× the error of the "
                     f"best Kalman one ({k_est['kind'].removeprefix('lqg-')}); LQG on the best "
                     f"FIR ({f_ret['name']}) {verdict} LQG on the best Kalman ({k_ret['name']})")
    if not compared:
        return ""
    return (f"FIR family against Kalman family, LQG on each — the FIR estimate is the better "
            f"one in {better_estimate} of {compared} settings and its control beats the "
            f"Kalman family's in {better_control}. " + "; ".join(parts) + ".")


def _estimate_vs_control(plant_cells: list[Any]) -> str:
    nominal = next((rows for _, c, _, rows, _ in plant_cells if c == "nominal"), None)
    if nominal is None:
        return ""
    true_nominal = next((r for r in nominal if r["name"] == "lqg-true"), None)
    if true_nominal is None:
        return ""
    parts = []
    mismatched = total = 0
    for _, condition, strength, rows, records in plant_cells:
        by_name = {r["name"]: r for r in rows}
        lqg = [r for r in rows if r["name"].startswith("lqg-") and r["name"] != "lqg-true"
               and math.isfinite(_error(r))]
        if len(lqg) < 2 or "lqg-true" not in by_name:
            continue
        total += 1
        best_estimate = min(lqg, key=_error)
        best_control = max(lqg, key=lambda r: r["iqm"])
        if best_estimate["name"] == best_control["name"]:
            continue
        verdict = _compare(records, by_name, best_estimate["name"], best_control["name"])
        if verdict.startswith("beats"):
            continue
        mismatched += 1
        true_row = by_name["lqg-true"]
        excursion = (true_nominal["iqm"] - true_row["iqm"]) / abs(true_nominal["iqm"] or 1.0)
        gaps = [r["gap"] for r in lqg if r.get("gap") is not None]
        parts.append(
            f"{_label(condition, strength)}: {best_estimate['name']} has the smallest error "
            f"({_error(best_estimate):.3g} against {_error(best_control):.3g}) yet {verdict} "
            f"{best_control['name']}; the condition costs the true-state LQG "
            f"{excursion:+.2f} of its nominal return, while the estimation gaps span "
            f"{min(gaps):.2f} to {max(gaps):.2f}")
    if not total:
        return ""
    head = (f"a smaller estimation error did not give a better LQG return in {mismatched} of "
            f"{total} settings")
    return head + (". " + "; ".join(parts) + "." if parts else ".")


def _memory_and_randomisation(plant_cells: list[Any]) -> str:
    parts = []
    for _, condition, strength, rows, records in plant_cells:
        by_name = {r["name"]: r for r in rows}
        learned = [r for r in rows if r.get("regime")]
        if not learned:
            continue
        nominal = [r for r in learned if r["regime"] == "nominal"]
        filters = [r for r in nominal if r["kind"] not in (*MEMORY, "true", "measurement")]
        memory = [r for r in nominal if r["kind"] in MEMORY]
        randomised = [r for r in learned if r["regime"] != "nominal" and r["kind"] != "true"]
        pieces = []
        best_filter = max(filters, key=lambda r: r["iqm"]) if filters else None
        if best_filter and memory:
            best_memory = max(memory, key=lambda r: r["iqm"])
            pieces.append(f"the best filter-fed PPO ({best_filter['name']}) "
                          f"{_compare(records, by_name, best_filter['name'], best_memory['name'])}"
                          f" the best memory ({best_memory['name']})")
        if randomised and nominal:
            best_dr = max(randomised, key=lambda r: r["iqm"])
            candidates = [r for r in nominal if r["kind"] != "true"]
            if candidates:
                best_nominal = max(candidates, key=lambda r: r["iqm"])
                pieces.append(f"the best domain-randomised controller ({best_dr['name']}) "
                              f"{_compare(records, by_name, best_dr['name'], best_nominal['name'])}"
                              f" the best nominal-trained one ({best_nominal['name']})")
        if pieces:
            parts.append(f"{_label(condition, strength)}: " + "; ".join(pieces))
    if not parts:
        return ""
    return "learned controllers — " + "; ".join(parts) + "."
