"""compare-controllers: validation before training, jobs on the runner, resume, the CLI."""

import json
import time

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from fir_gym.cli import main
from fir_gym.scenarios.runner import Runner
from fir_gym.training import RunConfig, compare_controllers, evaluate, train

SMALL = {"max_episode_steps": 40}


def test_same_numbers_on_the_serial_and_joblib_backends(tmp_path):
    kwargs = dict(steps=512, episodes=2, n_envs=2, env_kwargs=SMALL,
                  kind_kwargs={"efir": {"horizon": 5}})
    serial = compare_controllers("fir_gym/Orbit-v0", ["true", "efir", "lqg"], [0, 1],
                                 tmp_path / "serial", **kwargs)
    with Runner("joblib", jobs=2) as runner:
        parallel = compare_controllers("fir_gym/Orbit-v0", ["true", "efir", "lqg"], [0, 1],
                                       tmp_path / "joblib", runner=runner, **kwargs)
    for a, b in zip(serial, parallel, strict=True):
        assert a["per_seed"] == b["per_seed"] and a["rmse"] == b["rmse"]
    efir = serial[1]
    assert efir["rmse"] is not None and len(efir["rmse"]) == 2 and efir["anees"] > 0
    assert serial[0]["rmse"] is None                       # the true state: no estimator
    assert serial[2]["std"] == 0.0                         # LQG: nothing trained, no seed
    results = json.loads((tmp_path / "serial" / "results.json").read_text())
    assert len(results) == 6


def test_a_bad_kind_option_or_kwarg_fails_before_any_training(tmp_path):
    for bad, message in [({"kinds": ["true", "nope"]}, "unknown kind 'nope'"),
                         ({"kind_kwargs": {"efir": {"horizn": 3}}}, "horizn"),
                         ({"kind_kwargs": {"horizon": 3}}, "'horizon'"),
                         ({"algo_kwargs": {"n_stepz": 3}}, "n_stepz"),
                         ({"env_kwargs": {"muu": 3}}, "muu")]:
        args = {"kinds": ["true", "efir"], **bad}
        start = time.perf_counter()
        with pytest.raises(ValueError, match=message):
            compare_controllers("fir_gym/Orbit-v0", args.pop("kinds"), [0], tmp_path / "x",
                                steps=100_000, **args)
        assert time.perf_counter() - start < 30
        assert not (tmp_path / "x").exists()                # nothing ran


def test_resume_skips_finished_jobs_and_checkpoints_continue(tmp_path):
    kwargs = dict(steps=512, episodes=1, n_envs=2, env_kwargs=SMALL, checkpoint_freq=256)
    first = compare_controllers("fir_gym/VanDerPol-v0", ["measurement"], [0], tmp_path, **kwargs)
    result = tmp_path / "measurement-seed0" / "result.json"
    stamp = result.stat().st_mtime_ns
    again = compare_controllers("fir_gym/VanDerPol-v0", ["measurement"], [0], tmp_path,
                                resume=True, **kwargs)
    assert again[0]["per_seed"] == first[0]["per_seed"] and result.stat().st_mtime_ns == stamp
    assert list((tmp_path / "measurement-seed0" / "checkpoints").glob("model_*_steps.zip"))


def test_train_evaluate_a_run_folder_with_the_best_model(tmp_path):
    config = RunConfig(env_id="fir_gym/CarrierMotion-v0", observation_kind="kf", steps=1024,
                       n_envs=2, env_kwargs=SMALL, eval_freq=512, eval_episodes=1)
    run = train(config, tmp_path / "run")
    for name in ("model.zip", "vecnormalize.pkl", "run.json", "best/best_model.zip"):
        assert (run / name).is_file()
    first, second = evaluate(run, episodes=2), evaluate(run, episodes=2)
    assert first.returns == second.returns and len(first.rmse) == 2
    assert np.all(np.isfinite(evaluate(run, episodes=1, best=True).returns))


def test_memory_kinds_train_and_evaluate(tmp_path):
    for kind in ("measurement-stack", "recurrent"):
        config = RunConfig(env_id="fir_gym/Orbit-v0", observation_kind=kind, steps=512,
                           n_envs=2, env_kwargs=SMALL,
                           kind_kwargs={"horizon": 4} if kind == "measurement-stack" else {})
        run = train(config, tmp_path / kind)
        result = evaluate(run, episodes=2)
        assert len(result.returns) == 2 and result.rmse is None


def test_cli_errors_are_one_line_naming_the_argument(tmp_path, capsys):
    cases = [
        (["compare-controllers", "--env", "fir_gym/Orbit-v0", "--observations", "true,nope"],
         "unknown kind 'nope'"),
        (["compare-controllers", "--env", "fir_gym/Orbit-v0", "--observations", "efir",
          "--kind-kwargs", '{"horizon": 50}'], "'horizon'"),
        (["train", "--env", "fir_gym/Orbit-v0", "--estimator", "efir",
          "--estimator-kwargs", '{"efir": {"horizn": 5}}'], "horizn"),
        (["evaluate", "--env", "fir_gym/Orbit-v0", "--kind", "ekf"], "learned"),
        (["evaluate", "--model", str(tmp_path)], "run folder"),
    ]
    for argv, message in cases:
        code = main(argv + (["--out", str(tmp_path / "o")] if argv[0] != "evaluate" else []))
        err = capsys.readouterr().err.strip()
        assert code == 2 and message in err and len(err.splitlines()) == 1, err


def test_cli_evaluates_lqg_and_compares(tmp_path, capsys):
    assert main(["evaluate", "--env", "fir_gym/Orbit-v0", "--kind", "lqg", "--episodes", "1",
                 "--env-kwargs", '{"max_episode_steps": 30}']) == 0
    assert "estimation RMSE" in capsys.readouterr().out
    code = main(["compare-controllers", "--env", "fir_gym/CarrierMotion-v0",
                 "--observations", "true,lqg", "--seeds", "1", "--steps", "256",
                 "--n-envs", "2", "--episodes", "1", "--out", str(tmp_path), "--no-progress",
                 "--env-kwargs", json.dumps(SMALL)])
    assert code == 0
    table = (tmp_path / "comparison.md").read_text()
    assert "| true" in table and "| lqg" in table and "IQM" in table
    assert (tmp_path / "learning_curves.png").is_file()


def test_tensorboard_logs_are_written(tmp_path):
    pytest.importorskip("tensorboard")
    config = RunConfig(env_id="fir_gym/Orbit-v0", observation_kind="true", steps=256, n_envs=2,
                       env_kwargs=SMALL, tensorboard=str(tmp_path / "tb"))
    train(config, tmp_path / "run")
    assert list((tmp_path / "tb").glob("true-seed0_*/events.out.tfevents.*"))
