#!/usr/bin/env python
"""Measure the timings README.md states for ``fir-gym reproduce``, and print them.

    python scripts/readme_timings.py [--runs cold,warm,quick] [--keep DIR]
    python scripts/readme_timings.py --reference-only

* **cold** — the first run on a fresh machine: numba's on-disk cache is an empty
  folder (``NUMBA_CACHE_DIR``), so every kernel compiles during the run;
* **warm** — the same command again with that cache filled: what every later run costs;
* **quick** — ``fir-gym reproduce --quick`` with the warm cache.

Each run is ``fir-gym reproduce --out DIR --no-progress`` in a fresh process (the
installed ``fir-gym`` of this interpreter), timed by wall clock and by the CPU time the
process used (user + system, from ``resource.getrusage``). The machine's load average
before and after each run is printed with it: timings on a shared machine are noisy,
so re-run this on a quiet one before quoting the figures.

**A figure that transfers.** Before and after the runs the script times a *reference
workload* (:func:`reference_workload`: fixed numpy and pure-Python arithmetic on one core,
the two kinds of work a reproduce run does), and states every run's CPU time as a multiple
of it. A machine of the same kind can differ by 3x in speed; the multiple stays put far
better than the seconds, so ``--reference-only`` on your machine, times the multiple,
predicts your run. The compile cost is cold CPU − warm CPU of the same invocation. The
last lines are the Markdown README.md quotes, with the date, the CPU model, the cores and
the load.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fir_gym.machine import cpu_model

RUNS = {"cold": [], "warm": [], "quick": ["--quick"]}


def reference_workload(repeats: int = 3) -> float:
    """The CPU seconds (best of ``repeats``) of a fixed workload: 320 products of 200 x 200
    matrices and eight million pure-Python additions (about a second on the development
    machine) — numpy and interpreter work, as in a reproduce run."""
    import numpy as np

    rng = np.random.default_rng(0)
    a = rng.normal(size=(200, 200))
    best = float("inf")
    for _ in range(repeats):
        start = time.process_time()
        m = a
        for _ in range(320):
            m = np.tanh(m @ a / 200.0)
        total = 0.0
        for i in range(8_000_000):
            total += i * 1e-6
        best = min(best, time.process_time() - start)
        assert np.isfinite(m).all() and total > 0
    return best


def fir_gym_command() -> list[str]:
    """``fir-gym`` as installed beside this interpreter (else the module entry point)."""
    script = Path(sys.executable).with_name("fir-gym")
    return [str(script)] if script.exists() else [sys.executable, "-m", "fir_gym.cli"]


def load() -> str:
    return f"{os.getloadavg()[0]:.1f}" if hasattr(os, "getloadavg") else "?"


def timed(argv: list[str], env: dict[str, str]) -> dict[str, object]:
    """Run ``argv``; its wall time, CPU time (user + system) and exit status."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load_before, start = load(), time.perf_counter()
    result = subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({result.returncode}):\n{result.stderr}")
    return {"wall": wall, "cpu": cpu, "load": f"{load_before} → {load()}"}


def minutes(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 100 else f"{seconds / 60:.1f} min"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", default="cold,warm,quick",
                        help="which runs, in order, among cold, warm, quick "
                             "(default: cold,warm,quick)")
    parser.add_argument("--reference-only", action="store_true",
                        help="time only the reference workload (to scale the README's "
                             "multiples to this machine)")
    parser.add_argument("--keep", default=None, metavar="DIR",
                        help="keep the reports and the numba cache in DIR (default: a "
                             "temporary folder, removed)")
    args = parser.parse_args(argv)
    if args.reference_only:
        seconds = reference_workload()
        print(f"reference workload: {seconds:.3f} s of CPU on {cpu_model()}, "
              f"{os.cpu_count()} CPUs (load average {load()})")
        return 0
    runs = [r.strip() for r in args.runs.split(",") if r.strip()]
    bad = [r for r in runs if r not in RUNS]
    if bad or not runs:
        parser.error(f"--runs takes cold, warm and quick; got {args.runs!r}")
    root = Path(args.keep or tempfile.mkdtemp(prefix="fir-gym-timings-"))
    cache = root / "numba-cache"
    if cache.exists():
        shutil.rmtree(cache)          # cold means an empty cache
    cache.mkdir(parents=True)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "MUJOCO_GL": "egl"}
    machine = (f"{cpu_model()}, {os.cpu_count()} CPUs, Python "
               f"{platform.python_version()}, {platform.platform()}")
    print(f"fir-gym reproduce timings, {datetime.date.today().isoformat()}, {machine}")
    ref_before = reference_workload()
    print(f"  reference workload: {ref_before:.3f} s of CPU", flush=True)
    results = {}
    try:
        for name in runs:
            argv_ = [*fir_gym_command(), "reproduce", "--out", str(root / f"report-{name}"),
                     "--no-progress", *RUNS[name]]
            r = timed(argv_, env)
            results[name] = r
            print(f"  {name:5s}: {r['wall']:6.1f} s wall, {r['cpu']:6.1f} s CPU "
                  f"(load average {r['load']}): {' '.join(argv_[-4:])}", flush=True)
    finally:
        if args.keep is None:
            shutil.rmtree(root, ignore_errors=True)
    ref_after = reference_workload()
    ref = min(ref_before, ref_after)
    print(f"  reference workload again: {ref_after:.3f} s of CPU (the multiples use the "
          f"smaller, {ref:.3f} s)")
    start_load = next(iter(results.values()))["load"].split(" ")[0] if results else load()
    print(f"\nFor README.md (measured {datetime.date.today().isoformat()} on {cpu_model()}, "
          f"{os.cpu_count()} cores, load average {start_load} at the start; reference "
          f"workload {ref:.2f} s of CPU):\n")
    labels = {"cold": "the first `fir-gym reproduce` (numba compiles its kernels and caches "
                      "them on disk)",
              "warm": "every later `fir-gym reproduce`", "quick": "`fir-gym reproduce --quick`"}
    print("| run | wall | CPU | CPU in reference workloads |")
    print("|---|---|---|---|")
    for name, r in results.items():
        cpu = float(r["cpu"])
        print(f"| {labels[name]} | {minutes(float(r['wall']))} | {minutes(cpu)} | "
              f"{cpu / ref:.0f} × |")
    if "cold" in results and "warm" in results:
        compile_cpu = float(results["cold"]["cpu"]) - float(results["warm"]["cpu"])
        print(f"\nCompiling the kernels: {minutes(compile_cpu)} of CPU "
              f"({compile_cpu / ref:.0f} reference workloads), cold CPU − warm CPU.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
