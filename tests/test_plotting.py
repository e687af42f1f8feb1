"""fir_gym.plotting: each helper draws the data it is given, on the axes it is given, and
never touches matplotlib's backend."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from fir_gym import plotting
from fir_gym.estimators import chi2_band

REPO = Path(__file__).resolve().parents[1]
T, N = 40, 2


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


def data(seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T) * 0.1
    truth = np.cumsum(rng.standard_normal((T, N)), axis=0)
    estimate = truth + 0.3 * rng.standard_normal((T, N))
    L = rng.standard_normal((T, N, N)) * 0.2
    P = L @ np.swapaxes(L, 1, 2) + 0.05 * np.eye(N)
    return t, truth, estimate, P


def band_edges(collection: PolyCollection, t, n=T):
    """The lower and upper curves of a fill_between band of ``n`` points, on the times ``t``."""
    verts = collection.get_paths()[0].vertices
    lower = {round(x, 9): y for x, y in verts[1:n + 1]}
    upper = {round(x, 9): y for x, y in verts[n + 2:2 * n + 2]}
    return (np.array([lower[round(x, 9)] for x in t]),
            np.array([upper[round(x, 9)] for x in t]))


def line(ax, label):
    (found,) = [ln for ln in ax.lines if ln.get_label() == label]
    return found


def test_plot_estimates_draws_truth_estimate_band_and_measurement_per_state():
    t, truth, estimate, P = data()
    y = truth[:, :1] + 0.5
    fig = plotting.plot_estimates(t, estimate, truth, P, measurement=y, names=["r", "v"],
                                  label="EKF")
    assert isinstance(fig, Figure) and len(fig.axes) == N
    sd = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
    for i, ax in enumerate(fig.axes):
        np.testing.assert_array_equal(line(ax, "truth").get_xydata(),
                                      np.column_stack([t, truth[:, i]]))
        np.testing.assert_array_equal(line(ax, "EKF").get_xydata(),
                                      np.column_stack([t, estimate[:, i]]))
        (band,) = [c for c in ax.collections if c.get_label() == "EKF ±2σ"]
        lo, hi = band_edges(band, t)
        np.testing.assert_allclose(lo, estimate[:, i] - 2 * sd[:, i], rtol=1e-12)
        np.testing.assert_allclose(hi, estimate[:, i] + 2 * sd[:, i], rtol=1e-12)
        assert ax.get_ylabel() == ["r", "v"][i]
    np.testing.assert_array_equal(line(fig.axes[0], "measurement").get_ydata(), y[:, 0])
    assert not [ln for ln in fig.axes[1].lines if ln.get_label() == "measurement"]


def test_plot_estimates_adds_a_second_estimator_to_the_same_panels():
    t, truth, estimate, P = data()
    fig = plotting.plot_estimates(t, estimate, truth, P, label="EKF")
    again = plotting.plot_estimates(t, estimate + 1, covariance=P, label="UKF", axes=fig.axes,
                                    sigma=3.0)
    assert again is fig and len(fig.axes) == N
    np.testing.assert_array_equal(line(fig.axes[1], "UKF").get_ydata(), estimate[:, 1] + 1)
    (band,) = [c for c in fig.axes[1].collections if c.get_label() == "UKF ±3σ"]
    lo, _ = band_edges(band, t)
    np.testing.assert_allclose(lo, estimate[:, 1] + 1 - 3 * np.sqrt(P[:, 1, 1]), rtol=1e-12)


def test_plot_estimates_accepts_variances_and_one_state():
    t, truth, estimate, P = data()
    fig = plotting.plot_estimates(t, estimate[:, 0], truth[:, 0], P[:, 0, 0])
    assert len(fig.axes) == 1
    (band,) = fig.axes[0].collections
    _, hi = band_edges(band, t)
    np.testing.assert_allclose(hi, estimate[:, 0] + 2 * np.sqrt(P[:, 0, 0]), rtol=1e-12)


def test_plot_errors_draws_truth_minus_estimate_and_a_band_about_zero():
    t, truth, estimate, P = data()
    import matplotlib.pyplot as plt

    given, axes = plt.subplots(N, 1)
    fig = plotting.plot_errors(t, estimate, truth, P, axes=axes)
    assert fig is given
    for i, ax in enumerate(fig.axes):
        np.testing.assert_array_equal(line(ax, "error").get_ydata(), truth[:, i] - estimate[:, i])
        (band,) = [c for c in ax.collections if c.get_label() == "±2σ"]
        lo, hi = band_edges(band, t)
        np.testing.assert_allclose(hi, 2 * np.sqrt(P[:, i, i]), rtol=1e-12)
        np.testing.assert_allclose(lo, -hi, rtol=1e-12)


@pytest.mark.parametrize("helper, dof", [(plotting.plot_nees, 2), (plotting.plot_nis, 1)])
def test_consistency_plots_draw_the_values_and_their_chi2_band(helper, dof):
    t = np.arange(T) * 0.1
    rng = np.random.default_rng(1)
    runs = rng.chisquare(dof, size=(25, T))
    fig = helper(t, runs, dof=dof, confidence=0.99)
    (ax,) = fig.axes
    (values,) = [ln for ln in ax.lines if ln.get_label() in ("NEES", "NIS")]
    np.testing.assert_allclose(values.get_ydata(), runs.mean(axis=0))
    (span,) = [p for p in ax.patches if "χ²" in p.get_label()]
    ys = span.get_path().transformed(span.get_patch_transform()).vertices[:, 1]
    np.testing.assert_allclose([ys.min(), ys.max()], chi2_band(dof, 25, 0.99), rtol=1e-12)
    assert "25 runs" in ax.get_ylabel() and ax.get_yscale() == "log"
    one = helper(t, runs[0], dof=dof, log=False)
    (span,) = [p for p in one.axes[0].patches if "χ²" in p.get_label()]
    ys = span.get_path().transformed(span.get_patch_transform()).vertices[:, 1]
    np.testing.assert_allclose([ys.min(), ys.max()], chi2_band(dof, 1, 0.95), rtol=1e-12)
    with pytest.raises(ValueError, match="runs"):
        helper(t, runs, dof=dof, runs=3)


def write_run(folder: Path, episodes_per_file):
    """A run folder as SB3's Monitor writes it: a JSON line, a header, then r,l,t rows."""
    (folder / "monitor").mkdir(parents=True)
    for k, episodes in enumerate(episodes_per_file):
        lines = ["#" + json.dumps({"t_start": 0.0, "env_id": "x"}), "r,l,t"]
        lines += [f"{r},{length},{i}" for i, (r, length) in enumerate(episodes)]
        (folder / "monitor" / f"{k}.monitor.csv").write_text("\n".join(lines) + "\n")


def test_plot_learning_curves_draws_each_run_and_averages_seeds(tmp_path):
    # 3 bins over 300 steps: edges 0, 100, 200, 300; episodes end at steps 100, 200, 300,
    # so bin 0 is empty, bin 1 holds the first episode, bin 2 the other two
    write_run(tmp_path / "a", [[(-10.0, 100), (-5.0, 100), (-2.0, 100)]])
    write_run(tmp_path / "b", [[(-12.0, 100), (-7.0, 100), (-1.0, 100)]])
    write_run(tmp_path / "none", [[]])
    fig = plotting.plot_learning_curves(tmp_path / "a", bins=3)
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_xydata(),
                                  [[50.0, np.nan], [150.0, -10.0], [250.0, -3.5]])
    fig = plotting.plot_learning_curves({"ekf": [tmp_path / "a", tmp_path / "b"],
                                         "true": tmp_path / "none"}, bins=3)
    (ax,) = fig.axes
    (mean,) = ax.lines
    # the empty bin takes its neighbour's value: a [-10, -10, -3.5], b [-12, -12, -4]
    np.testing.assert_allclose(mean.get_ydata(), [-11.0, -11.0, -3.75])
    assert mean.get_label() == "ekf" and len(ax.collections) == 1        # the seeds' spread
    lo, hi = band_edges(ax.collections[0], [50.0, 150.0, 250.0], 3)
    np.testing.assert_allclose(hi - lo, [2.0, 2.0, 0.5])                 # ± std of 2 seeds
    assert any("true" in text.get_text() for text in ax.texts)          # said, not dropped


def test_bad_shapes_name_the_argument():
    t, truth, estimate, P = data()
    with pytest.raises(ValueError, match="truth"):
        plotting.plot_estimates(t, estimate, truth[:-1])
    with pytest.raises(ValueError, match="covariance"):
        plotting.plot_estimates(t, estimate, covariance=P[:, :1])
    with pytest.raises(ValueError, match="measured"):
        plotting.plot_estimates(t, estimate, measurement=truth, measured=[0, 5])
    with pytest.raises(ValueError, match="axes must hold 2"):
        import matplotlib.pyplot as plt

        plotting.plot_errors(t, estimate, truth, axes=plt.subplots(3, 1)[1])


def test_the_helpers_never_change_the_backend(tmp_path):
    """In a fresh interpreter: importing fir_gym.plotting and drawing every kind of figure
    leaves the backend as the session set it, and never calls matplotlib.use."""
    code = """
import matplotlib
matplotlib.use("svg")
def refuse(*args, **kwargs):
    raise AssertionError("matplotlib.use was called")
matplotlib.use = refuse
import numpy as np
import fir_gym, fir_gym.plotting as p, fir_gym.training, fir_gym.wrappers
t = np.arange(5.0); x = np.zeros((5, 2)); P = np.tile(np.eye(2), (5, 1, 1))
p.plot_estimates(t, x, x, P); p.plot_errors(t, x, x, P); p.plot_nees(t, t + 1, dof=2)
p.plot_nis(t, t + 1, dof=1)
print(matplotlib.get_backend())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=tmp_path)     # the installed fir_gym, not the source
    assert out.stdout.strip() == "svg"
    assert matplotlib.rcParams._get("backend") is not None           # this session: untouched


def test_no_module_of_the_plotting_package_calls_matplotlib_use():
    for path in sorted((REPO / "fir_gym" / "plotting").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                assert node.func.attr != "use" or not (
                    isinstance(node.func.value, ast.Name) and node.func.value.id == "matplotlib"
                ), f"{path.name} calls matplotlib.use"
