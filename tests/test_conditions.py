"""The conditions registry: every condition's strengths checked, what each builds on every
plant, and the refusals (docs/robustness.md#conditions)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import fir_gym
from fir_gym.conditions import CONDITIONS, condition_setup, get_condition


def plant(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make(env_id).unwrapped


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
@pytest.mark.parametrize("name", [n for n in CONDITIONS if n != "nominal"])
def test_every_condition_builds_on_every_plant_at_every_strength(env_id, name):
    p = plant(env_id)
    for strength in CONDITIONS[name].strengths:
        setup = condition_setup(name, strength, p, 200)
        built = {**setup.plant_kwargs, **setup.sensor_faults}
        assert built, name
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            env = gym.make(env_id, **setup.plant_kwargs, sensor_faults=setup.sensor_faults,
                           estimator="ekf", estimator_kwargs=setup.estimator_kwargs or None)
        env.reset(seed=0)
        _, reward, *_ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert np.isfinite(reward)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        checked = gym.make(env_id, **setup.plant_kwargs, sensor_faults=setup.sensor_faults)
        check_env(checked.unwrapped if not setup.sensor_faults else checked,
                  skip_render_check=True)


def test_what_the_conditions_build():
    orbit = plant("fir_gym/Orbit-v0")
    assert condition_setup("mismatch", 0.1, orbit, 300).plant_kwargs == {
        "randomize": {"mu": 0.1, "thrust_max": 0.1}}
    assert condition_setup("burst", 0.15, orbit, 300).plant_kwargs == {
        "burst": ((150, 179, 0.15),)}
    bias = condition_setup("bias", 3.0, orbit, 300).sensor_faults["bias"]
    assert bias[0] == 150 and bias[1] == pytest.approx([3.0 * np.sqrt(1e-3)])
    delay = condition_setup("delay", 2, orbit, 300)
    assert delay.sensor_faults == {"delay": 2} and delay.estimator_kwargs == {"delay": 2}
    assert condition_setup("multirate", 5, orbit, 300).sensor_faults == {"every": 5}
    assert condition_setup("nominal", None, orbit).plant_kwargs == {}


@pytest.mark.parametrize(("name", "strength", "needle"), [
    ("rain", 0.1, "unknown condition 'rain'"),
    ("mismatch", 1.0, "condition 'mismatch': strength must be in [0, 1)"),
    ("dropout", 1.5, "condition 'dropout': strength must be in [0, 1]"),
    ("burst", -1.0, "condition 'burst'"),
    ("delay", 1.5, "an integer >= 1"),
    ("delay", 0, "an integer >= 1"),
    ("multirate", 1, "an integer >= 2"),
    ("outliers", "a lot", "condition 'outliers'"),
    ("nominal", 0.3, "takes no strength"),
])
def test_bad_names_and_strengths_are_refused_naming_them(name, strength, needle):
    with pytest.raises(ValueError, match=needle.replace("[", r"\[").replace("(", r"\(")
                       .replace(")", r"\)")):
        condition_setup(name, strength, plant("fir_gym/Orbit-v0"), 300)


def test_a_delay_as_long_as_the_episode_is_refused():
    with pytest.raises(ValueError, match="not shorter than an episode"):
        condition_setup("delay", 300, plant("fir_gym/Orbit-v0"), 300)


def test_list_shows_the_conditions(capsys):
    from fir_gym.cli import main

    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in CONDITIONS:
        assert f"\n{name} " in out
    assert get_condition("delay").strength_meaning in out
