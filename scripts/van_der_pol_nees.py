#!/usr/bin/env python
"""The EKF's closed-loop NEES on VanDerPol-v0, per step: its mean, median, tail and χ² band.

Twenty episodes (seeds 0–19) of 100 steps of ``gym.make("fir_gym/VanDerPol-v0",
estimator="ekf")`` under zero action or under the LQG controller on the EKF's estimate
(``fir_gym.controllers.LQGController``); at every step, the reset step included, the NEES
``(x − x̂)ᵀ P⁻¹ (x − x̂)`` and the smallest eigenvalue of ``P``. The summary is
:func:`fir_gym.estimators.metrics.nees_summary`: mean (ANEES, not divided by ``n_x``),
median, 95th percentile and the fraction of steps inside the two-sided 95 % χ²(2) band.
The smallest eigenvalue is over the steps after the first (step 0's ``P`` is the
wrapper's prior, ``1e-9 I``: the initial state is known exactly).

``--candidates`` runs the EKF with each candidate process noise of its model (the plant,
the truth, is never changed): the first-order rank-one ``Q h g gᵀ``, ``g = [1, 1]ᵀ``, and
the integrated noise ``Q_d(x) = ∫₀ʰ e^{J(x) s} g Q gᵀ e^{J(x)ᵀ s} ds`` of the
linearisation ``J(x)`` at the origin, or averaged over one period of the noise-free limit
cycle, over the states of zero-action episodes, or over the states of LQG episodes (held-out
seeds 1000–1019) — docs/envs/van-der-pol.md#process-noise.

    python scripts/van_der_pol_nees.py [--candidates] [--seeds 20]
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym
import numpy as np

import fir_gym  # noqa: F401
from fir_gym.controllers import LQGController
from fir_gym.envs.van_der_pol import (
    NOISE_INPUT,
    limit_cycle_states,
    van_der_pol_continuous_model,
)
from fir_gym.estimators import StateSpaceModel
from fir_gym.estimators.metrics import nees, nees_summary
from fir_gym.tables import format_table

ENV_ID = "fir_gym/VanDerPol-v0"
CONTROLLERS = ("zero", "lqg")


def closed_loop(model: StateSpaceModel | None = None, controller: str = "zero",
                seeds: range = range(20), steps: int = 100) -> dict[str, np.ndarray]:
    """Per-step NEES, smallest eigenvalue of ``P``, step index and true state, EKF in the loop.

    ``model`` replaces the EKF's model (same sizes; the plant is unchanged); ``None``
    keeps the plant's own :attr:`model`.
    """
    env = gym.make(ENV_ID, estimator="ekf", max_episode_steps=steps)
    estimator: Any = env.get_wrapper_attr("estimator")
    if model is not None:
        estimator.model = model
    policy = LQGController(env) if controller == "lqg" else None
    values, eigs, ks, states = [], [], [], []

    def record(info: dict[str, Any], k: int) -> None:
        P = estimator.P
        values.append(float(nees(info["state"], info["estimate"], P)))
        eigs.append(float(np.linalg.eigvalsh(P)[0]))
        ks.append(k)
        states.append(info["state"])

    for seed in seeds:
        obs, info = env.reset(seed=seed)
        k = 0
        record(info, k)
        while True:
            action = np.zeros(1) if policy is None else policy.predict(obs)[0]
            obs, _, terminated, truncated, info = env.step(action)
            k += 1
            record(info, k)
            if terminated or truncated:
                break
    env.close()
    return {"nees": np.array(values), "min_eig": np.array(eigs), "step": np.array(ks),
            "state": np.array(states)}


def candidates(seeds: range = range(1000, 1020)) -> dict[str, StateSpaceModel]:
    """The EKF's model with each candidate process noise (see the module docstring)."""
    plant: Any = gym.make(ENV_ID).unwrapped
    model: StateSpaceModel = plant.model
    p = plant.nominal_params
    cm = van_der_pol_continuous_model(p)

    def mean_noise(states: np.ndarray) -> np.ndarray:
        return np.asarray(np.mean(cm.integrated_noise(states), axis=0))

    first_order = model.replace(G=NOISE_INPUT.reshape(2, 1), Q=p["Q"] * p["h"])
    noises = {
        "Van Loan at the origin": cm.integrated_noise(np.zeros(2)),
        "Van Loan, mean over the limit cycle": mean_noise(limit_cycle_states(p["epsilon"])),
        "Van Loan, mean over zero-action states": mean_noise(
            closed_loop(None, "zero", seeds)["state"]),
        "Van Loan, mean over LQG states": mean_noise(closed_loop(None, "lqg", seeds)["state"]),
    }
    return {"first order Q h g gᵀ (rank one)": first_order,
            **{name: model.replace(G=np.eye(2), Q=Q) for name, Q in noises.items()}}


def row(name: str, controller: str, out: dict[str, np.ndarray]) -> list[Any]:
    s = nees_summary(out["nees"], dof=2)
    later = out["step"] > 0
    return [name, controller, s.mean, s.median, s.p95, s.in_band,
            float(out["min_eig"][later].min()), int(out["step"][np.argmax(out["nees"])])]


HEADERS = ["model noise", "controller", "mean NEES", "median", "95th pct", "in 95 % band",
           "min eig P (k ≥ 1)", "step of max"]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--candidates", action="store_true",
                        help="every candidate process noise (default: the plant's model)")
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args(argv)
    seeds = range(args.seeds)
    models: dict[str, StateSpaceModel | None] = (
        dict(candidates()) if args.candidates else {"the plant's model": None})
    if args.candidates:
        for name, m in models.items():
            assert m is not None
            print(f"{name}: G Q Gᵀ = {np.array2string(m.GQGT, precision=4)}")
    rows = [row(name, c, closed_loop(m, c, seeds)) for name, m in models.items()
            for c in CONTROLLERS]
    s = nees_summary(np.ones(1), dof=2)
    print(f"χ²(2): mean 2, median {s.expected_median:.3g}, 95th pct {s.expected_p95:.3g}, "
          f"95 % band [{s.band[0]:.3g}, {s.band[1]:.3g}]; {len(seeds)} seeds × 101 steps")
    print(format_table(HEADERS, rows))


if __name__ == "__main__":
    main()
