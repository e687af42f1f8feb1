"""fir-gym's speed targets, judged on the results of ``fir-gym speed``.

Each row gives the measured ratio, its limit, whether it is met and — where a floor
was measured in the same run — the ceiling: the best ratio that floor allows. Where
a later target tightened an earlier one (single-system KF/EKF on the 2x1 model ≤ 0.35 ×
filterpy, UKF on the 4x2 model ≤ 0.2 ×, batched B = 1024 KF ≤ 0.1, EKF 4x2 ≤ 0.45,
UKF 4x2 ≤ 2, EFIR ≤ 1.6 µs per system-step, the vector wrapper over the native
vector env ≤ 1.3 × bare), the tighter one is the row; these also hold on
mismatched data, and the step's fixed Python cost is ≤ 4 µs.
"""

from __future__ import annotations

from typing import Any

from ..tables import format_table

#: (filter, model) -> (single / filterpy, B = 1024 µs per system-step)
KALMAN_LIMITS = {("kf", "linear 2x1"): (0.35, 0.1), ("kf-full", "linear 2x1"): (0.35, 0.5),
                 ("ekf", "linear 2x1"): (0.35, 0.5), ("ukf", "linear 2x1"): (0.5, 2.0),
                 ("ekf", "nonlinear 4x2"): (1.0, 0.45), ("ukf", "nonlinear 4x2"): (0.2, 2.0)}


def ratio(a: float | None, b: float | None) -> float | None:
    """``a / b``, or ``None`` when either is missing or ``b`` is 0."""
    return None if a is None or b is None or b == 0 else a / b


def targets(results: dict[str, Any]) -> list[dict[str, Any]]:
    """Every speed target with its measured ratio."""
    out: list[dict[str, Any]] = []

    def add(what: str, value: float | None, limit: float, upper: bool,
            ceiling: float | None = None) -> None:
        ok = None if value is None else (value <= limit if upper else value >= limit)
        out.append({"target": what, "value": value, "limit": f"{'≤' if upper else '≥'} {limit:g}",
                    "met": ok, "ceiling": ceiling})

    k = results.get("kalman")
    if k:
        for r in k["rows"]:
            tag = f"{r['filter']} {r['model']} ({r.get('data', 'consistent')})"
            single, batched = KALMAN_LIMITS[(r["filter"], r["model"])]
            add(f"{tag}: single / filterpy", r["ratio"], single, True)
            add(f"{tag}: B=1024 µs per system-step", r["batched_us"], batched, True)
            add(f"{tag}: B=1024 throughput / looped filterpy", r["throughput_vs_filterpy"],
                25.0, False)
        add("efir n=3 N=10: B=1024 µs per system-step", k["efir"]["batched_us"], 1.6, True)
        add("efir n=3 N=10: B=1024 throughput / looped filterpy EKF",
            k["efir"]["throughput_vs_filterpy_ekf"], 25.0, False)
        for f in k.get("fixed_cost", []):
            add(f"Estimator.step fixed Python cost, B={f['batch']} (µs)", f["python_us"], 4.0,
                True)
    e = results.get("envs")
    if e:
        for r in e["plants"]:
            if r["env"].endswith("VanDerPol-v0"):
                add("VanDerPol-v0 native×1024 / sync steps per second",
                    ratio(r["sync64_us"], r["native1024_us"]), 100.0, False,
                    ratio(r["sync64_us"], r.get("wiener1024_us")))
        for p in e["pendulum"]:
            add(f"PendulumSlider-v0 ({p['friction']}) / InvertedPendulum-v5 steps per second",
                p["steps_per_s_ratio"], 1.0, False,
                ratio(p.get("inverted_pendulum_us"), p.get("mujoco_us")))
    w = results.get("wrappers")
    if w:
        for r in w["vector"]:
            floor = r.get("ekf_floor_us")
            add(f"VectorEstimatorObservation(ekf) {r['env'].removeprefix('fir_gym/')} "
                f"{r['mode']}×64: wrapped / bare", r["ratio"],
                1.3 if r["mode"] == "native" else 1.2, True,
                None if floor is None else (r["bare_us"] + floor) / r["bare_us"])
    t = results.get("training")
    if t and "skipped" not in t:
        from .training import targets as training_targets

        for what, value, limit, ceiling in training_targets(t):
            add(what, value, limit, False, ceiling)
    return out


def print_targets(rows: list[dict[str, Any]]) -> None:
    print("\n5. targets\n")
    print(format_table(["target", "measured", "limit", "met", "ceiling"],
                       [[r["target"], r["value"], r["limit"],
                         "—" if r["met"] is None else ("yes" if r["met"] else "NO"),
                         r.get("ceiling")]
                        for r in rows], floatfmt=".3g"))
    print("   ceiling: the best ratio a floor measured in this run allows — VanDerPol: its "
          "Wiener increments alone (numpy's normal draws, 100 per sub-env step); "
          "PendulumSlider: MuJoCo's own steps with the friction law, no env around them; "
          "wrapper: bare plus what a 64-system EKF step cannot skip — the plant model's "
          "f, F, h, H and the filter's fixed cost (a one-state model whose callables return "
          "ready arrays); SB3 stepping: the bare native vector env plus the batched EKF; "
          "PPO training: PPO's own cost per sample (a VecEnv whose step is free)")
