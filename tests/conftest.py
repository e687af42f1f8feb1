"""Test-session settings: headless MuJoCo rendering (EGL) unless the caller chose a backend;
fixtures several test files share."""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(scope="session")
def tiny_runs(tmp_path_factory):
    """Two tiny trained runs on CarrierMotion-v0, trained once for the session (watch and
    record play them): ``"true"`` sees the true state, ``"kf"`` a KF's estimate."""
    pytest.importorskip("stable_baselines3")
    from fir_gym.training import RunConfig, train

    root = tmp_path_factory.mktemp("runs")
    out = {}
    for kind in ("true", "kf"):
        config = RunConfig(env_id="fir_gym/CarrierMotion-v0", observation_kind=kind,
                           steps=256, seed=0, n_envs=1, env_kwargs={"max_episode_steps": 30})
        out[kind] = train(config, root / kind)
    return out
