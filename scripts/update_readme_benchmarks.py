"""Write the README's two benchmark sections from a ``fir-gym benchmark-robustness`` run.

    python scripts/update_readme_benchmarks.py --results robustness/results.json
        [--readme README.md]

Between ``<!-- robustness:start -->`` and ``<!-- robustness:end -->``: the robustness table
(:func:`fir_gym.robustness.readme.robustness_table`) and the answers computed from the
results (:func:`fir_gym.robustness.answers.answers`); between ``<!-- benchmark:start -->``
and ``<!-- benchmark:end -->``: the controllers on estimates of the nominal plant, per plant
(:func:`fir_gym.robustness.readme.controllers_table`). Every number comes from the results.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from fir_gym.robustness.plan import PLANTS, SEEDS
from fir_gym.robustness.readme import controllers_table, robustness_table


def _run_line(results: dict) -> str:
    m = results["machine"]
    load = ""
    if m.get("load_start") and m.get("load_end"):
        load = (f", load average {', '.join(f'{v:g}' for v in m['load_start'])} at the start "
                f"and {', '.join(f'{v:g}' for v in m['load_end'])} at the end")
    jobs = f" --jobs {m['jobs']}" if m.get("jobs") else ""
    seeds = max((r["seeds"] for cell in results["tables"] for r in cell["rows"]
                 if r.get("regime") is not None), default=0)
    seeds_option = f" --seeds {seeds}" if seeds and seeds != SEEDS else ""
    steps = ", ".join(f"{env_id.split('/')[-1]} {PLANTS[env_id].steps:,}".replace(",", " ")
                      for env_id in results["plants"] if env_id in PLANTS)
    return (f"`fir-gym benchmark-robustness --backend {m['backend']}{jobs}{seeds_option}` "
            f"(code version `{results['code_version']}`) on {m['cpu']}, {m['cores']} cores"
            f"{load}: the LQG grid, {results['lqg_tasks']} cells of 100 episodes, in "
            f"{results['lqg_seconds'] / 60:.1f} min; the learned grid, "
            f"{results['learned_tasks']} trained controllers each evaluated under every "
            f"condition ({seeds} seeds per plant, kind and regime; training steps: {steps}), "
            f"in {results['learned_seconds'] / 3600:.2f} h "
            f"({results['train_seconds'] / 3600:.2f} h of training, summed over workers"
            + (f"; {results['learned_reused']} reused from a finished run at the same code"
               if results.get("learned_reused") else "") + ").")


def robustness_block(results: dict) -> str:
    lines = [
        "**Benchmark: robustness in the loop.** " + _run_line(results),
        "",
        "Per plant and condition, at the condition's middle strength: the return (a cost, "
        "higher is better: the IQM over the shared episodes and seeds) of the LQG on the "
        "true state, and for each family its best controller, `name return (gap)` — the "
        "LQG on the best Kalman-family and the best FIR-family estimate (`+gate`: with the "
        "innovation gate), PPO trained on the nominal plant on the best estimate and on the "
        "best memory (`measurement-stack`, `recurrent`), and the best PPO trained with a "
        "condition on. The gap is the estimation gap: the share of that controller's cost "
        "that the same family on the true state removes (0: knowing the state would not "
        "help). Every strength, interval, RMSE, NEES, divergence rate and recovery time: "
        "`DIR/REPORT.md`; the conditions: [docs/robustness.md](docs/robustness.md).",
        "",
        robustness_table(results),
        "",
        "Computed from the results by `fir_gym.robustness.answers` (paired 95 % bootstrap "
        "intervals: a tie where the interval of the difference contains 0, a match within "
        "1 %):",
        "",
        *[f"- {a}" for a in results["answers"]],
    ]
    return "\n".join(lines)


def controllers_block(results: dict) -> str:
    lines = [
        "**Benchmark: controllers on estimates**, the nominal plant — the nominal cell of "
        "the robustness benchmark above (" + _run_line(results).split(" (code version")[0]
        + "): PPO with fir-gym's defaults (the shipped YAML) trained on the nominal plant on "
        "the true state, the raw measurement, the last K measurements and actions (K = the "
        "plant's window), RecurrentPPO on the measurements and each estimator's estimate, "
        "and the LQG of the nominal model on the true state and on every applicable "
        "estimator (no training; on VanDerPol-v0 with the detuned input weight of "
        "`VanDerPolEnv.design_point`, envs/van_der_pol.py); every controller evaluated on the same "
        "20 (PPO) or 100 (LQG) episodes. Returns are costs (higher is better); the "
        "estimation gap is the share of the row's cost that the same family on the true "
        "state removes; NEES: the median (χ²(n_x)'s is about n_x − 2/3), the fraction of "
        "steps inside the 95 % χ² band (0.95 for a consistent filter) and the mean (the "
        "ANEES, which a few steps with a nearly singular P can blow up).",
        "",
    ]
    for cell in results["tables"]:
        if cell["condition"] != "nominal":
            continue
        lines += [f"*{cell['env_id']}*", "", controllers_table(results, cell["env_id"]), ""]
    return "\n".join(lines).rstrip()


def replace_block(text: str, name: str, content: str) -> str:
    pattern = re.compile(rf"(<!-- {name}:start -->\n).*?(<!-- {name}:end -->)", re.DOTALL)
    if not pattern.search(text):
        raise SystemExit(f"the README has no <!-- {name}:start --> ... <!-- {name}:end --> block")
    return pattern.sub(lambda m: m.group(1) + content + "\n" + m.group(2), text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", required=True, help="benchmark-robustness results.json")
    parser.add_argument("--readme", default="README.md")
    args = parser.parse_args()
    results = json.loads(Path(args.results).read_text())
    readme = Path(args.readme)
    text = readme.read_text()
    text = replace_block(text, "robustness", robustness_block(results))
    text = replace_block(text, "benchmark", controllers_block(results))
    readme.write_text(text)
    print(f"wrote the robustness and benchmark sections of {readme}")


if __name__ == "__main__":
    main()
