"""Speed of the plants: steps per second, and ratios against references timed in the same run.

* every plant, single env: µs per step;
* PendulumSlider-v0 (each friction mode) against Gymnasium's InvertedPendulum-v5
  (another one-cart pendulum in MuJoCo): the ratio of steps per second, target ≥ 1;
* the native vector envs against Gymnasium's sync vector env at 64 sub-envs.

Each figure is the best of ``repeats`` timings (the minimum is the least disturbed
by other load); only ratios measured in one run should be compared.

    fir-gym bench envs [--steps N] [--repeats R]
"""

from __future__ import annotations

import argparse
import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym

from .. import ENV_IDS, VECTOR_ENV_IDS
from ..tables import format_table
from ._timing import per_call, stepper, vector_stepper


def time_single(env_id: str, steps: int, repeats: int, **kwargs: Any) -> float:
    """Seconds per step of one unwrapped env (reset when an episode ends)."""
    return per_call(stepper(env_id, **kwargs), steps, repeats, warmup=steps)


def time_vector(env_id: str, mode: str, num_envs: int, steps: int, repeats: int) -> float:
    """Seconds per sub-env step of a vector env."""
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode)
    seconds = per_call(vector_stepper(envs), steps, repeats, warmup=steps) / num_envs
    envs.close()
    return seconds


def run(steps: int = 2000, repeats: int = 5) -> list[tuple[str, list[str], list[list[object]]]]:
    """The three tables of this benchmark: (title, headers, rows)."""
    tables = []
    rows = [[env_id, 1e6 * time_single(env_id, steps, repeats)] for env_id in ENV_IDS]
    tables.append(("single env", ["env", "µs/step"], rows))

    rows = []
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reference = time_single("InvertedPendulum-v5", steps, repeats)
    except Exception as err:  # gymnasium[mujoco] needs imageio: the `bench` extra
        reference = None
        rows.append(["InvertedPendulum-v5", f"unavailable: {err}", None, None])
    for friction in ("none", "coulomb", "paper"):
        ours = time_single("fir_gym/PendulumSlider-v0", steps, repeats, friction=friction)
        rows.append([f"PendulumSlider-v0 ({friction})", 1e6 * ours,
                     None if reference is None else 1e6 * reference,
                     None if reference is None else reference / ours])
    tables.append(("PendulumSlider-v0 vs InvertedPendulum-v5 (target ratio ≥ 1)",
                   ["env", "µs/step", "InvertedPendulum-v5 µs/step", "steps/s ratio"], rows))

    rows = []
    for env_id in VECTOR_ENV_IDS:
        sync = time_vector(env_id, "sync", 64, max(20, steps // 40), repeats)
        native = time_vector(env_id, "vector_entry_point", 64, max(20, steps // 40), repeats)
        rows.append([env_id, 1e6 * sync, 1e6 * native, sync / native])
    tables.append(("vector envs, 64 sub-envs (µs per sub-env step)",
                   ["env", "sync", "native", "speed-up"], rows))
    return tables


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="fir-gym bench envs", description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    for title, headers, rows in run(args.steps, args.repeats):
        print(f"\n{title}\n")
        print(format_table(headers, rows, floatfmt=".3g"))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
