#!/usr/bin/env python
"""Time ``fir-gym reproduce`` serially, on two joblib workers and on a two-worker Dask cluster.

    python scripts/reproduce_scaling.py [--quick] [--cold] [--backends serial,joblib,dask]
                                        [--out DIR] [--no-figures]

Each backend runs back to back in a fresh process (``python -m fir_gym.cli reproduce``,
imports and kernel loading included), the load average is printed before each run,
and the speed-ups are the serial wall time over each backend's, measured in the same
call. The REPORT.md files are compared byte for byte. ``--cold`` first deletes the
numba cache (the ``*.nbi``/``*.nbc`` files under the installed ``fir_gym.estimators``
and ``fir_gym.envs``), so the first run also compiles the kernels. Timings on a shared
machine are depressed in proportion to its load: read the ratios with the load beside
them.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

JOBS = 2


def clear_numba_cache() -> int:
    """Delete the compiled-kernel cache of the installed package; the number of files."""
    import fir_gym.envs
    import fir_gym.estimators

    removed = 0
    for package in (fir_gym.estimators, fir_gym.envs):
        for path in Path(package.__file__).parent.rglob("__pycache__/*.nb[ic]"):
            path.unlink()
            removed += 1
    return removed


def run(backend: str, out: Path, quick: bool, figures: bool) -> float:
    args = [sys.executable, "-m", "fir_gym.cli", "reproduce", "--no-progress"]
    args += ["--quick"] if quick else []
    args += ["--out", str(out)] if figures else []
    if backend != "serial":
        args += ["--backend", backend, "--jobs", str(JOBS)]
    start = time.perf_counter()
    done = subprocess.run(args, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"{backend} failed:\n{done.stderr[-2000:]}")
    if not figures:                                    # the text report on stdout
        out.mkdir(parents=True, exist_ok=True)
        (out / "REPORT.md").write_text(done.stdout)
    return wall


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fir-gym reproduce --quick")
    p.add_argument("--cold", action="store_true", help="clear the numba cache first")
    p.add_argument("--backends", default="serial,joblib,dask")
    p.add_argument("--out", default=None, help="where the reports go (default: a temp dir)")
    p.add_argument("--no-figures", action="store_true",
                   help="no --out for fir-gym: time the computation and the text report only")
    args = p.parse_args(argv)
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    root = Path(args.out or tempfile.mkdtemp(prefix="fir-gym-scaling-"))
    if args.cold:
        print(f"cleared {clear_numba_cache()} cached kernel files")
    walls: dict[str, float] = {}
    for b in backends:
        load = os.getloadavg()
        walls[b] = run(b, root / b, args.quick, not args.no_figures)
        print(f"{b:7s} {walls[b]:7.1f} s   (load average before: {load[0]:.2f} {load[1]:.2f} "
              f"{load[2]:.2f} on {os.cpu_count()} CPUs)", flush=True)
    reports = {b: (root / b / "REPORT.md").read_bytes() for b in backends}
    same = len(set(reports.values())) == 1
    if "serial" in walls:
        for b in backends:
            if b != "serial":
                print(f"speed-up {b} ({JOBS} workers) over serial: "
                      f"{walls['serial'] / walls[b]:.2f}x")
    print(f"REPORT.md identical on {', '.join(backends)}: {same}   ({root})")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
