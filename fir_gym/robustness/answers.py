"""The benchmark's questions, answered from its numbers (every sentence computed).

Per plant, at each condition's middle strength (the cells of :mod:`.tables`):

1. **Does the FIR family's open-loop robustness carry into the closed loop?** The best
   FIR-family estimate (``fir``, ``efir``, ``ufir``, ``rfir``; plain or gated) against the
   best Kalman-family one (``kf``, ``ekf``, ``ukf``, ``lkf``, ``cd-ekf``, ``bpf-kf``) — by
   estimation error (the geometric mean over states of the RMSE) and by the LQG's return
   on it (the paired bootstrap difference of the two families' best returns) — and, after
   a burst, by recovery time.
2. **When is a better estimate not a better control?** The settings where the LQG with
   the smallest estimation error is not the one with the best return, and why the data
   show: the estimation gap (the share of a controller's cost that knowing the state would
   remove) against what the condition costs the plant itself (the true-state LQG's return
   under the condition against its nominal one).
3. **Does memory (stack, recurrent) or domain randomisation beat a filter?** In the
   learned grid: the best filter-fed PPO of the nominal regime against the best memory
   kind of the nominal regime, and the best controller trained with a condition on
   (``dr-…``) against the best nominal-regime one.

Two returns are compared by the 95 % interval of their paired bootstrap difference
(:func:`.tables.paired_difference`): "beats"/"loses to" when it excludes 0, "ties with"
when it contains 0, "matches" when the IQMs are within :data:`MATCH` of each other.
:func:`answers` gives one short paragraph per plant and question (the README's);
:func:`details` the same per setting (the report's).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .formatting import middle
from .plan import short_name
from .tables import cells, paired_difference

#: IQMs this close (relatively) count as a match
MATCH = 0.01
KALMAN = ("kf", "ekf", "ukf", "lkf", "cd-ekf", "bpf-kf")
FIR = ("fir", "efir", "ufir", "rfir")
MEMORY = ("measurement-stack", "recurrent")

#: one setting of one plant: ``(env_id, condition, strength, rows, records)``
Cell = tuple[str, str, float, list[dict[str, Any]], list[dict[str, Any]]]


def base_estimator(kind: str) -> str:
    """An estimator's registry name from a row's kind (``lqg-efir+gate`` → ``efir``)."""
    return kind.removeprefix("lqg-").removesuffix("+gate")


def error_of(row: dict[str, Any]) -> float:
    """The estimation error of a row: the geometric mean over states of its RMSE (inf for a
    row without one, or with a non-finite or zero one)."""
    rmse = row.get("rmse")
    if not rmse:
        return math.inf
    values = np.asarray(rmse, dtype=np.float64)
    if not np.all(np.isfinite(values)) or np.any(values <= 0):
        return math.inf
    return float(np.exp(np.mean(np.log(values))))


def verdict(records: Sequence[dict[str, Any]], rows: dict[str, dict[str, Any]], a: str,
            b: str) -> str:
    """``a`` against ``b``: "matches", "beats", "loses to" or "ties with", with the numbers."""
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


def middle_cells(report: dict[str, Any], records: Sequence[dict[str, Any]]) -> list[Cell]:
    """Each plant's nominal cell and each condition's cell at its middle strength."""
    grouped = cells(records)
    out = []
    for cell in report["tables"]:
        strengths = report.get("conditions", {}).get(cell["condition"], [0.0])
        if cell["condition"] != "nominal" and not math.isclose(cell["strength"],
                                                               middle(strengths)):
            continue
        key = (cell["env_id"], cell["condition"], float(cell["strength"]))
        out.append((*key, cell["rows"], grouped.get(key, [])))
    return out


def label(condition: str, strength: float) -> str:
    return "nominal" if condition == "nominal" else f"{condition} {strength:g}"


def _lqg(rows: list[dict[str, Any]], family: tuple[str, ...]) -> list[dict[str, Any]]:
    return [r for r in rows if r["name"].startswith("lqg-") and r["name"] != "lqg-true"
            and base_estimator(r["kind"]) in family]


# ---------------------------------------------------------------------------- question 1
def fir_against_kalman(cell: Cell) -> dict[str, Any] | None:
    """Question 1 in one setting: the two families' best estimates and best LQG returns."""
    _, condition, strength, rows, records = cell
    fir, kalman = _lqg(rows, FIR), _lqg(rows, KALMAN)
    if not fir or not kalman:
        return None
    by_name = {r["name"]: r for r in rows}
    f_est, k_est = min(fir, key=error_of), min(kalman, key=error_of)
    f_ret, k_ret = max(fir, key=lambda r: r["iqm"]), max(kalman, key=lambda r: r["iqm"])
    ratio = error_of(f_est) / error_of(k_est) if math.isfinite(error_of(k_est)) else math.nan
    control = verdict(records, by_name, f_ret["name"], k_ret["name"])
    out = {"label": label(condition, strength), "fir_estimate": f_est["name"],
           "kalman_estimate": k_est["name"], "ratio": ratio, "fir_control": f_ret["name"],
           "kalman_control": k_ret["name"], "control": control}
    fir_times = [float(r["recovery"]) for r in fir if r.get("recovery") is not None]
    kalman_times = [float(r["recovery"]) for r in kalman if r.get("recovery") is not None]
    if fir_times and kalman_times:
        out["recovery"] = (min(fir_times), min(kalman_times))
    return out


def _q1(plant_cells: list[Cell]) -> str:
    found = [c for c in (fir_against_kalman(cell) for cell in plant_cells
                         if cell[1] != "nominal") if c]
    if not found:
        return ""
    better = [c["label"] for c in found if c["ratio"] < 1]
    wins = [c["label"] for c in found if c["control"].startswith("beats")]
    losses = [c["label"] for c in found if c["control"].startswith("loses")]
    parts = [f"the FIR family's best estimate has the smaller error in {len(better)} of "
             f"{len(found)} conditions" + (f" ({', '.join(better)})" if better else "")]
    parts.append(f"its LQG beats the Kalman family's in {len(wins)}"
                 + (f" ({', '.join(wins)})" if wins else "")
                 + f", loses in {len(losses)}" + (f" ({', '.join(losses)})" if losses else "")
                 + f" and ties or matches in {len(found) - len(wins) - len(losses)}")
    burst = next((c for c in found if c["label"].startswith("burst") and c.get("recovery")),
                 None)
    if burst is not None:
        fir_steps, kalman_steps = burst["recovery"]
        parts.append(f"after the burst the fastest FIR estimate is back in {fir_steps:.0f} "
                     f"step{'s' if fir_steps != 1 else ''}, the fastest Kalman one in "
                     f"{kalman_steps:.0f}")
    return "FIR against Kalman, LQG on each: " + "; ".join(parts) + "."


# ---------------------------------------------------------------------------- question 2
def _q2(plant_cells: list[Cell]) -> str:
    nominal = next((rows for _, c, _, rows, _ in plant_cells if c == "nominal"), None)
    true_nominal = next((r for r in nominal or [] if r["name"] == "lqg-true"), None)
    if true_nominal is None:
        return ""
    mismatched, total, excursions, gaps = [], 0, [], []
    for _, condition, strength, rows, records in plant_cells:
        by_name = {r["name"]: r for r in rows}
        lqg = [r for r in rows if r["name"].startswith("lqg-") and r["name"] != "lqg-true"
               and math.isfinite(error_of(r))]
        if len(lqg) < 2 or "lqg-true" not in by_name:
            continue
        total += 1
        excursions.append((by_name["lqg-true"]["iqm"] - true_nominal["iqm"])
                          / abs(true_nominal["iqm"] or 1.0))
        best_estimate = min(lqg, key=error_of)
        best_control = max(lqg, key=lambda r: r["iqm"])
        gaps.append(float(best_estimate.get("gap") or 0.0))
        if best_estimate["name"] != best_control["name"] and not verdict(
                records, by_name, best_estimate["name"], best_control["name"]
        ).startswith("beats"):
            mismatched.append(label(condition, strength))
    if not total:
        return ""
    text = (f"the smallest estimation error buys no better LQG return in {len(mismatched)} of "
            f"{total} settings" + (f" ({', '.join(mismatched)})" if mismatched else "")
            + " (the LQG on the best estimate matches, ties with or loses to another's)")
    text += (f". Decomposed: on the best estimate, the share of the LQG's cost that knowing "
             f"the state would remove is {_percent(min(gaps))} to {_percent(max(gaps))} "
             f"across the settings, while the conditions change the true-state LQG's own "
             f"return by {_percent(min(excursions), True)} to "
             f"{_percent(max(excursions), True)} (the plant's excursion)")
    if max(gaps) < 0.05:
        text += ("; the cost is the plant's own, so no estimate can do better than another "
                 "by more than a few per cent")
    elif min(gaps) > 0.5:
        text += ("; the cost is mostly the estimate's, so the estimate decides the control")
    return "Better estimate, better control? " + text + "."


def _percent(value: float, signed: bool = False) -> str:
    """``value`` as a whole percentage, without a sign on a value that rounds to 0."""
    rounded = round(100 * value)
    if rounded == 0:
        return "0%"
    return f"{rounded:+d}%" if signed else f"{rounded:d}%"


# ---------------------------------------------------------------------------- question 3
def _q3(plant_cells: list[Cell]) -> str:
    memory_counts: dict[str, list[str]] = {"beats": [], "ties": [], "loses": []}
    dr_counts: dict[str, list[str]] = {"beats": [], "ties": [], "loses": []}
    for _, condition, strength, rows, records in plant_cells:
        by_name = {r["name"]: r for r in rows}
        learned = [r for r in rows if r.get("regime")]
        nominal = [r for r in learned if r["regime"] == "nominal"]
        filters = [r for r in nominal if r["kind"] not in (*MEMORY, "true", "measurement")]
        memory = [r for r in nominal if r["kind"] in MEMORY]
        name = label(condition, strength)
        if filters and memory:
            best_filter = max(filters, key=lambda r: r["iqm"])
            best_memory = max(memory, key=lambda r: r["iqm"])
            v = verdict(records, by_name, best_filter["name"], best_memory["name"])
            memory_counts[_word(v)].append(name)
        randomised = [r for r in learned if r["regime"] != "nominal" and r["kind"] != "true"]
        candidates = [r for r in nominal if r["kind"] != "true"]
        if randomised and candidates:
            best_dr = max(randomised, key=lambda r: r["iqm"])
            best_nominal = max(candidates, key=lambda r: r["iqm"])
            dr_counts[_word(verdict(records, by_name, best_dr["name"],
                                    best_nominal["name"]))].append(name)
    parts = []
    if any(memory_counts.values()):
        parts.append("the best filter-fed PPO, against the best memory baseline, "
                     + _counts(memory_counts))
    if any(dr_counts.values()):
        parts.append("the best domain-randomised controller, against the best "
                     "nominal-trained one, " + _counts(dr_counts))
    return ("Learned controllers: " + "; ".join(parts) + ".") if parts else ""


# ---------------------------------------------------------------------------- the reference
#: how far below the true-state LQG PPO on the true state may score before the learned
#: rows' estimation gap stops measuring estimation (a share of the LQG's cost)
WEAK_REFERENCE = 0.10


def _reference(plant_cells: list[Cell]) -> str:
    """Whether PPO on the true state, the learned rows' reference, is itself a weak
    controller (the nominal cell): below the true-state LQG by more than
    :data:`WEAK_REFERENCE` of its cost, and which nominal-trained kinds without the true
    state score above it. Then the learned rows' estimation gaps are negative and measure
    PPO's training on that input, not the estimate."""
    cell = next((c for c in plant_cells if c[1] == "nominal"), None)
    if cell is None:
        return ""
    rows = cell[3]
    lqg_true = next((r for r in rows if r["name"] == "lqg-true"), None)
    ppo_true = next((r for r in rows if r.get("regime") == "nominal" and r["kind"] == "true"),
                    None)
    if lqg_true is None or ppo_true is None:
        return ""
    shortfall = (lqg_true["iqm"] - ppo_true["iqm"]) / abs(lqg_true["iqm"] or 1.0)
    if shortfall <= WEAK_REFERENCE:
        return ""
    above = [r for r in rows if r.get("regime") == "nominal" and r["kind"] != "true"
             and "+gate" not in r["kind"] and r["iqm"] > ppo_true["iqm"]]
    text = (f"PPO on the true state, the learned rows' reference, costs "
            f"{ppo_true['iqm'] / lqg_true['iqm']:.2g}× the true-state LQG "
            f"({ppo_true['iqm']:.3g} against {lqg_true['iqm']:.3g})")
    if not above:
        return (text + ": the learned rows' estimation gaps are measured against a weaker "
                "controller than the LQG rows', so they understate what knowing the state "
                "is worth.")
    best = max(above, key=lambda r: r["iqm"])
    return (text + f", and {len(above)} nominal-trained kinds without the true state score "
            f"above it ({', '.join(r['kind'] for r in above)}; the best, {best['kind']}, "
            f"{best['iqm']:.3g}): with the same training budget PPO learns less from the "
            "true state than from poorer inputs, so the learned rows' estimation gaps "
            "(negative where a row beats it) measure training, not estimation; the LQG "
            "rows' gaps do.")


def _word(verdict_text: str) -> str:
    return ("beats" if verdict_text.startswith("beats") else
            "loses" if verdict_text.startswith("loses") else "ties")


def _counts(counts: dict[str, list[str]]) -> str:
    pieces = []
    for key, words in (("beats", "beats"), ("ties", "ties with or matches"),
                       ("loses", "loses to")):
        if counts[key]:
            pieces.append(f"{words} it in {len(counts[key])} "
                          f"({', '.join(counts[key])})")
    return ", ".join(pieces) or "is never compared with"


def answers(report: dict[str, Any], records: Sequence[dict[str, Any]]) -> list[str]:
    """One short paragraph per plant and question (module docstring)."""
    out: list[str] = []
    middle = middle_cells(report, records)
    for env_id in dict.fromkeys(c[0] for c in middle):
        plant_cells = [c for c in middle if c[0] == env_id]
        name = short_name(env_id)
        out += [f"{name}: {sentence}" for sentence in
                (_q1(plant_cells), _q2(plant_cells), _q3(plant_cells),
                 _reference(plant_cells)) if sentence]
    return out


def details(report: dict[str, Any], records: Sequence[dict[str, Any]]) -> list[str]:
    """Question 1 setting by setting, with the filters named and the intervals (the
    report's)."""
    out = []
    for cell in middle_cells(report, records):
        found = fir_against_kalman(cell)
        if found is None:
            continue
        out.append(f"{short_name(cell[0])}, {found['label']}: the best FIR estimate "
                   f"({found['fir_estimate']}) has {found['ratio']:.2g}× the error of the "
                   f"best Kalman one ({found['kalman_estimate']}); {found['fir_control']} "
                   f"{found['control']} {found['kalman_control']}")
    return out
