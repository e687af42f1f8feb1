"""Both backends, 10 seeds each, on the raw-measurement rows of Orbit-v0 and
UncertainOscillator-v0, in one run (docs/jax.md, "The benchmark beside stable-baselines3").

The SB3 side is the controller benchmark's own jobs (``benchmark_jobs``, its plants' steps,
episode settings and evaluation episodes) for the kind (``measurement``, or ``--kind``, e.g.
``recurrent``); the JAX side is ``fir_gym.jax.benchmark.run_benchmark`` on the same plants
and kind. Prints each backend's IQM and 95 % interval on the same numpy-env episodes, and the
seconds each took.

    python scripts/seeds10_measurement.py [--out DIR] [--seeds N] [--kind K]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

PLANTS = ["fir_gym/Orbit-v0", "fir_gym/UncertainOscillator-v0"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="runs/seeds10", help="output folder")
    parser.add_argument("--seeds", type=int, default=10, help="seeds per backend and plant")
    parser.add_argument("--kind", default="measurement", help="the rows' kind")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")

    from fir_gym.jax.benchmark import run_benchmark
    from fir_gym.scenarios.runner import SERIAL
    from fir_gym.training.benchmark import benchmark_jobs, run_job, summarise

    out = Path(args.out)
    print(f"load average at the start: {os.getloadavg()}")
    start = time.perf_counter()
    jobs = [j for j in benchmark_jobs(out / "sb3", seeds=args.seeds, plants=PLANTS)
            if j["config"].observation_kind == args.kind]
    sb3 = summarise(SERIAL.map(run_job, jobs, desc="sb3"))
    sb3_seconds = time.perf_counter() - start
    start = time.perf_counter()
    report = run_benchmark(out / "jax", seeds=args.seeds, plants=PLANTS,
                           kinds=[args.kind], progress=False)
    jax_seconds = time.perf_counter() - start
    for env_id in PLANTS:
        (mine,) = [r for r in sb3[env_id] if r["kind"] == args.kind]
        (theirs,) = report["tables"][env_id]
        inside = mine["low"] <= theirs["numpy_iqm"] <= mine["high"]
        print(f"{env_id}: SB3 {mine['iqm']:.4g} [{mine['low']:.4g}, {mine['high']:.4g}], "
              f"JAX {theirs['numpy_iqm']:.4g} [{theirs['numpy_low']:.4g}, "
              f"{theirs['numpy_high']:.4g}] ({args.seeds} seeds each; JAX inside SB3's "
              f"interval: {'yes' if inside else 'no'})")
    print(f"SB3 {sb3_seconds:.0f} s, JAX {jax_seconds:.0f} s (compilation included): "
          f"{sb3_seconds / jax_seconds:.2f}x; load average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
