#!/usr/bin/env python
"""Measure the timings README.md states for ``fir-gym reproduce``, and print them.

    python scripts/readme_timings.py [--runs cold,warm,quick] [--keep DIR]

* **cold** — the first run on a fresh machine: numba's on-disk cache is an empty
  folder (``NUMBA_CACHE_DIR``), so every kernel compiles during the run;
* **warm** — the same command again with that cache filled: what every later run costs;
* **quick** — ``fir-gym reproduce --quick`` with the warm cache.

Each run is ``fir-gym reproduce --out DIR --no-progress`` in a fresh process (the
installed ``fir-gym`` of this interpreter), timed by wall clock and by the CPU time the
process used (user + system, from ``resource.getrusage``). The machine's load average
before and after each run is printed with it: timings on a shared machine are noisy,
so re-run this on a quiet one before quoting the figures. The last lines are the
Markdown README.md quotes, with the date and the machine.
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

RUNS = {"cold": [], "warm": [], "quick": ["--quick"]}


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
    parser.add_argument("--keep", default=None, metavar="DIR",
                        help="keep the reports and the numba cache in DIR (default: a "
                             "temporary folder, removed)")
    args = parser.parse_args(argv)
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
    machine = (f"{os.cpu_count()} CPUs, "
               f"{platform.processor() or platform.machine()}, Python "
               f"{platform.python_version()}, {platform.platform()}")
    print(f"fir-gym reproduce timings, {datetime.date.today().isoformat()}, {machine}")
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
    print("\nFor README.md:\n")
    parts = []
    labels = {"cold": "the first run (numba compiles its kernels)",
              "warm": "every later run", "quick": "`--quick`"}
    for name, r in results.items():
        parts.append(f"{labels[name]} {minutes(float(r['wall']))} "
                     f"({minutes(float(r['cpu']))} of CPU)")
    print(f"Measured {datetime.date.today().isoformat()} on {os.cpu_count()} CPUs "
          f"(load average at start {next(iter(results.values()))['load'].split(' ')[0]}): "
          + "; ".join(parts) + ".")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
