"""Both backends, N seeds each (10 by default), on the same rows of the controller benchmark,
in one run (docs/jax.md, "The benchmark beside stable-baselines3").

The SB3 side is the controller benchmark's own jobs (``benchmark_jobs``: its plants' steps,
episode settings and evaluation episodes; finished run folders under ``OUT/sb3`` are
reused, so a larger ``--seeds`` only trains the new seeds); the JAX side is
``fir_gym.jax.benchmark.run_benchmark`` on the same plants and kinds. For each row it prints
each backend's IQM and 95 % interval on the same numpy-env episodes, the IQM difference
JAX − SB3 with its 95 % interval (``episode_bootstrap`` of both backends together: one draw
of the shared episodes, then each backend's seeds), the two-sided Mann–Whitney p of the
per-seed mean returns, and the seconds each backend took. The rows go to
``OUT/comparison.json`` and ``OUT/COMPARISON.md``.

    python scripts/seeds10_measurement.py [--out DIR] [--seeds N] [--plants P,...]
        [--kinds K,...] [--jobs N] [--quick]

The defaults are the first such run's: the raw-measurement rows of Orbit-v0 and
UncertainOscillator-v0, one process each side.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings
from pathlib import Path
from typing import Any

PLANTS = "fir_gym/Orbit-v0,fir_gym/UncertainOscillator-v0"


def compare(sb3: list[list[float]], jax: list[list[float]]) -> dict[str, Any]:
    """Both backends' rows on the same episodes: IQMs, intervals, the difference and p."""
    import scipy.stats

    from fir_gym.training.stats import episode_bootstrap, iqm, percentile_interval

    draws = episode_bootstrap({"sb3": sb3, "jax": jax})
    means = {k: [sum(e) / len(e) for e in v] for k, v in (("sb3", sb3), ("jax", jax))}
    row: dict[str, Any] = {"seeds": {k: len(v) for k, v in means.items()}}
    for k in ("sb3", "jax"):
        row[k] = {"iqm": iqm(means[k]), "interval": percentile_interval(draws[k]),
                  "per_seed": means[k]}
    row["difference"] = {"iqm": row["jax"]["iqm"] - row["sb3"]["iqm"],
                         "interval": percentile_interval(draws["jax"] - draws["sb3"])}
    row["mann_whitney_p"] = float(scipy.stats.mannwhitneyu(means["jax"], means["sb3"],
                                                           alternative="two-sided").pvalue)
    low, high = row["sb3"]["interval"]
    row["jax_inside_sb3"] = bool(low <= row["jax"]["iqm"] <= high)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="runs/seeds10", help="output folder")
    parser.add_argument("--seeds", type=int, default=10, help="seeds per backend and row")
    parser.add_argument("--plants", default=PLANTS, help="comma-separated plant ids")
    parser.add_argument("--kinds", "--kind", default="measurement",
                        help="comma-separated kinds (the rows), e.g. true,ekf")
    parser.add_argument("--quick", action="store_true",
                        help="the benchmarks' --quick budgets: checks the script, numbers mean "
                             "nothing")
    parser.add_argument("--jobs", type=int, default=1,
                        help="worker processes on each side (SB3: joblib's; JAX: --jobs)")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")

    from fir_gym.jax.benchmark import run_benchmark
    from fir_gym.scenarios.runner import SERIAL, Runner
    from fir_gym.tables import format_table
    from fir_gym.training.benchmark import benchmark_jobs, run_job

    out = Path(args.out)
    plants = [p.strip() for p in args.plants.split(",") if p.strip()]
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    print(f"load average at the start: {os.getloadavg()}")
    start = time.perf_counter()
    jobs = benchmark_jobs(out / "sb3", quick=args.quick, seeds=args.seeds, plants=plants,
                          kinds=kinds)
    runner = Runner("joblib", jobs=args.jobs) if args.jobs > 1 else SERIAL
    sb3 = runner.map(run_job, jobs, desc="sb3")
    sb3_seconds = time.perf_counter() - start
    start = time.perf_counter()
    report = run_benchmark(out / "jax", quick=args.quick, seeds=args.seeds, plants=plants,
                           kinds=kinds, progress=False, jobs=args.jobs if args.jobs > 1 else None)
    jax_seconds = time.perf_counter() - start

    rows, lines = [], []
    for env_id, table in report["tables"].items():
        for theirs in table:
            mine = [list(map(float, r["returns"])) for r in sb3
                    if r["config"]["env_id"] == env_id and r["kind"] == theirs["kind"]]
            if not mine:
                continue
            row = {"env_id": env_id, "kind": theirs["kind"],
                   **compare(mine, theirs["numpy_returns"])}
            rows.append(row)
            s, j, d = row["sb3"], row["jax"], row["difference"]
            lines.append([env_id.split("/")[-1], row["kind"],
                          f"{s['iqm']:.4g} [{s['interval'][0]:.4g}, {s['interval'][1]:.4g}]",
                          f"{j['iqm']:.4g} [{j['interval'][0]:.4g}, {j['interval'][1]:.4g}]",
                          f"{d['iqm']:+.4g} [{d['interval'][0]:+.4g}, {d['interval'][1]:+.4g}]",
                          f"{row['mann_whitney_p']:.2g}",
                          "yes" if row["jax_inside_sb3"] else "no"])
    table_text = format_table(
        ["plant", "kind", f"SB3, {args.seeds} seeds [95% CI]",
         f"JAX, numpy env, {args.seeds} seeds [95% CI]", "JAX − SB3 [95% CI]",
         "Mann–Whitney p", "JAX inside SB3's"], lines, markdown=True)
    timing = (f"SB3 {sb3_seconds:.0f} s, JAX {jax_seconds:.0f} s (compilation included; "
              f"{args.jobs} process(es) each side): {sb3_seconds / jax_seconds:.2f}x; load "
              f"average at the end: {os.getloadavg()}")
    print(table_text)
    print(timing)
    out.mkdir(parents=True, exist_ok=True)
    (out / "comparison.json").write_text(json.dumps(
        {"seeds": args.seeds, "plants": plants, "kinds": kinds, "jobs": args.jobs,
         "sb3_seconds": sb3_seconds, "jax_seconds": jax_seconds, "rows": rows}, indent=1) + "\n")
    (out / "COMPARISON.md").write_text(table_text + "\n\n" + timing + "\n")


if __name__ == "__main__":
    main()
