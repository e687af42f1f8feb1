"""fir_gym.wrappers loads its classes on first use: the names are the modules' own."""

import importlib
import subprocess
import sys

import pytest

import fir_gym.wrappers as wrappers


def test_every_public_name_is_its_modules_object():
    for name in wrappers.__all__:
        module = importlib.import_module(f"fir_gym.wrappers.{wrappers._MODULES[name]}")
        assert getattr(wrappers, name) is getattr(module, name)
    assert sorted(wrappers.__all__) == sorted(wrappers._MODULES)
    assert set(wrappers.__all__) <= set(dir(wrappers))


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="Nope"):
        wrappers.Nope


def test_import_fir_gym_loads_no_estimator_until_an_env_is_built():
    code = ("import sys, gymnasium as gym, fir_gym\n"
            "before = 'fir_gym.estimators' in sys.modules\n"
            "env = gym.make('fir_gym/Orbit-v0', estimator='ekf')\n"
            "print(before, 'fir_gym.estimators' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd="/", timeout=120)
    assert out.stdout.split() == ["False", "True"], out.stderr
