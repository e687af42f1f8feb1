"""fir-gym speed's training section runs and reports its two ratios (no timing asserted)."""

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from fir_gym.benchmarks import training
from fir_gym.benchmarks.targets import targets


def test_the_training_section_reports_both_ratios_and_their_floors(monkeypatch, capsys):
    from fir_gym.benchmarks import jax_training

    monkeypatch.setattr(training, "N_ENVS", 2)                 # a smoke test, not a figure
    # the JAX backend's rows (with the jax extra) have their own smoke tests
    # (tests/jax/test_speed_jax.py): here the numpy section's two
    monkeypatch.setattr(jax_training, "run", lambda quick=False: {"skipped": "not here"})
    res = training.run(quick=True)
    step, train = res["step"], res["train"]
    for value in (step["ratio"], step["ekf16_us"], step["bare16_us"], step["ceiling"],
                  step["infos_us"],
                  train["ratio"], train["ceiling"], train["ppo_own_steps_per_s"]):
        assert np.isfinite(value) and value > 0
    # the ceiling is the ratio the floor allows: dummy / (bare + ekf)
    assert step["ceiling"] == pytest.approx(step["dummy_us"] / (step["bare16_us"]
                                                                + step["ekf16_us"]))
    rows = training.targets(res)
    assert [r[2] for r in rows] == [10.0, 3.0]
    assert [r[3] for r in rows] == [step["ceiling"], train["ceiling"]]
    # and the speed command's targets table lists both
    listed = [r["target"] for r in targets({"training": res})]
    assert listed == [r[0] for r in rows]
    training.print_results(res)
    assert "make_sb3_vec_env" in capsys.readouterr().out
