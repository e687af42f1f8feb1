"""A scripted benchmark episode: five estimators on the same episode of paper 002's plant.

    python examples/benchmark_episode.py [--steps 100] [--seed 0]

VanDerPol-v0 (paper 002's Van der Pol oscillator) under zero force. Each estimator runs
in its own env made with the same seed, so the plant's trajectory and measurements are
the same for all of them (checked below); the table gives each one's RMSE per state and
whether it flagged divergence: the discrete EKF and UKF, the extended FIR filter (at the
plant's default horizon), and paper 002's pair, the continuous-discrete EKF and the
block-pulse Kalman filter. ``fir-gym reproduce --paper 002`` runs the paper's Monte
Carlo experiment.
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym
import numpy as np

#: registry name -> its options (none: each takes the plant's prior and default horizon)
ESTIMATORS: dict[str, dict] = {"ekf": {}, "ukf": {}, "efir": {}, "cd-ekf": {}, "bpf-kf": {}}


def episode(name: str, options: dict, steps: int, seed: int) -> dict:
    env = gym.make("fir_gym:fir_gym/VanDerPol-v0", estimator=name,
                   estimator_kwargs=options)
    _, info = env.reset(seed=seed)
    truth, errors, diverged = [info["state"]], [info["estimation_error"]], False
    plant: Any = env.unwrapped
    zero = np.zeros(plant.action_space.shape, dtype=np.float32)
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(zero)
        truth.append(info["state"])
        errors.append(info["estimation_error"])
        diverged |= bool(info["estimator_diverged"])
        if terminated or truncated:
            break
    env.close()
    e = np.array(errors)
    return {"truth": np.array(truth), "rmse": np.sqrt(np.mean(e**2, axis=0)),
            "diverged": diverged, "names": plant.state_names}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100, help="steps (the episode is 100)")
    parser.add_argument("--seed", type=int, default=0, help="the episode's seed")
    args = parser.parse_args(argv)

    results = {name: episode(name, opts, args.steps, args.seed)
               for name, opts in ESTIMATORS.items()}
    first = next(iter(results.values()))
    for name, r in results.items():          # the same plant trajectory for every estimator
        assert np.array_equal(r["truth"], first["truth"]), f"{name} saw another episode"
    names = first["names"]
    print(f"VanDerPol-v0, seed {args.seed}, {len(first['truth']) - 1} steps, "
          "zero force: RMSE per state")
    print(f"{'estimator':10s}" + "".join(f"{n:>12s}" for n in names) + "   diverged")
    for name, r in results.items():
        print(f"{name:10s}" + "".join(f"{v:12.4g}" for v in r["rmse"])
              + f"   {'yes' if r['diverged'] else 'no'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
