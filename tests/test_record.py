"""``fir-gym record``: episodes written as a Minari dataset and read back with minari."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

minari = pytest.importorskip("minari")
pytest.importorskip("h5py")

from fir_gym.cli import main  # noqa: E402
from fir_gym.record import record  # noqa: E402

ENV = "fir_gym/Orbit-v0"


@pytest.fixture
def datasets(tmp_path, monkeypatch):
    """A temporary Minari datasets folder: nothing is written to the home directory."""
    root = tmp_path / "datasets"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def plain_rollout(env_id, estimator, seed, steps, act=None, **kwargs):
    """Observations and infos of the same episode through a plain ``gym.make``."""
    env = gym.make(env_id, estimator=estimator, **kwargs)
    obs, info = env.reset(seed=seed)
    observations, infos = [obs], [info]
    for _ in range(steps):
        action = (np.zeros(env.action_space.shape, dtype=np.float32) if act is None
                  else act(env, obs))
        obs, _, terminated, truncated, info = env.step(action)
        observations.append(obs)
        infos.append(info)
        if terminated or truncated:
            break
    return np.array(observations), infos


def test_round_trip_of_two_orbit_episodes(datasets):
    out = record(ENV, datasets, estimator="ekf", policy="zero", episodes=2, seed=3, steps=15)
    assert out.dataset_id == "fir_gym/orbit-ekf-zero-v0"
    assert (out.episodes, out.steps) == (2, 30)
    dataset = minari.load_dataset(out.dataset_id)
    assert (dataset.total_episodes, dataset.total_steps) == (2, 30)
    for i, episode in enumerate(dataset.iterate_episodes()):
        observations, infos = plain_rollout(ENV, "ekf", 3 + i, 15)
        np.testing.assert_array_equal(episode.observations, observations)
        assert episode.actions.shape == (15, 1) and not episode.actions.any()
        assert episode.truncations[-1] and not episode.truncations[:-1].any()
        assert not episode.terminations.any()
        got = episode.infos
        assert got["state"].shape == (16, 2) and got["measurement"].shape == (16, 1)
        assert got["estimate"].shape == (16, 2) and got["covariance"].shape == (16, 2, 2)
        assert got["estimator_diverged"].dtype == np.bool_ and not got["estimator_diverged"].any()
        np.testing.assert_array_equal(got["state"], [info["state"] for info in infos])
        np.testing.assert_array_equal(got["estimate"], observations)
        assert np.all(np.isfinite(got["covariance"]))
        np.testing.assert_allclose(got["covariance"], got["covariance"].transpose(0, 2, 1))
        assert set(got["estimator_info"]) >= {"nis"}
        assert "conditions" not in got                   # none active
    meta = dataset.storage.metadata["fir_gym"]
    assert meta["env_id"] == ENV and meta["estimator"] == "ekf" and meta["policy"] == "zero"
    assert meta["seeds"] == [3, 4] and meta["covariance"] is True
    assert meta["code_version"] and meta["fir_gym_version"] and meta["description"]
    assert dataset.spec.env_spec is not None and dataset.spec.env_spec.id == ENV
    recovered = dataset.recover_environment()           # the same env from the spec
    obs, info = recovered.reset(seed=3)
    np.testing.assert_array_equal(obs, dataset[0].observations[0])
    np.testing.assert_array_equal(info["measurement"], dataset[0].infos["measurement"][0])


def test_recording_twice_gives_identical_arrays(tmp_path, datasets):
    first = record(ENV, tmp_path / "a", estimator="ekf", episodes=2, steps=10, seed=7)
    second = record(ENV, tmp_path / "b", estimator="ekf", episodes=2, steps=10, seed=7)
    a = minari.MinariDataset(first.path / "data")
    b = minari.MinariDataset(second.path / "data")
    for x, y in zip(a.iterate_episodes(), b.iterate_episodes(), strict=True):
        np.testing.assert_array_equal(x.observations, y.observations)
        np.testing.assert_array_equal(x.rewards, y.rewards)
        for key in ("state", "measurement", "estimate", "covariance"):
            np.testing.assert_array_equal(x.infos[key], y.infos[key])
    assert not datasets.exists()                         # out, not the variable, decides


def test_the_lqg_policy_and_active_conditions_are_recorded(datasets):
    from fir_gym.controllers import LQGController

    kwargs = {"sensor_faults": {"dropout": 0.3}}
    out = record("fir_gym/CarrierMotion-v0", datasets, estimator="kf", policy="lqg",
                 episodes=1, steps=12, env_kwargs=kwargs, dataset_id="tests/carrier-lqg-v0")
    episode = minari.load_dataset("tests/carrier-lqg-v0")[0]
    controllers = {}

    def lqg(env, obs):
        controller = controllers.setdefault("lqg", LQGController(env))
        return np.asarray(controller.predict(obs)[0])

    observations, infos = plain_rollout("fir_gym/CarrierMotion-v0", "kf", 0, 12, act=lqg,
                                        **kwargs)
    np.testing.assert_array_equal(episode.observations, observations)
    assert episode.actions.any()                          # the LQR acts
    conditions = episode.infos["conditions"]
    np.testing.assert_array_equal(conditions["measurement_missing"],
                                  [info["measurement_missing"] for info in infos])
    assert conditions["measurement_missing"].any()
    assert conditions["sensor_faults"]["dropped"].dtype == np.bool_
    assert out.steps == 12


def test_an_estimator_without_covariance_stores_none():
    """No registered filter lacks a covariance today; a stand-in for one that does."""
    from types import SimpleNamespace

    from fir_gym.record import InfoShape, step_info

    info = {"state": [1.0, 2.0], "measurement": [0.5], "estimate": [1.0, 2.5],
            "estimator_diverged": False, "estimator_info": {"nis": 0.3, "diverged": False}}
    shape = InfoShape.of(info)
    got = step_info(info, SimpleNamespace(provides_covariance=False, P=None), shape)
    assert "covariance" not in got
    assert got["estimator_info"] == {"nis": 0.3} and got["estimate"].dtype == np.float64
    later = step_info({**info, "estimator_info": {}},
                      SimpleNamespace(provides_covariance=True, P=np.eye(2)), shape)
    assert np.isnan(later["estimator_info"]["nis"]) and later["covariance"].shape == (2, 2)


def test_an_existing_dataset_is_not_overwritten(datasets):
    record(ENV, datasets, estimator="ekf", episodes=1, steps=3)
    with pytest.raises(ValueError, match="already holds"):
        record(ENV, datasets, estimator="ekf", episodes=1, steps=3)


@pytest.mark.parametrize(("kwargs", "needle"), [
    ({"episodes": 0}, "episodes"), ({"steps": -1}, "steps"), ({"seed": -2}, "seed"),
    ({"dataset_id": "no version"}, "dataset_id"), ({"estimator": None}, "estimator"),
    ({"policy": "nope"}, "policy")])
def test_bad_arguments_name_themselves(datasets, kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        record(ENV, datasets, **{"estimator": "ekf", "episodes": 1, **kwargs})


def test_cli_records_and_a_bad_episodes_is_one_line(tmp_path, capsys):
    out = tmp_path / "ds"
    assert main(["record", "--env", ENV, "--estimator", "ekf", "--episodes", "1", "--steps",
                 "4", "--out", str(out)]) == 0
    assert "fir_gym/orbit-ekf-zero-v0" in capsys.readouterr().out
    assert (out / "fir_gym" / "orbit-ekf-zero-v0" / "data").is_dir()
    for bad in ("0", "two"):
        with pytest.raises(SystemExit) as exc:
            main(["record", "--env", ENV, "--estimator", "ekf", "--episodes", bad,
                  "--out", str(out)])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("fir-gym record: error:"), err
        assert "--episodes" in err[0]


def test_missing_minari_is_one_line_with_the_install_command():
    code = ("import sys\n"
            "sys.modules['minari'] = None\n"
            "from fir_gym.cli import main\n"
            "raise SystemExit(main(['record', '--env', 'fir_gym/Orbit-v0', '--estimator', "
            "'ekf', '--out', 'never']))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            cwd="/", timeout=300)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert 'pip install ".[dataset]"' in lines[0] and "Minari" in lines[0]


@pytest.fixture
def runs(tiny_runs):
    """The session's two tiny trained runs (tests/conftest.py)."""
    return tiny_runs


@pytest.mark.parametrize(("kind", "estimator"), [("kf", None), ("true", "kf")])
def test_a_trained_run_records_the_episode_its_evaluation_plays(datasets, runs, kind,
                                                                 estimator):
    """The oracle is fir_gym.training.evaluate: the same policy, normalisation and env give
    the recorded episode its first episode's return."""
    from fir_gym.training import evaluate

    out = record(None, datasets, estimator=estimator, policy=runs[kind], episodes=1, seed=5)
    dataset = minari.load_dataset(out.dataset_id)
    episode = dataset[0]
    reference = evaluate(runs[kind], episodes=1, seed=5).returns[0]
    assert episode.rewards.sum() == pytest.approx(reference, abs=5e-7)  # SB3's Monitor rounds
    assert out.steps == 30 and episode.infos["covariance"].shape == (31, 2, 2)
    meta = dataset.storage.metadata["fir_gym"]
    assert meta["run_kind"] == kind and meta["estimator"] == "kf"
    if kind == "true":                                  # the controller saw the true state
        np.testing.assert_array_equal(episode.observations, episode.infos["state"])
    else:
        np.testing.assert_array_equal(episode.observations, episode.infos["estimate"])
