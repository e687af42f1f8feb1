"""The environment ids: literal registrations whose entry points take the estimator options."""

from __future__ import annotations

import ast
import inspect
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest

import fir_gym
from fir_gym import _registration
from fir_gym.envs._vector import PlantVectorEnv
from fir_gym.wrappers import EstimatorObservation, TrueStateObservation

MODULE = "fir_gym._registration"


def module_level_names() -> set[str]:
    """Names bound by top-level statements of ``_registration.py`` (what a reader can grep)."""
    tree = ast.parse(inspect.getsource(_registration))
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
    return names


def find_wrapper(env: gym.Env, cls: type) -> gym.Env:
    """The wrapper of type ``cls`` in ``env``'s chain (an AssertionError if there is none)."""
    while not isinstance(env, cls):
        assert isinstance(env, gym.Wrapper), f"no {cls.__name__} in the wrapper chain"
        env = env.env
    return env


def fir_gym_specs() -> dict[str, gym.envs.registration.EnvSpec]:
    return {env_id: spec for env_id, spec in gym.registry.items() if spec.namespace == "fir_gym"}


def test_ids_are_the_registered_ones():
    specs = fir_gym_specs()
    assert set(specs) == set(fir_gym.ENV_IDS)
    assert len(set(fir_gym.ENV_IDS)) == len(fir_gym.ENV_IDS)
    assert {i for i, s in specs.items() if s.vector_entry_point} == set(fir_gym.VECTOR_ENV_IDS)


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
def test_entry_points_are_attributes_made_from_the_plant_s_one_row(env_id):
    """Each id is one row of PAPER_PLANTS (a statement of the module a reader can grep), and
    its entry points are the module attributes that row names, building the row's class."""
    assert "PAPER_PLANTS" in module_level_names()
    rows = [row for row in _registration.PAPER_PLANTS if row.id == env_id]
    assert len(rows) == 1
    row = rows[0]
    spec = gym.spec(env_id)
    assert spec.entry_point == f"{MODULE}:{row.entry}"
    assert spec.vector_entry_point == (f"{MODULE}:{row.entry}_vector" if row.vector else None)
    for point in (spec.entry_point, spec.vector_entry_point):
        if point is None:
            continue
        entry = getattr(_registration, point.partition(":")[2])
        assert callable(entry) and entry.plant == row.plant
    assert spec.max_episode_steps == row.max_episode_steps > 0
    assert spec.to_json()                              # string entry points: a JSON spec


def test_registering_again_changes_nothing_and_warns_of_nothing():
    before = dict(fir_gym_specs())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fir_gym.register_envs()
    after = fir_gym_specs()
    assert after.keys() == before.keys()
    assert all(after[i] is before[i] for i in before)


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
def test_make_with_an_estimator(env_id):
    env = gym.make(env_id, estimator="ekf", estimator_kwargs={"nan_policy": "skip"},
                   observation="estimate+covariance")
    assert isinstance(env.unwrapped, type(gym.make(env_id).unwrapped))
    assert find_wrapper(env, EstimatorObservation).estimator.nan_policy == "skip"
    obs, info = env.reset(seed=1)
    assert set(obs) == {"estimate", "covariance"}
    np.testing.assert_array_equal(obs["estimate"], info["estimate"])
    obs, *_, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    np.testing.assert_array_equal(obs["estimate"], info["estimate"])
    np.testing.assert_allclose(info["estimation_error"], info["state"] - info["estimate"])
    assert env.spec.max_episode_steps == gym.spec(env_id).max_episode_steps


def test_make_observing_the_true_state():
    env = gym.make("fir_gym/Orbit-v0", observation="true")
    find_wrapper(env, TrueStateObservation)
    obs, info = env.reset(seed=0)
    np.testing.assert_array_equal(obs, info["state"])


def test_make_without_an_estimator_refuses_its_options():
    with pytest.raises(ValueError, match="estimator_kwargs given without an estimator"):
        gym.make("fir_gym/Orbit-v0", estimator_kwargs={"horizon": 3})


@pytest.mark.parametrize("env_id", fir_gym.VECTOR_ENV_IDS)
def test_make_vec_uses_the_native_vector_env(env_id):
    envs = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(envs.unwrapped, PlantVectorEnv)
    assert envs.num_envs == 3
    obs, info = envs.reset(seed=0)
    assert obs.shape == (3, *gym.make(env_id).observation_space.shape)
    obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
    assert reward.shape == terminated.shape == truncated.shape == (3,)
    assert info["state"].shape[0] == 3
    envs.close()


def test_make_vec_refuses_estimator_options_with_a_pointer_to_the_wrapper():
    with pytest.raises(ValueError, match="VectorEstimatorObservation"):
        gym.make_vec("fir_gym/Orbit-v0", num_envs=2, vectorization_mode="vector_entry_point",
                     estimator="ekf")


def test_module_qualified_id_needs_no_prior_import(tmp_path):
    """``gym.make("fir_gym:fir_gym/Orbit-v0")`` imports the package itself (run outside the
    checkout, whose fir_gym/ folder would shadow the installed package)."""
    code = ("import gymnasium as gym\n"
            "env = gym.make('fir_gym:fir_gym/Orbit-v0', estimator='ekf')\n"
            "print(type(env.reset(seed=0)[0]).__name__)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=tmp_path, check=True)
    assert out.stdout.strip() == "ndarray"
