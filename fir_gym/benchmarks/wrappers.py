"""Cost of an estimator in the loop: the vector wrapper against the bare vector env.

For every plant with a native vector env, 64 sub-environments are stepped bare and
wrapped in :class:`~fir_gym.wrappers.VectorEstimatorObservation` with one batched
EKF, both in Gymnasium's sync vector env and in fir-gym's native one; the ratio
wrapped / bare per sub-env step is the wrapper's overhead (target ≤ 1.2). Best of
``repeats`` timings, measured in one run.

    fir-gym bench wrappers [--num-envs 64] [--steps 100] [--estimator ekf]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import gymnasium as gym

from .. import VECTOR_ENV_IDS
from ..tables import format_table
from ..wrappers import VectorEstimatorObservation
from ._timing import per_call, vector_stepper


def _time(envs: gym.vector.VectorEnv, steps: int, repeats: int) -> float:
    """Seconds per sub-env step."""
    return per_call(vector_stepper(envs), steps, repeats, warmup=5) / envs.num_envs


def run(num_envs: int = 64, steps: int = 100, repeats: int = 5, estimator: str = "ekf"
        ) -> list[list[object]]:
    rows = []
    for env_id in VECTOR_ENV_IDS:
        for mode in ("sync", "vector_entry_point"):
            bare = _time(gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode),
                         steps, repeats)
            wrapped = _time(VectorEstimatorObservation(
                gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode), estimator),
                steps, repeats)
            row: list[object] = [env_id, "native" if mode == "vector_entry_point" else mode,
                                 1e6 * bare, 1e6 * wrapped, wrapped / bare]
            rows.append(row)
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="fir-gym bench wrappers",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--estimator", default="ekf")
    args = parser.parse_args(argv)
    rows = run(args.num_envs, args.steps, args.repeats, args.estimator)
    print(f"\n{args.estimator} across {args.num_envs} sub-envs: µs per sub-env step "
          "(target ratio ≤ 1.2)\n")
    print(format_table(["env", "vector env", "bare", f"with batched {args.estimator}",
                        "ratio"], rows, floatfmt=".3g"))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
