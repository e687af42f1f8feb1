"""The speed targets of issues 3, 5, 7 and 9, judged on the results of ``fir-gym speed``.

Each row gives the measured ratio, its limit, whether it is met and — where a floor
was measured in the same run — the ceiling: the best ratio that floor allows.
"""

from __future__ import annotations

from typing import Any

from ..tables import format_table


def ratio(a: float | None, b: float | None) -> float | None:
    """``a / b``, or ``None`` when either is missing or ``b`` is 0."""
    return None if a is None or b is None or b == 0 else a / b


def targets(results: dict[str, Any]) -> list[dict[str, Any]]:
    """Every target of issues 3, 5, 7 and 9 with its measured ratio."""
    out: list[dict[str, Any]] = []

    def add(what: str, value: float | None, limit: float, upper: bool,
            ceiling: float | None = None) -> None:
        ok = None if value is None else (value <= limit if upper else value >= limit)
        out.append({"target": what, "value": value, "limit": f"{'≤' if upper else '≥'} {limit:g}",
                    "met": ok, "ceiling": ceiling})

    k = results.get("kalman")
    if k:
        for r in k["rows"]:
            tag = f"{r['filter']} {r['model']}"
            if r["filter"] in ("kf", "kf-full", "ekf"):
                add(f"{tag}: single / filterpy", r["ratio"], 1.0, True)
                add(f"{tag}: B=1024 µs per system-step", r["batched_us"], 0.5, True)
            else:
                add(f"{tag}: single / filterpy", r["ratio"], 0.5, True)
                add(f"{tag}: B=1024 µs per system-step", r["batched_us"], 2.0, True)
            add(f"{tag}: B=1024 throughput / looped filterpy", r["throughput_vs_filterpy"],
                25.0, False)
        add("efir n=3 N=10: B=1024 µs per system-step", k["efir"]["batched_us"], 5.0, True)
        add("efir n=3 N=10: B=1024 throughput / looped filterpy EKF",
            k["efir"]["throughput_vs_filterpy_ekf"], 25.0, False)
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
                f"{r['mode']}×64: wrapped / bare", r["ratio"], 1.2, True,
                None if floor is None else (r["bare_us"] + floor) / r["bare_us"])
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
          "ready arrays)")
