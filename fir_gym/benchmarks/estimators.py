"""Every registered estimator on every plant's model: µs per step, single and batched.

``fir-gym bench estimators [--quick]`` (also section 2 of ``fir-gym speed``): for each
plant and each estimator that accepts its model (FIR family with ``horizon = 10``, the
plant's initial-state prior), µs per step of one system given as ``(n_y,)`` and µs per
system-step at B = 1, 64, 1024 and 16384 (a batch of one runs the general batched
code), on measurements of one rollout of the plant (a little extra noise per system).
"""

from __future__ import annotations

import argparse
import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from .. import ENV_IDS
from ..tables import format_table
from ._timing import best_time

BATCHES = (1, 64, 1024, 16384)
HORIZON = 10                                     # FIR-family option


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b == 0 else a / b


def _applicable(env: gym.Env) -> list[tuple[str, Any, dict[str, Any]]]:
    """(name, model, options) of every registered estimator that accepts this plant."""
    from fir_gym.estimators import estimator_class, estimator_names
    from fir_gym.wrappers.estimator_observation import default_prior

    plant = env.unwrapped
    x0, P0 = default_prior(env)
    out = []
    for name in estimator_names():
        cls = estimator_class(name)
        model = getattr(plant, cls.model_attribute, None)
        if model is None:
            continue
        opts: dict[str, Any] = {"x0": x0, "P0": P0} if x0 is not None else {}
        if "fir" in name:
            opts["horizon"] = HORIZON
        try:
            cls(model, **opts)
        except (TypeError, ValueError):
            continue
        out.append((name, model, opts))
    return out


def _rollout(env_id: str, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Measurements ``(steps, n_y)`` and applied actions of one episode under small random
    actions (restarted where an episode ends)."""
    env = gym.make(env_id)
    rng = np.random.default_rng(0)
    y, _ = env.reset(seed=0)
    Y, U = [y], [np.zeros(env.action_space.shape or ())]
    while len(Y) < steps:
        a = 0.3 * rng.uniform(-1, 1, size=env.action_space.shape)
        y, _, term, trunc, info = env.step(a)
        if term or trunc:
            break
        Y.append(y)
        U.append(info["action"])
    env.close()
    return np.array(Y), np.array(U)


def _time_estimator(cls: type, model: Any, opts: dict[str, Any], Y: np.ndarray, U: np.ndarray,
                    batch: int | None, budget: float) -> float | None:
    """µs per system-step (``batch`` None: one system given as ``(n_y,)``)."""
    rng = np.random.default_rng(1)
    if batch is None:
        ys, us = Y, U
    else:                       # the rollout, with a little extra noise per system
        K = len(Y) if batch < 1024 else min(len(Y), 32)
        sd = np.sqrt(np.diag(np.atleast_2d(model.R)))
        ys = Y[:K, None, :] + 0.1 * sd * rng.standard_normal((K, batch, Y.shape[1]))
        us = np.ascontiguousarray(np.broadcast_to(U[:K, None, :], (K, batch, U.shape[1])))
    K = len(ys)
    flt = cls(model, **opts)
    warm = min(K - 1, HORIZON + 2)
    for k in range(warm):
        flt.step(ys[k], None if k == 0 else us[k])
    state = {"k": warm}

    def step() -> None:
        k = state["k"]
        flt.step(ys[k], us[k])
        state["k"] = k + 1 if k + 1 < K else warm

    try:
        return 1e6 * best_time(step, budget, repeats=3, max_calls=5000) / (batch or 1)
    except Exception as err:  # a filter that fails is reported, not fatal
        warnings.warn(f"{cls.__name__} on {model!r}: {err}", stacklevel=2)
        return None


def run(quick: bool) -> list[dict[str, Any]]:
    from fir_gym.estimators import estimator_class

    budget = 0.01 if quick else 0.05
    batches = (1, 64, 1024) if quick else BATCHES
    rows = []
    for env_id in ENV_IDS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            env = gym.make(env_id)
            Y, U = _rollout(env_id, 48 if quick else 120)
        for name, model, opts in _applicable(env):
            cls = estimator_class(name)
            row: dict[str, Any] = {"env": env_id, "estimator": name,
                                   "single_us": _time_estimator(cls, model, opts, Y, U, None,
                                                                budget)}
            for b in batches:
                # a big batch of a slow filter: a few steps are enough
                row[f"B{b}_us"] = _time_estimator(cls, model, opts, Y, U, b,
                                                  budget * (1 + np.log2(b) / 4))
            rows.append(row)
        env.close()
    return rows


def print_table(rows: list[dict[str, Any]]) -> None:
    if not rows:
        return
    batches = [int(k[1:-3]) for k in rows[0] if k.startswith("B") and k.endswith("_us")]
    print("\nevery estimator on every plant's model: µs per system-step "
          "(speed-up = single / largest batch)\n")
    headers = ["env", "estimator", "single"] + [f"B={b}" for b in batches] + [
        "B=1/single", f"speed-up B={batches[-1]}"]
    table = []
    for r in rows:
        big = r[f"B{batches[-1]}_us"]
        table.append([r["env"].removeprefix("fir_gym/"), r["estimator"], r["single_us"]]
                     + [r[f"B{b}_us"] for b in batches]
                     + [_ratio(r["B1_us"], r["single_us"]), _ratio(r["single_us"], big)])
    print(format_table(headers, table, floatfmt=".3g"))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="fir-gym bench estimators",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    print_table(run(parser.parse_args(argv).quick))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
