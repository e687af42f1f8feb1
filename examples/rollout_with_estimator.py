"""Estimator in the loop: an EKF on Orbit-v0, its error beside the truth, a figure and a video.

    python examples/rollout_with_estimator.py [--steps 200] [--seed 0] [--out examples-output]

Writes ``OUT/orbit_ekf.png`` (estimate ± 2σ against the truth, per state) and
``OUT/orbit_ekf.gif`` (the estimate drawn over the plant's frames; needs the ``video``
extra: ``pip install ".[video]"``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200, help="steps to roll out")
    parser.add_argument("--seed", type=int, default=0, help="the episode's seed")
    parser.add_argument("--out", default="examples-output", help="output folder")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    # The "fir_gym:" prefix imports fir_gym (which registers its ids) before the lookup.
    env = gym.make("fir_gym:fir_gym/Orbit-v0", estimator="ekf")
    _, info = env.reset(seed=args.seed)
    truth, estimates, covariances = [info["state"]], [info["estimate"]], []
    plant: Any = env.unwrapped
    estimator = env.get_wrapper_attr("estimator")
    covariances.append(estimator.P.copy())
    for _ in range(args.steps):
        action = np.zeros(plant.action_space.shape, dtype=np.float32)   # zero thrust
        _, _, terminated, truncated, info = env.step(action)
        if info["estimator_diverged"]:
            print("the EKF diverged; stopping")
            break
        truth.append(info["state"])
        estimates.append(info["estimate"])
        covariances.append(estimator.P.copy())
        if terminated or truncated:
            break
    env.close()

    x, x_hat = np.array(truth), np.array(estimates)
    rmse = np.sqrt(np.mean((x - x_hat) ** 2, axis=0))
    names = plant.state_names
    print(f"{len(x) - 1} steps; EKF RMSE " + ", ".join(
        f"{n} {v:.3g}" for n, v in zip(names, rmse, strict=True)))

    from fir_gym.plotting import plot_estimates

    dt = float(plant.time_step)
    fig = plot_estimates(dt * np.arange(len(x)), x_hat, x, np.array(covariances),
                         names=names, label="EKF")
    fig.savefig(out / "orbit_ekf.png")
    print(f"wrote {out / 'orbit_ekf.png'}")

    from fir_gym.video import watch

    rec = watch("fir_gym/Orbit-v0", out / "orbit_ekf.gif", estimator="ekf",
                steps=args.steps, seed=args.seed, every=5)
    print(f"wrote {rec.path}: {rec.frames} frames")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
