"""Every speed figure of fir-gym in one run, as ratios to references timed in the same run.

``fir-gym speed [SECTION ...] [--json PATH] [--quick]`` (or
``python scripts/bench_speed.py ...``; sections ``kalman estimators envs wrappers training
fir``, default all; ``fir-gym bench`` is the same command under its old name) prints:

1. **kalman** — KF, EKF and UKF on two models (2-state/1-output linear,
   4-state/2-output nonlinear), single system and batched at B = 1024, on consistent
   data and on mismatched data (ten times the model's noise: the divergence flag is
   raised and stays raised), beside filterpy's filters on the same models and data:
   ours / filterpy per step and the batched throughput over looping filterpy; the
   EFIR (n = 3, N = 10, paper 000's sim 2) against the EKF on the same model, and
   batched; ``Estimator.step``'s fixed cost (:mod:`.kalman_speed`).
2. **estimators** — every registered estimator on every plant's model where it
   applies: µs per step of one system, and per system-step at B = 1, 64, 1024 and
   16384 (a batch of one is the general batched code; "single" is one system given
   as ``(n_y,)``), with the batched speed-up over the single system.
3. **envs** — steps per second of every plant (unwrapped, through ``gym.make``,
   Gymnasium's sync vector env, the native vector env at 64 and 1024 sub-envs) and
   Gymnasium's references (``CartPole-v1`` single, sync and native vector;
   ``InvertedPendulum-v5``): PendulumSlider-v0 / InvertedPendulum-v5 (target ≥ 1)
   and native / sync vector speed-ups (VanDerPol-v0 at 1024 envs: target ≥ 100).
4. **wrappers** — ``EstimatorObservation`` with an EKF over one env and
   ``VectorEstimatorObservation`` with a batched EKF over 64 sub-envs of the sync
   and the native vector env: wrapped / bare step time (targets ≤ 1.2 over the sync and
   ≤ 1.3 over the native vector env).
5. **targets** — the targets, measured, met or not, with the ceiling a floor
   measured in the same run allows (:mod:`.targets`, floors in :mod:`._floors`);
   section 1 also prints each batched filter's gain over its own numpy path (the
   compiled kernels off).
6. **training** — stable-baselines3 on the batched plants (:mod:`.training`; needs the
   ``rl`` extra) and, with the ``jax`` extra, the JAX backend against it: PPO and raw
   stepping of Orbit-v0 with its EKF (:mod:`.jax_training`).
7. **fir** — the FIR gains' cost against the horizon ``N`` (two-stage recursion, batch
   formula, time-varying filter step) with fitted exponents (:func:`.fir.growth`).

Every figure is the best of a few timed blocks (the least disturbed by other load
on the machine); compare ratios from one run, not times across runs. Set
``OPENBLAS_NUM_THREADS=1``: multi-threaded BLAS on tiny matrices only adds noise.
The default run takes about two minutes; ``--quick`` about a tenth of that.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.estimators import compiled

from .. import ENV_IDS, VECTOR_ENV_IDS
from ..machine import cpu_model
from ..tables import format_table
from . import SECTIONS, _floors, speed_parser
from . import estimators as est_bench
from . import fir as fir_bench
from . import training as training_bench
from ._timing import env_stepper, interleaved, stepper, vector_stepper
from .kalman_speed import kalman_section, print_kalman
from .targets import print_targets, ratio, targets


# ---------------------------------------------------------------------------- 2. estimators
def print_estimators(rows: list[dict[str, Any]]) -> None:
    print("\n2.", end="")
    est_bench.print_table(rows)


# ---------------------------------------------------------------------------- 3. envs
def envs_section(quick: bool) -> dict[str, Any]:
    """Steps per second of every plant and of Gymnasium's references (alternating blocks)."""
    steps, reps = (200, 3) if quick else (1000, 6)
    vsteps = 5 if quick else 20
    out: dict[str, Any] = {"plants": [], "references": [], "pendulum": []}

    def measure(env_id: str, native: bool, **kw: Any) -> dict[str, Any]:
        runs: dict[str, tuple[Callable[[], Any], int]] = {
            "unwrapped": (stepper(env_id, **kw), steps),
            "make": (stepper(env_id, unwrap=False, **kw), steps)}
        if native:
            runs["sync64"] = (vector_stepper(gym.make_vec(env_id, num_envs=64,
                                                           vectorization_mode="sync")), vsteps)
            for n in (64, 1024):
                runs[f"native{n}"] = (vector_stepper(gym.make_vec(
                    env_id, num_envs=n, vectorization_mode="vector_entry_point")),
                    max(2, vsteps * 64 // n) if n > 64 else vsteps)
        if env_id.endswith("VanDerPol-v0") and native:   # the floor: its Wiener increments
            draws = np.random.default_rng(0)
            plant: Any = gym.make(env_id).unwrapped
            substeps = plant.params["substeps"]
            runs["wiener1024"] = (lambda: draws.standard_normal((substeps, 1024)),
                                  max(2, vsteps // 16))
        t = interleaved(runs, reps)
        row: dict[str, Any] = {"env": env_id}
        for key, sec in t.items():                       # per (sub-)env step
            vec = key.startswith(("sync", "native", "wiener"))
            n = int(key.removeprefix("sync").removeprefix("native").removeprefix("wiener")) \
                if vec else 1
            row[f"{key}_us"] = 1e6 * sec / n
        return row

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for env_id in ENV_IDS:
            out["plants"].append(measure(env_id, env_id in VECTOR_ENV_IDS))
        try:
            out["references"].append(measure("CartPole-v1", True))
        except Exception as err:
            out["references"].append({"env": "CartPole-v1", "error": str(err)})
        runs = {f: (stepper("fir_gym/PendulumSlider-v0", friction=f), steps)
                for f in ("none", "coulomb", "paper")}
        for f in ("coulomb", "paper"):                   # the floor: MuJoCo's own steps
            runs[f"mujoco_{f}"] = (_floors.mujoco_stepper(f), steps)
        try:
            runs["ip"] = (stepper("InvertedPendulum-v5"), steps)
        except Exception as err:  # gymnasium[mujoco] needs imageio
            out["references"].append({"env": "InvertedPendulum-v5", "error": str(err)})
        times = interleaved(runs, 2 * reps)              # alternating: a fair ratio
        ip = 1e6 * times["ip"] if "ip" in times else None
        if ip is not None:
            out["references"].append({"env": "InvertedPendulum-v5", "unwrapped_us": ip})
        for friction in ("none", "coulomb", "paper"):
            ours = 1e6 * times[friction]
            physics = times.get(f"mujoco_{friction}")
            out["pendulum"].append({"friction": friction, "us": ours,
                                    "inverted_pendulum_us": ip,
                                    "steps_per_s_ratio": ratio(ip, ours),
                                    "mujoco_us": None if physics is None else 1e6 * physics})
    return out


def print_envs(res: dict[str, Any]) -> None:
    print("\n3. environments: µs per (sub-)env step and ratios of steps per second\n")
    rows = []
    for r in res["plants"] + [r for r in res["references"] if "error" not in r]:
        rows.append([r["env"].removeprefix("fir_gym/"), r.get("unwrapped_us"), r.get("make_us"),
                     r.get("sync64_us"), r.get("native64_us"), r.get("native1024_us"),
                     ratio(r.get("unwrapped_us"), r.get("make_us")),
                     ratio(r.get("sync64_us"), r.get("native64_us")),
                     ratio(r.get("sync64_us"), r.get("native1024_us"))])
    print(format_table(["env", "unwrapped", "gym.make", "sync×64", "native×64", "native×1024",
                        "make/unwrapped speed", "native/sync ×64", "native/sync ×1024"], rows,
                       floatfmt=".3g"))
    for r in res["references"]:
        if "error" in r:
            print(f"   {r['env']}: unavailable ({r['error']})")
    print("\n   PendulumSlider-v0 against InvertedPendulum-v5 (steps/s ratio, target ≥ 1)\n")
    print(format_table(["friction", "µs/step", "InvertedPendulum-v5 µs/step", "steps/s ratio"],
                       [[p["friction"], p["us"], p["inverted_pendulum_us"],
                         p["steps_per_s_ratio"]] for p in res["pendulum"]], floatfmt=".3g"))


# ---------------------------------------------------------------------------- 4. wrappers
def wrappers_section(quick: bool) -> dict[str, Any]:
    """Wrapped against bare step time, in alternating blocks."""
    from ..wrappers import EstimatorObservation, VectorEstimatorObservation

    steps, reps = (200, 3) if quick else (1000, 6)
    vsteps = 10 if quick else 40
    single, vector = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for env_id in ENV_IDS:
            wrapped_env = EstimatorObservation(gym.make(env_id).unwrapped, "ekf")
            t = interleaved({"bare": (stepper(env_id), steps),
                             "wrapped": (env_stepper(wrapped_env), steps)}, reps)
            single.append({"env": env_id, "bare_us": 1e6 * t["bare"],
                           "wrapped_us": 1e6 * t["wrapped"], "ratio": t["wrapped"] / t["bare"]})
        for env_id in VECTOR_ENV_IDS:
            for mode in ("sync", "vector_entry_point"):
                bare = gym.make_vec(env_id, num_envs=64, vectorization_mode=mode)
                wrapped = VectorEstimatorObservation(
                    gym.make_vec(env_id, num_envs=64, vectorization_mode=mode), "ekf")
                t = interleaved({"bare": (vector_stepper(bare), vsteps),
                                 "wrapped": (vector_stepper(wrapped), vsteps),
                                 "fixed": (_floors.trivial_ekf_step(64), vsteps),
                                 "model": (_floors.model_evaluation(wrapped.estimator), vsteps)},
                                reps)
                b, w = 1e6 * t["bare"] / 64, 1e6 * t["wrapped"] / 64
                vector.append({"env": env_id, "mode": "native" if mode != "sync" else "sync",
                               "bare_us": b, "wrapped_us": w, "ratio": w / b, "ekf_us": w - b,
                               "ekf_floor_us": 1e6 * (t["fixed"] + t["model"]) / 64})
                bare.close()
                wrapped.close()
    return {"single": single, "vector": vector}


def print_wrappers(res: dict[str, Any]) -> None:
    print("\n4. estimator in the loop: wrapped / bare step time\n")
    print(format_table(["env", "bare µs/step", "EstimatorObservation(ekf) µs/step", "ratio"],
                       [[r["env"].removeprefix("fir_gym/"), r["bare_us"], r["wrapped_us"],
                         r["ratio"]] for r in res["single"]], floatfmt=".3g"))
    print("\n   VectorEstimatorObservation, batched EKF over 64 sub-envs: µs per sub-env step "
          "(target ratio ≤ 1.2 sync, ≤ 1.3 native)\n")
    print(format_table(["env", "vector env", "bare", "wrapped", "EKF share", "ratio"],
                       [[r["env"].removeprefix("fir_gym/"), r["mode"], r["bare_us"],
                         r["wrapped_us"], r["ekf_us"], r["ratio"]] for r in res["vector"]],
                       floatfmt=".3g"))


# ---------------------------------------------------------------------------- 7. fir
def print_fir(res: dict[str, Any]) -> None:
    print("\n7. ", end="")
    fir_bench.print_growth(res)


# ---------------------------------------------------------------------------- main
Runner = tuple[Callable[[bool], Any], Callable[[Any], None]]
RUNNERS: dict[str, Runner] = {"kalman": (kalman_section, print_kalman),
                              "estimators": (est_bench.run, print_estimators),
                              "envs": (envs_section, print_envs),
                              "wrappers": (wrappers_section, print_wrappers),
                              "training": (training_bench.run, training_bench.print_results),
                              "fir": (fir_bench.growth_section, print_fir)}


def run(sections: Sequence[str] = SECTIONS, quick: bool = False, echo: bool = True
        ) -> dict[str, Any]:
    """Run the chosen sections; returns every figure (what ``--json`` writes)."""
    results: dict[str, Any] = {"machine": {
        "cpu": cpu_model(), "python": platform.python_version(), "numpy": np.__version__,
        "platform": platform.platform(), "cpus": os.cpu_count(),
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
        "compiled_kernels": (f"numba {compiled.numba.__version__}" if compiled.ENABLED
                             else "off (numpy paths)"),
        "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None}}
    start = time.perf_counter()
    for name in sections:
        measure, show = RUNNERS[name]
        results[name] = measure(quick)
        if echo:
            show(results[name])
            sys.stdout.flush()
    results["targets"] = targets(results)
    results["seconds"] = time.perf_counter() - start
    if echo:
        print_targets(results["targets"])
        machine = results["machine"]
        print(f"\n({results['seconds']:.0f} s on {machine['cpu']}, {machine['cpus']} CPUs; "
              "compiled kernels: "
              f"{results['machine']['compiled_kernels']}; load average at start "
              f"{results['machine']['load_average']})")
    return results


def main(argv: Sequence[str] | None = None) -> int:
    """``fir-gym speed [SECTION ...] [--quick] [--json PATH]`` (:func:`speed_parser`)."""
    parser = speed_parser()
    args = parser.parse_args(argv)
    chosen = [args.sections] if isinstance(args.sections, str) else args.sections
    sections = [name for name in SECTIONS if name in chosen or "all" in chosen]
    results = run(sections, args.quick, echo=args.json != "-")
    if args.json:
        text = json.dumps(results, indent=1, default=_jsonable)
        if args.json == "-":
            print(text)
        else:
            with open(args.json, "w", encoding="utf-8") as fh:
                fh.write(text + "\n")
            print(f"wrote {args.json}")
    return 0


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
