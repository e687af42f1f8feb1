"""Training on estimates: PPO on a Kalman filter's estimate of CarrierMotion-v0, beside LQG.

    python examples/train_on_estimates.py [--steps 2048] [--episodes 5] [--out examples-output]

Needs the ``rl`` extra: ``pip install torch==2.13.0 && pip install ".[rl]"``. The
controller sees the KF's estimate (``observation_kind="kf"``); the classical baseline is
the LQR of the plant's nominal model on the same estimate (``"lqg"``). The default budget
is a demonstration, not a trained controller: ``fir-gym compare-controllers`` runs the
real comparison over seeds.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2048, help="training timesteps")
    parser.add_argument("--episodes", type=int, default=5, help="evaluation episodes")
    parser.add_argument("--episode-steps", type=int, default=100,
                        help="steps per episode (the plant's max_episode_steps)")
    parser.add_argument("--out", default="examples-output", help="output folder")
    args = parser.parse_args(argv)

    from fir_gym.training import RunConfig, evaluate, train

    env_kwargs = {"max_episode_steps": args.episode_steps}
    config = RunConfig(env_id="fir_gym/CarrierMotion-v0", observation_kind="kf",
                       steps=args.steps, seed=0, n_envs=1, env_kwargs=env_kwargs)
    run = train(config, Path(args.out) / "carrier-kf")
    learned = evaluate(run, episodes=args.episodes)
    lqg = evaluate(RunConfig(env_id="fir_gym/CarrierMotion-v0", observation_kind="lqg",
                             kind_kwargs={"estimator": "kf"}, env_kwargs=env_kwargs),
                   episodes=args.episodes)
    for label, result in (("PPO on the KF estimate", learned), ("LQG (KF + LQR)", lqg)):
        rmse = ", ".join(f"{v:.3g}" for v in result.rmse) if result.rmse is not None else "—"
        print(f"{label:24s} return {result.mean:9.4g} ± {result.std:.3g}; "
              f"estimation RMSE {rmse}")
    print(f"the run is saved in {run} (fir-gym watch --policy {run} --out run.gif)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
