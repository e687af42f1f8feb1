"""The benchmark's report: the tables in Markdown, the figures, and rebuilding both from
``results.json`` (``fir-gym benchmark-robustness --out DIR --report-only``)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from fir_gym.tables import format_table

from .answers import answers, details
from .formatting import gap_interval, interval, middle, number
from .plan import short_name
from .tables import cell_rows, cells

__all__ = ["answers", "details", "markdown", "rebuild", "save_figures", "tables_of"]


def tables_of(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every cell's rows (:func:`.tables.cell_rows`): ``[{env_id, condition, strength,
    rows}]`` in the order the records first name them."""
    return [{"env_id": env_id, "condition": condition, "strength": strength,
             "rows": cell_rows(rs)}
            for (env_id, condition, strength), rs in cells(records).items()]


def _recovery(row: dict[str, Any]) -> str:
    if "recovery" not in row:
        return "—"
    if row["recovery"] is None:
        return "n/a"
    return (">" if row.get("recovery_censored") else "") + f"{row['recovery']:.0f}"


def markdown(report: dict[str, Any], figures: list[str] | None = None) -> str:
    """The report in Markdown (module docstring)."""
    lines = ["# Robustness in the loop: the benchmark", ""]
    if report.get("quick"):
        lines += ["**--quick run: tiny budgets and few episodes, the numbers mean nothing.**", ""]
    machine = report.get("machine", {})
    lines += [
        f"Code version {report.get('code_version')}; {machine.get('cpu', '?')}, "
        f"{machine.get('cores', '?')} cores, backend {machine.get('backend')} "
        f"(jobs {machine.get('jobs')}). LQG grid: {report.get('lqg_tasks', 0)} tasks in "
        f"{report.get('lqg_seconds', 0.0) / 60:.1f} min; learned grid: "
        f"{report.get('learned_tasks', 0)} tasks in {report.get('learned_seconds', 0.0) / 60:.1f} "
        f"min ({report.get('learned_reused', 0)} reused from an earlier run's cached result, "
        f"{report.get('train_seconds', 0.0) / 3600:.2f} h of training in all).", "",
        "Returns are costs (higher is better): the IQM of the per-seed mean returns on the "
        "shared evaluation episodes with a 95 % bootstrap interval over episodes and seeds. "
        "The estimation gap is `(IQM(true) − IQM(row)) / |IQM(row)|`, the share of the row's "
        "cost that the same controller family on the true state would remove (`lqg-true` "
        "for the LQG rows, PPO on the true state of the same training regime for a learned "
        "row): 0 is as good as knowing the state. NEES: the median over steps and the "
        "fraction of steps inside the 95 % χ² band (0.95 for a consistent filter). "
        "Diverged: the fraction of episodes whose divergence flag rose. Recovery: after a "
        "burst, the median number of steps until the estimation error's 10-step level is "
        "back at its pre-burst 95th percentile "
        "(`>`: censored by the episode's end). `+gate`: the estimator with its innovation "
        "gate. Learned rows name their training regime in brackets.", ""]
    if report.get("skipped"):
        lines += ["Left out of the LQG grid (the estimator refuses the setting): "
                  + "; ".join(report["skipped"]) + ".", ""]
    if machine.get("learned_backend") == "jax":
        lines += ["The learned grid was trained with the JAX backend (`--backend jax`: "
                  "every seed of a plant, kind and regime in one compiled program) and "
                  "evaluated in the numpy envs like the stable-baselines3 one.", ""]
    if report.get("learned_skipped"):
        lines += ["Left out of the learned grid: " + "; ".join(report["learned_skipped"])
                  + ".", ""]
    lines += ["## Answers", ""] + [f"- {a}" for a in report.get("answers", [])] + [""]
    if report.get("details"):
        lines += ["FIR against Kalman, setting by setting (LQG on each family's best):", ""]
        lines += [f"- {d}" for d in report["details"]] + [""]
    conditions = report.get("conditions", {})
    by_plant: dict[str, list[dict[str, Any]]] = {}
    for cell in report["tables"]:
        by_plant.setdefault(cell["env_id"], []).append(cell)
    for env_id, plant_cells in by_plant.items():
        name = short_name(env_id)
        lines += [f"## {env_id}", ""]
        lines += _summary_table(plant_cells, conditions)
        for figure in figures or []:
            if Path(figure).name.startswith(name + "_"):
                lines += [f"![{Path(figure).stem}]({figure})", ""]
        for condition in conditions:
            chosen = [c for c in plant_cells if c["condition"] == condition]
            if not chosen:
                continue
            meaning = report.get("strength_meaning", {}).get(condition, "")
            lines += [f"### {name}: {condition}" + (f" (strength: {meaning})"
                                                      if condition != "nominal" else ""), ""]
            rows = []
            for cell in chosen:
                for r in cell["rows"]:
                    rmse = "—" if r["rmse"] is None else ", ".join(f"{v:.3g}" for v in r["rmse"])
                    rows.append([r["name"], number(cell["strength"]), r["seeds"],
                                 interval(r["iqm"], r["low"], r["high"]), gap_interval(r), rmse,
                                 number(r.get("nees_median"), 3),
                                 number(r.get("nees_in_band"), 2),
                                 number(r.get("diverged"), 2), _recovery(r)])
            lines.append(format_table(
                ["controller", "strength", "seeds", "IQM return [95% CI]",
                 "estimation gap [95% CI]", "RMSE per state", "NEES median", "in χ² band",
                 "diverged", "recovery"], rows, markdown=True))
            lines.append("")
    return "\n".join(lines)


def _summary_table(plant_cells: list[dict[str, Any]], conditions: dict[str, list[float]]
                   ) -> list[str]:
    """Rows: controllers; columns: each condition at its middle strength; entries: the
    estimation gap (the IQM return for the true-state rows)."""
    chosen = []
    for condition, strengths in conditions.items():
        strength = middle(strengths) if condition != "nominal" else 0.0
        cell = next((c for c in plant_cells if c["condition"] == condition
                     and math.isclose(c["strength"], strength)), None)
        if cell is not None:
            chosen.append((f"{condition} {number(strength)}" if condition != "nominal"
                           else "nominal", cell))
    if not chosen:
        return []
    names = list(dict.fromkeys(r["name"] for _, c in chosen for r in c["rows"]))
    table = []
    for name in names:
        row: list[Any] = [name]
        for _, cell in chosen:
            r = next((x for x in cell["rows"] if x["name"] == name), None)
            if r is None:
                row.append("—")
            elif r.get("gap") is None:
                row.append(f"R {number(r['iqm'])}")
            else:
                row.append(f"{r['gap']:.2f}")
        table.append(row)
    return ["Estimation gap at each condition's middle strength (`R`: the IQM return of "
            "the true-state rows the gaps are measured against):", "",
            format_table(["controller"] + [label for label, _ in chosen], table,
                         markdown=True), ""]


def save_figures(report: dict[str, Any], folder: Path) -> list[str]:
    """Per plant, the IQM return against each condition's strength: one panel per
    condition, one line per LQG controller and per learned kind of the nominal regime.
    Returns the figures' paths relative to the report's folder."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    conditions = [c for c in report.get("conditions", {}) if c != "nominal"]
    by_plant: dict[str, list[dict[str, Any]]] = {}
    for cell in report["tables"]:
        by_plant.setdefault(cell["env_id"], []).append(cell)
    written = []
    for env_id, plant_cells in by_plant.items():
        nominal = next((c for c in plant_cells if c["condition"] == "nominal"), None)
        for family, keep in (("lqg", lambda n: n.startswith("lqg-")),
                             ("learned", lambda n: n.endswith("(nominal)"))):
            names = list(dict.fromkeys(r["name"] for c in plant_cells for r in c["rows"]
                                       if keep(r["name"])))
            if not names or not conditions:
                continue
            columns = min(4, len(conditions))
            rows_n = math.ceil(len(conditions) / columns)
            fig, axes = plt.subplots(rows_n, columns, figsize=(4.2 * columns, 3.2 * rows_n),
                                     squeeze=False)
            for ax, condition in zip(axes.flat, conditions, strict=False):
                for i, name in enumerate(names):
                    points = []
                    if nominal is not None:
                        r0 = next((r for r in nominal["rows"] if r["name"] == name), None)
                        if r0 is not None:
                            points.append((0.0, r0["iqm"]))
                    for cell in plant_cells:
                        if cell["condition"] != condition:
                            continue
                        r = next((x for x in cell["rows"] if x["name"] == name), None)
                        if r is not None:
                            points.append((cell["strength"], r["iqm"]))
                    points.sort()
                    if points:
                        xs, ys = zip(*points, strict=True)
                        style = ":" if name.endswith("+gate") or "+gate " in name else "-"
                        if name in ("lqg-true", "true (nominal)"):
                            style = "--"
                        ax.plot(xs, ys, style, marker="os^vD<>ph*"[i % 10], markersize=4,
                                color=f"C{i % 10}", label=name)
                meaning = report.get("strength_meaning", {}).get(condition, "strength")
                ax.set_title(condition, fontsize=10)
                ax.set_xlabel(f"strength ({meaning})", fontsize=7)
                ax.set_ylabel("IQM return (higher is better)", fontsize=7)
                ax.tick_params(labelsize=7)
            for ax in list(axes.flat)[len(conditions):]:
                ax.set_visible(False)
            handles, labels = axes.flat[0].get_legend_handles_labels()
            fig.legend(handles, labels, loc="center left", bbox_to_anchor=(1.0, 0.5),
                       fontsize=7, frameon=False)
            fig.suptitle(f"{env_id}: {'LQG on each estimator' if family == 'lqg' else 'PPO'}"
                         " — return against condition strength (0: nominal)", fontsize=10)
            fig.tight_layout()
            name = f"{short_name(env_id)}_{family}.png"
            fig.savefig(folder / name, dpi=110, bbox_inches="tight")
            plt.close(fig)
            written.append(f"figures/{name}")
    return written


def rebuild(out: str | Path) -> dict[str, Any]:
    """Rewrite ``OUT/REPORT.md``, the figures and the tables and answers of
    ``OUT/results.json`` from the records it holds (no task is run again)."""
    out = Path(out)
    path = out / "results.json"
    if not path.is_file():
        raise ValueError(f"{out} holds no results.json (run fir-gym benchmark-robustness "
                         f"--out {out} first)")
    saved = json.loads(path.read_text())
    records = saved.pop("records")
    saved["tables"] = tables_of(records)
    saved["answers"] = answers(saved, records)
    saved["details"] = details(saved, records)
    path.write_text(json.dumps({**saved, "records": records}) + "\n")
    figures = save_figures(saved, out / "figures")
    (out / "REPORT.md").write_text(markdown(saved, figures) + "\n")
    return saved
