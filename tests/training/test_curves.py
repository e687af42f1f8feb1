"""training.plot_learning_curves: the figure file, drawn without touching matplotlib's backend."""

import subprocess
import sys

import pytest

pytest.importorskip("matplotlib")


def test_the_learning_curve_figure_leaves_the_backend_and_pyplot_alone(tmp_path):
    """In a fresh interpreter on the svg backend with matplotlib.use refused: the PNG is
    written, the backend is still svg and pyplot holds no figure (nothing a notebook would
    show twice)."""
    code = f"""
import json, pathlib, matplotlib
matplotlib.use("svg")
def refuse(*args, **kwargs):
    raise AssertionError("matplotlib.use was called")
matplotlib.use = refuse
run = pathlib.Path({str(tmp_path)!r}) / "ekf-seed0"
run.mkdir()
rows = ["#" + json.dumps({{"t_start": 0}}), "r,l,t"] + [f"{{-10 + i}},100,{{i}}" for i in range(6)]
(run / "monitor.monitor.csv").write_text("\\n".join(rows) + "\\n")
from fir_gym.training import plot_learning_curves
out = plot_learning_curves({{"ekf": [run], "lqg": []}}, run.parent / "curves.png", title="t")
import matplotlib.pyplot as plt
print(matplotlib.get_backend(), plt.get_fignums(), out.stat().st_size > 1000)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=tmp_path)     # the installed fir_gym, not the source
    assert out.stdout.split() == ["svg", "[]", "True"]


def test_no_finished_episode_writes_no_figure(tmp_path):
    """Runs whose monitors hold no finished episode: no file (not an empty figure), and
    kinds_with_curves names none; one finished episode is enough for a figure."""
    import json

    from fir_gym.training import plot_learning_curves
    from fir_gym.training.curves import kinds_with_curves

    run = tmp_path / "ppo-seed0"
    run.mkdir()
    header = ["#" + json.dumps({"t_start": 0}), "r,l,t"]
    (run / "monitor.monitor.csv").write_text("\n".join(header) + "\n")
    runs = {"ppo": [run], "lqg": []}
    assert kinds_with_curves(runs) == []
    assert plot_learning_curves(runs, tmp_path / "curves.png") is None
    assert not (tmp_path / "curves.png").exists()
    (run / "monitor.monitor.csv").write_text("\n".join([*header, "-5,100,1"]) + "\n")
    assert kinds_with_curves(runs) == ["ppo"]
    assert plot_learning_curves(runs, tmp_path / "curves.png") == tmp_path / "curves.png"
