"""docs/tutorials/your-own-plant.md runs as written: its Python blocks, in order, in one
namespace of their own (the PPO block with 256 steps of 8 × 32 instead of 20 000; the full run is
tests/envs/test_model_plant.py's, marked slow)."""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import matplotlib
import numpy as np
import pytest

PAGE = Path(__file__).resolve().parents[1] / "docs" / "tutorials" / "your-own-plant.md"
IDS = ("my_pkg/Pendulum-v0", "my_pkg/UncertainPendulum-v0")


def blocks() -> list[str]:
    text = PAGE.read_text(encoding="utf-8")
    return re.findall(r"^```python\n(.*?)^```", text, re.MULTILINE | re.DOTALL)


@pytest.fixture
def page_namespace(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    matplotlib.use("Agg")
    namespace: dict = {"__name__": "tutorial"}
    yield namespace
    for env_id in IDS:
        gym.registry.pop(env_id, None)


def test_the_tutorial_runs_as_written(page_namespace, tmp_path, capsys):
    code = blocks()
    assert len(code) == 3
    first = code[0]
    # the plant, the EKF, the LQG and the figure in under 40 lines of code
    assert len([line for line in first.splitlines() if line.strip()]) < 40
    ppo = code[2].replace("total_timesteps=20_000", "total_timesteps=256").replace(
        "n_steps=256", "n_steps=32")
    assert ppo != code[2]
    for block in (*code[:2], ppo):
        exec(compile(block, str(PAGE), "exec"), page_namespace)
    ns = page_namespace
    states = np.array(ns["states"])
    # the LQG on the EKF held the pendulum up for the whole episode
    assert ns["truncated"] and not ns["terminated"] and len(states) == 201
    assert np.max(np.abs(states[:, 0])) < 0.3
    assert (tmp_path / "your-own-plant.png").stat().st_size > 10_000
    # the randomized pendulum drew a truth around its nominal g/l
    true_g = ns["info"]["true_params"]["g_over_l"]
    assert true_g != 9.5 and abs(true_g / 9.5 - 1) < 0.25
    assert ns["agent"].num_timesteps >= 256
    capsys.readouterr()
