"""Compare the step times of two versions of the code from `fir-gym speed --json` files.

Usage::

    python scripts/compare_speed.py --before b1.json b2.json --after a1.json a2.json

Run each version at least twice, alternating (before, after, before, after), on an idle
machine: a figure is each version's best run, and the *noise* of a figure is the larger of
the two versions' own spread between their runs. A figure is reported slower only when
after/before − 1 exceeds that noise. Every per-step time (µs) of the kalman, estimators and
wrappers sections is compared; ratios and counts are skipped.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any


def step_times(result: dict[str, Any]) -> Iterator[tuple[str, float]]:
    """``(name, µs)`` of every per-step time of one `fir-gym speed --json` result."""
    kalman = result.get("kalman", {})
    for row in kalman.get("rows", []):
        name = f"kalman {row['filter']} {row['model']} ({row['data']})"
        for key in ("single_us", "batched_us"):
            yield f"{name} {key}", row[key]
    for row in kalman.get("fixed_cost", []):
        yield f"Estimator.step fixed cost B={row['batch']} step_us", row["step_us"]
        yield f"Estimator.step fixed cost B={row['batch']} python_us", row["python_us"]
    efir = kalman.get("efir") or {}
    for key in ("efir_us", "ekf_us", "batched_us"):
        if isinstance(efir.get(key), (int, float)):
            yield f"kalman efir n=3 N=10 {key}", efir[key]
    for row in result.get("estimators", []):
        for key in ("single_us", "B1_us", "B64_us", "B1024_us"):
            if isinstance(row.get(key), (int, float)):
                yield f"{row['env']} {row['estimator']} {key}", row[key]
    wrappers = result.get("wrappers", {})
    for mode in ("single", "vector"):
        for row in wrappers.get(mode, []):
            label = f"wrapper {mode} {row['env']} {row.get('mode', '')}".rstrip()
            for key in ("wrapped_us", "ekf_us"):
                if isinstance(row.get(key), (int, float)):
                    yield f"{label} {key}", row[key]


def best_and_spread(paths: list[Path]) -> dict[str, tuple[float, float]]:
    runs = [dict(step_times(json.loads(p.read_text()))) for p in paths]
    out = {}
    for name in runs[0]:
        values = [run[name] for run in runs if name in run]
        lo, hi = min(values), max(values)
        out[name] = (lo, hi / lo - 1.0 if lo > 0 else 0.0)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", nargs="+", type=Path, required=True)
    parser.add_argument("--after", nargs="+", type=Path, required=True)
    args = parser.parse_args(argv)
    before, after = best_and_spread(args.before), best_and_spread(args.after)
    slower = 0
    print(f"{'figure':<62} {'before µs':>10} {'after µs':>10} {'after/before':>12} "
          f"{'noise':>6}")
    for name, (b, b_noise) in before.items():
        if name not in after:
            continue
        a, a_noise = after[name]
        noise = max(b_noise, a_noise)
        change = a / b - 1.0
        flag = "  slower" if change > noise else ""
        slower += bool(flag)
        print(f"{name:<62} {b:>10.4g} {a:>10.4g} {a / b:>12.3f} {noise:>6.1%}{flag}")
    print(f"\n{slower} of {len(before)} figures slower than before by more than their noise")
    return 0


if __name__ == "__main__":
    sys.exit(main())
