"""Controller training: a CI smoke test (small budgets) of train / evaluate / compare."""

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from fir_gym.cli import main
from fir_gym.training import RunConfig, evaluate, learning_curve, train


@pytest.mark.parametrize(("env_id", "kind"), [("fir_gym/CarrierMotion-v0", "kf"),
                                              ("fir_gym/Orbit-v0", "efir"),
                                              ("fir_gym/VanDerPol-v0", "measurement")])
def test_train_then_evaluate_a_run_folder(tmp_path, env_id, kind):
    config = RunConfig(env_id=env_id, observation_kind=kind, steps=2048, seed=0, n_envs=2,
                       env_kwargs={"max_episode_steps": 50})
    run = train(config, tmp_path / "run")
    for name in ("model.zip", "vecnormalize.pkl", "run.json"):
        assert (run / name).is_file()
    assert json.loads((run / "run.json").read_text())["observation_kind"] == kind
    first, second = evaluate(run, episodes=2), evaluate(run, episodes=2)
    assert len(first.returns) == 2 and np.all(np.isfinite(first.returns))
    assert first.returns == second.returns           # fixed evaluation seeds: reproducible
    steps, means = learning_curve(run, bins=4)
    assert len(steps) == 4 and np.any(np.isfinite(means))   # 40 finished 50-step episodes


def test_bad_config_is_rejected():
    with pytest.raises(ValueError, match="algo"):
        RunConfig(env_id="fir_gym/Orbit-v0", algo="dqn")


def test_cli_compare_controllers_writes_a_table(tmp_path, capsys):
    code = main(["compare-controllers", "--env", "fir_gym/CarrierMotion-v0",
                 "--observations", "true,measurement", "--seeds", "1", "--steps", "512",
                 "--episodes", "1", "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    table = (tmp_path / "comparison.md").read_text()
    assert "| true" in table and "| measurement" in table
    assert "mean return" in capsys.readouterr().out
