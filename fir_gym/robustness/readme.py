"""The README's two benchmark sections, computed from a ``benchmark-robustness`` results.json.

``python scripts/update_readme_benchmarks.py --results DIR/results.json`` writes them
between the README's markers: the robustness table and its answers
(``<!-- robustness:start -->``), and the controllers on estimates of the nominal plant
(``<!-- benchmark:start -->``: the learned grid's nominal regime under the nominal
condition, beside the LQG on each estimator). Every number in them is read from the
results; the prose around them says what was run, on which machine, and how long it took.
"""

from __future__ import annotations

from typing import Any

from fir_gym.tables import format_table

from .answers import FIR, KALMAN, MEMORY, base_estimator, error_of, label, middle_cells
from .formatting import gap_interval, interval, number
from .plan import short_name


def _entry(row: dict[str, Any] | None) -> str:
    """``name return (gap)`` of a row, or — ."""
    if row is None:
        return "—"
    name = row["name"].removeprefix("lqg-").replace(" (nominal)", "")
    gap = "" if row.get("gap") is None else f" ({row['gap']:.2f})"
    return f"{name} {number(row['iqm'], 3)}{gap}"


def _best(rows: list[dict[str, Any]], keep: Any) -> dict[str, Any] | None:
    chosen = [r for r in rows if keep(r)]
    return max(chosen, key=lambda r: r["iqm"]) if chosen else None


def robustness_table(results: dict[str, Any]) -> str:
    """Per plant and condition (middle strength): the true-state LQG's return, and each
    family's best controller with its return and estimation gap."""
    rows = []
    for env_id, condition, strength, r, _ in middle_cells(results,
                                                          results.get("records", [])):
        lqg_true = next((x for x in r if x["name"] == "lqg-true"), None)
        learned_nominal = [x for x in r if x.get("regime") == "nominal"]
        rows.append([
            short_name(env_id), label(condition, strength),
            "—" if lqg_true is None else number(lqg_true["iqm"], 3),
            _entry(_best(r, lambda x: x["name"].startswith("lqg-")
                         and base_estimator(x["kind"]) in KALMAN)),
            _entry(_best(r, lambda x: x["name"].startswith("lqg-")
                         and base_estimator(x["kind"]) in FIR)),
            _entry(_best(learned_nominal, lambda x: x["kind"] not in
                         (*MEMORY, "true", "measurement"))),
            _entry(_best(learned_nominal, lambda x: x["kind"] in MEMORY)),
            _entry(_best([x for x in r if x.get("regime") not in (None, "nominal")],
                         lambda x: x["kind"] != "true")),
        ])
    return format_table(["plant", "condition", "LQG, true state", "LQG, best Kalman",
                         "LQG, best FIR", "PPO, best estimate", "PPO, best memory",
                         "PPO, best randomised"], rows, markdown=True)


def controllers_table(results: dict[str, Any], env_id: str) -> str:
    """The nominal cell of one plant: PPO of the nominal regime on each kind, the LQG on the
    true state and on each estimator (plain), with RMSE and NEES."""
    cell = next((c for c in results["tables"] if c["env_id"] == env_id
                 and c["condition"] == "nominal"), None)
    if cell is None:
        return ""
    rows = []
    for r in cell["rows"]:
        if r.get("regime") not in (None, "nominal") or r["name"].endswith("+gate") \
                or r["name"].endswith("+gate (nominal)"):
            continue
        rmse = "—" if r["rmse"] is None else ", ".join(f"{v:.3g}" for v in r["rmse"])
        rows.append([r["name"].replace(" (nominal)", ""), r["seeds"],
                     interval(r["iqm"], r["low"], r["high"]), gap_interval(r),
                     rmse, number(r.get("nees_median"), 3), number(r.get("nees_in_band"), 2),
                     number(r.get("nees_mean"), 3)])
    return format_table(["controller", "seeds", "IQM return [95% CI]",
                         "estimation gap [95% CI]", "estimation RMSE per state",
                         "NEES median", "in χ² band", "ANEES"], rows, markdown=True)


def error_ratio(rows: list[dict[str, Any]], a: str, b: str) -> float:
    """The estimation-error ratio of two rows of a cell (for prose)."""
    by_name = {r["name"]: r for r in rows}
    return error_of(by_name[a]) / error_of(by_name[b])
