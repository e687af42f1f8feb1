"""Every script in examples/ runs, with small sizes and its output in a temporary folder.

Each script is run as a user runs it (``python examples/NAME.py ...`` in a fresh
interpreter, outside the checkout) and its output is checked for what it claims.
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run(name, *args, cwd):
    result = subprocess.run([sys.executable, str(EXAMPLES / name), *args], cwd=cwd,
                            capture_output=True, text=True, timeout=300,
                            env={**__import__("os").environ, "MUJOCO_GL": "egl"})
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout


def test_every_example_is_tested():
    tested = {"rollout_with_estimator.py", "train_on_estimates.py", "benchmark_episode.py"}
    assert {p.name for p in EXAMPLES.glob("*.py")} == tested


def test_rollout_with_an_estimator_and_a_video(tmp_path):
    imageio = pytest.importorskip("imageio.v2")
    out = run("rollout_with_estimator.py", "--steps", "40", "--out", str(tmp_path / "o"),
              cwd=tmp_path)
    rmse = [float(v) for v in re.findall(r"(?:r|v) ([0-9.e+-]+)", out.splitlines()[0])]
    assert len(rmse) == 2 and all(0 <= v < 1 for v in rmse)    # the EKF tracks the orbit
    assert (tmp_path / "o" / "orbit_ekf.png").stat().st_size > 1000
    frames = imageio.mimread(tmp_path / "o" / "orbit_ekf.gif")
    assert len(frames) == 40 // 5 + 1                            # reset + every 5th step


def test_training_on_estimates(tmp_path):
    pytest.importorskip("stable_baselines3")
    out = run("train_on_estimates.py", "--steps", "128", "--episodes", "2",
              "--episode-steps", "20", "--out", str(tmp_path / "o"), cwd=tmp_path)
    lines = out.splitlines()
    assert lines[0].startswith("PPO on the KF estimate") and lines[1].startswith("LQG")
    # both controllers see the same KF on the same seeds: where the closed loops differ
    # the RMSEs may too, but every figure is a finite number
    for line in lines[:2]:
        numbers = re.findall(r"-?[0-9.]+(?:e[+-]?\d+)?", line.split("return", 1)[1])
        assert numbers and all(abs(float(v)) < 1e6 for v in numbers)
    assert (tmp_path / "o" / "carrier-kf" / "run.json").is_file()


def test_a_scripted_benchmark_episode(tmp_path):
    out = run("benchmark_episode.py", "--steps", "30", cwd=tmp_path)
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines()[2:]}
    assert set(rows) == {"ekf", "ukf", "efir", "cd-ekf", "bpf-kf"}
    for name, cells in rows.items():
        assert all(float(v) >= 0 for v in cells[:2]) and cells[2] in ("yes", "no"), name
