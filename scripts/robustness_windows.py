"""The windowed filters' window for the robustness benchmark: the LQG's closed-loop return and
the estimation RMSE of the extended FIR filter with windows of 10, 20 and 50 measurements
(and the open-loop or re-anchored nominal) on every plant, nominal and under a stuck sensor,
100 episodes each — the numbers behind docs/robustness.md#estimator-settings.

    python scripts/robustness_windows.py [--episodes 100] [--windows 10,20,50]
"""

from __future__ import annotations

import argparse
import warnings

import gymnasium as gym
import numpy as np

from fir_gym.conditions import condition_setup
from fir_gym.controllers import LQGController
from fir_gym.robustness.closed_loop import build_env, play
from fir_gym.robustness.lqg_grid import ControllerPolicy
from fir_gym.robustness.plan import EVAL_SEED, PLANTS, episode_steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--windows", default="10,20,50")
    args = parser.parse_args()
    windows = [int(w) for w in args.windows.split(",")]
    warnings.simplefilter("ignore")
    print("| plant | condition | window | nominal | LQG return | RMSE per state | diverged |")
    print("|---|---|---|---|---|---|---|")
    for env_id, plan in PLANTS.items():
        plant = gym.make(env_id, **plan.env_kwargs).unwrapped
        for condition, strength in (("nominal", 0.0), ("stuck", 0.02)):
            setup = condition_setup(condition, strength, plant, episode_steps(env_id))
            for window in windows:
                for nominal in ("open-loop", "reanchor"):
                    venv = build_env(env_id, args.episodes, "efir", setup,
                                     env_kwargs=plan.env_kwargs,
                                     estimator_kwargs={"horizon": window, "nominal": nominal})
                    ep = play(venv, ControllerPolicy(LQGController(venv)), EVAL_SEED)
                    rmse = ", ".join(f"{v:.3g}" for v in np.asarray(ep.rmse))
                    diverged = float(np.mean(ep.diverged)) if ep.diverged is not None else 0.0
                    print(f"| {env_id.split('/')[-1]} | {condition} | {window} | {nominal} | "
                          f"{np.mean(ep.returns):.4g} | {rmse} | {diverged:.2f} |", flush=True)


if __name__ == "__main__":
    main()
