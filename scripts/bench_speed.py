#!/usr/bin/env python
"""Every speed figure of fir-gym in one run, as ratios (what ``fir-gym speed`` runs).

    OPENBLAS_NUM_THREADS=1 python scripts/bench_speed.py [SECTION ...] [--json PATH] [--quick]

Sections: kalman, estimators, envs, wrappers (default: all). See
:mod:`fir_gym.benchmarks.speed` for what is measured and the targets.
"""

import sys

from fir_gym.benchmarks.speed import main

if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
