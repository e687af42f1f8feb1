"""Speed of stable-baselines3 on fir-gym's batched plants (``fir-gym speed training``);
with the ``jax`` extra, also the JAX backend's against it (:mod:`.jax_training`).

Two targets, each a ratio of env-steps per second measured in the same run:

* stepping :func:`fir_gym.training.make_sb3_vec_env` (Orbit-v0, 16 sub-envs,
  ``estimator="ekf"``: the native vector env and one batched EKF) with random actions,
  against SB3's ``DummyVecEnv`` over 16 single wrapped envs (``gym.make`` with the
  EKF) — target ≥ 10;
* PPO (fir-gym's defaults: the shipped YAML's Orbit-v0 entry) training on each —
  target ≥ 3.

Beside them the floors that bound the ratios, measured in the same run:

* stepping: the bare native vector env (16 Orbit-v0 plants, same-step autoreset, no
  estimator and no SB3 bookkeeping) and the batched EKF's own step at 16 systems — what
  the fast path cannot skip — cap the ratio at ``dummy / (bare + ekf)``; the rest of the
  fast path's time (``fast − bare − ekf``) is the wrappers' (fir-gym's
  ``VectorEstimatorObservation`` and ``SB3VecEnv``), of which building the 16 per-env
  info dicts SB3's API asks for (the single env's seven keys each, from the vector
  info) is timed alone (``infos_us``);
* training: PPO's own cost per sample (the same PPO on a ``VecEnv`` whose step costs
  nothing: the rollout's forward passes and the gradient epochs, stable-baselines3 and
  torch) caps the training ratio at ``(dummy + ppo) / ppo`` — with fir-gym's default
  PPO settings below 3, so that target cannot be met by any env.
"""

from __future__ import annotations

import time
import warnings
from typing import Any, cast

import numpy as np

from ._timing import interleaved

ENV_ID = "fir_gym/Orbit-v0"
N_ENVS = 16


def _step_envs(quick: bool) -> dict[str, Any]:
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    from fir_gym.estimators import estimator_class
    from fir_gym.training import make_sb3_vec_env, make_single_env

    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1, 1, (N_ENVS, 1)).astype(np.float32) for _ in range(64)]
    fast = make_sb3_vec_env(ENV_ID, N_ENVS, estimator="ekf", seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dummy = DummyVecEnv([lambda: make_single_env(ENV_ID, estimator="ekf")
                             for _ in range(N_ENVS)])
    dummy.seed(0)
    fast.reset()
    dummy.reset()
    bare = gym.make_vec(ENV_ID, N_ENVS, vectorization_mode="vector_entry_point",
                        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    bare.reset(seed=0)
    model = getattr(gym.make(ENV_ID).unwrapped, "model")  # noqa: B009
    ekf = estimator_class("ekf")(model, x0=np.tile([7.99, 1.99], (N_ENVS, 1)), P0=np.eye(2))
    y = np.full((N_ENVS, 1), 7.99)
    ekf.step(y)
    u = np.full((N_ENVS, 1), 0.3)
    k = [0]

    def stepper(venv: Any) -> Any:
        def step() -> None:
            k[0] += 1
            venv.step(actions[k[0] % 64])
        return step

    from fir_gym.training.vec_env import _rows

    vector_info = cast(Any, fast).venv.step(actions[0])[4]    # what SB3VecEnv makes dicts of

    def infos() -> None:
        _rows(vector_info, N_ENVS)

    def ekf_step() -> None:
        ekf.step(y + 1e-3 * (k[0] % 7), u)     # consistent measurements: the lean path
        k[0] += 1

    blocks = 20 if quick else 200
    best = interleaved({"dummy": (stepper(dummy), max(5, blocks // 10)),
                        "fast": (stepper(fast), blocks),
                        "bare": (stepper(bare), blocks),
                        "ekf": (ekf_step, blocks),
                        "infos": (infos, blocks)}, repeats=3 if quick else 7)
    fast.close()
    dummy.close()
    bare.close()
    return {"dummy_us": best["dummy"] * 1e6, "fast_us": best["fast"] * 1e6,
            "ekf16_us": best["ekf"] * 1e6, "bare16_us": best["bare"] * 1e6,
            "infos_us": best["infos"] * 1e6,
            "ceiling": best["dummy"] / (best["bare"] + best["ekf"]),
            "dummy_steps_per_s": N_ENVS / best["dummy"], "fast_steps_per_s": N_ENVS / best["fast"],
            "ratio": best["dummy"] / best["fast"]}


class _FreeVecEnv:
    """A VecEnv whose step costs (almost) nothing: PPO's own cost per sample."""

    @staticmethod
    def make(observation_space: Any, action_space: Any) -> Any:
        from stable_baselines3.common.vec_env import VecEnv

        class Free(VecEnv):
            def __init__(self) -> None:
                self._obs = np.zeros((N_ENVS,) + observation_space.shape)
                self._rew = np.zeros(N_ENVS, dtype=np.float32)
                self._done = np.zeros(N_ENVS, dtype=bool)
                self._infos: list[dict[str, Any]] = [{} for _ in range(N_ENVS)]
                super().__init__(N_ENVS, observation_space, action_space)

            def reset(self) -> Any:
                return self._obs

            def step_async(self, actions: Any) -> None:
                pass

            def step_wait(self) -> Any:
                return self._obs, self._rew, self._done, [{} for _ in range(N_ENVS)]

            def close(self) -> None:
                pass

            def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
                if attr_name == "render_mode":
                    return [None] * N_ENVS
                raise AttributeError(attr_name)

            def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
                raise AttributeError(attr_name)

            def env_method(self, method_name: str, *args: Any, indices: Any = None,
                           **kwargs: Any) -> list[Any]:
                raise AttributeError(method_name)

            def env_is_wrapped(self, wrapper_class: Any, indices: Any = None) -> list[bool]:
                return [False] * N_ENVS

        return Free()


def _train_speed(quick: bool) -> dict[str, Any]:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from fir_gym.training import RunConfig, make_sb3_vec_env, make_single_env

    torch.set_num_threads(1)
    settings = RunConfig(env_id=ENV_ID, observation_kind="ekf", n_envs=N_ENVS).settings()
    kwargs = settings["algo_kwargs"]
    rollout = kwargs["n_steps"] * N_ENVS
    rollouts = 1 if quick else 3
    fast = make_sb3_vec_env(ENV_ID, N_ENVS, estimator="ekf", seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dummy = DummyVecEnv([lambda: make_single_env(ENV_ID, estimator="ekf")
                             for _ in range(N_ENVS)])
    free = _FreeVecEnv.make(fast.observation_space, fast.action_space)
    models = {}
    for name, venv in (("dummy", dummy), ("fast", fast), ("free", free)):
        models[name] = PPO(settings["policy"], VecNormalize(venv), seed=0, device="cpu",
                           verbose=0, **kwargs)
        models[name].learn(rollout)                     # warm-up: first rollout and update
    best = dict.fromkeys(models, float("inf"))
    for _ in range(1 if quick else 3):                  # alternating blocks, best of each
        for name, model in models.items():
            t0 = time.perf_counter()
            model.learn(rollout * rollouts, reset_num_timesteps=False)
            best[name] = min(best[name], (time.perf_counter() - t0) / (rollout * rollouts))
    for venv in (dummy, fast):
        venv.close()
    return {"dummy_steps_per_s": 1.0 / best["dummy"], "fast_steps_per_s": 1.0 / best["fast"],
            "ppo_own_steps_per_s": 1.0 / best["free"], "ratio": best["dummy"] / best["fast"],
            "ceiling": best["dummy"] / best["free"], "algo_kwargs": kwargs}


def run(quick: bool = False) -> dict[str, Any]:
    """Both figures (needs the ``rl`` extra; ``{"skipped": reason}`` without it), and the
    JAX backend's (:mod:`.jax_training`, with the ``jax`` extra) under ``"jax"``."""
    from . import jax_training

    try:
        import stable_baselines3  # noqa: F401
        import torch  # noqa: F401
    except ImportError as err:
        return {"skipped": f"needs the rl extra ({err.name} is missing)"}
    return {"step": _step_envs(quick), "train": _train_speed(quick),
            "jax": jax_training.run(quick)}


def print_results(res: dict[str, Any]) -> None:
    from ..tables import format_table

    print("\n6. training — stable-baselines3 on Orbit-v0 with an EKF, 16 sub-envs\n")
    if "skipped" in res:
        print(f"   skipped: {res['skipped']}")
        return
    s, t = res["step"], res["train"]
    print(format_table(
        ["what", "DummyVecEnv steps/s", "make_sb3_vec_env steps/s", "ratio", "target",
         "floor"],
        [["step, random actions", s["dummy_steps_per_s"], s["fast_steps_per_s"], s["ratio"],
          "≥ 10", f"bare native step {s['bare16_us']:.3g} µs + batched EKF step "
          f"{s['ekf16_us']:.3g} µs of {s['fast_us']:.3g} (ceiling {s['ceiling']:.3g}); "
          f"SB3's info dicts {s['infos_us']:.3g} µs"],
         ["PPO training", t["dummy_steps_per_s"], t["fast_steps_per_s"], t["ratio"], "≥ 3",
          f"PPO alone: {t['ppo_own_steps_per_s']:.4g} steps/s (ceiling {t['ceiling']:.3g})"]],
        floatfmt=".4g"))
    print("   floor: what the fast path cannot skip (the plants' own batched step and the "
          "EKF's), or PPO's own cost per sample (stable-baselines3 and torch on a VecEnv "
          "whose step is free); ceiling: the best ratio that floor allows")
    if "jax" in res:
        from . import jax_training

        jax_training.print_results(res["jax"])


def targets(res: dict[str, Any]) -> list[tuple[str, float | None, float, float | None]]:
    """``(what, measured, limit, ceiling)`` of the two targets (limits are lower bounds)."""
    if not res or "skipped" in res:
        return []
    s, t = res["step"], res["train"]
    step_ceiling = s.get("ceiling")
    from . import jax_training

    return [("make_sb3_vec_env(Orbit, 16, ekf) / DummyVecEnv steps per second",
             s["ratio"], 10.0, step_ceiling),
            ("PPO on make_sb3_vec_env / on DummyVecEnv steps per second",
             t["ratio"], 3.0, t["ceiling"]), *jax_training.targets(res.get("jax", {}))]
