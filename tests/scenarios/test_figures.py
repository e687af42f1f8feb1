"""The scenarios' figures leave matplotlib's backend alone: importing fir_gym.scenarios (every
scenario module) and drawing a reproduction's figures neither calls ``matplotlib.use`` nor
changes the session's backend, and registers no pyplot figure (a notebook's inline plots
stay as they were)."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from fir_gym.scenarios import SCENARIOS

REPO = Path(__file__).resolve().parents[2]


def test_importing_the_scenarios_and_drawing_leaves_the_backend(tmp_path):
    """In a fresh interpreter whose backend is svg (so a switch to Agg would show) and whose
    ``matplotlib.use`` raises: import every scenario module, run paper 002's quick experiment
    and write its figure. Neither loads stable-baselines3 or PyTorch (``fir-gym reproduce``
    runs on the base install, and each of its workers would carry them)."""
    code = f"""
import importlib, sys
import matplotlib
matplotlib.use("svg")
def refuse(*args, **kwargs):
    raise AssertionError("matplotlib.use was called")
matplotlib.use = refuse
import fir_gym.scenarios
for name in {list(SCENARIOS)!r} + ["_plotting", "paper003_lsm"]:
    importlib.import_module("fir_gym.scenarios." + name)
from fir_gym.scenarios import paper002
report = paper002.run(quick=True, runs=2)
paper002.plot(report, {str(tmp_path)!r})
assert report.images, "no figure written"
pyplot = sys.modules.get("matplotlib.pyplot")
print(matplotlib.get_backend(), 0 if pyplot is None else len(pyplot.get_fignums()))
# the reproduction's figures need only the base install: no rl extra is loaded
print([m for m in ("torch", "stable_baselines3", "fir_gym.training") if m in sys.modules])
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=tmp_path)                 # the installed fir_gym, not the source
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.splitlines() == ["svg 0", "[]"]
    assert (tmp_path / "figures" / "paper002_fig1_vdp.png").stat().st_size > 10_000


@pytest.mark.parametrize("path", sorted((REPO / "fir_gym" / "scenarios").glob("*.py")),
                         ids=lambda p: p.name)
def test_no_scenario_module_selects_a_backend(path):
    """No ``matplotlib.use(...)`` and no pyplot (whose figures a notebook would show, and
    whose first figure resolves a backend) anywhere in fir_gym/scenarios."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            assert not (node.func.attr == "use" and isinstance(node.func.value, ast.Name)
                        and node.func.value.id == "matplotlib"), f"{path.name} calls matplotlib.use"
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in node.names] + [getattr(node, "module", None) or ""]
            assert not any("pyplot" in n for n in names), f"{path.name} imports pyplot"


def test_a_figure_task_draws_what_plot_writes(tmp_path):
    """``draw_task`` (run by a worker) hands back the bytes ``plot`` writes into a folder,
    and ``save_figures`` writes them and records the same images in the report."""
    from fir_gym.scenarios import paper002
    from fir_gym.scenarios.figures import draw_task, save_figures, with_figures
    from fir_gym.scenarios.plan import run_plan

    direct = paper002.run(quick=True, runs=2)
    paper002.plot(direct, tmp_path / "direct")
    done = run_plan(with_figures(paper002.plan(quick=True, runs=2), "paper002"))
    report = save_figures(done, tmp_path / "task")
    assert report.images == direct.images and report.images
    for path in direct.images.values():
        assert (tmp_path / "task" / path).read_bytes() == (tmp_path / "direct" / path).read_bytes()
    images, files = draw_task(("paper002", direct))
    assert images == direct.images and set(files) == set(direct.images.values())


def test_every_figure_the_report_writes_has_labelled_axes_and_legends_off_the_data(
        quick_report, tiny_sweep, tmp_path, monkeypatch):
    """Draw every scenario's figures and inspect each Figure as it is saved: every panel has
    a y label and an x label (its own, or that of a panel sharing its x axis), and every
    legend lies outside its panel. The number of figures inspected is the number of files
    written and of images the reports list, so the check cannot pass on no figure."""
    import importlib

    from matplotlib.figure import Figure

    from fir_gym.scenarios._plotting import unlabelled_axes

    inspected = []
    savefig = Figure.savefig

    def inspect(fig, path, *args, **kwargs):
        out = savefig(fig, path, *args, **kwargs)
        renderer = fig.canvas.get_renderer()
        overlaps = []
        for ax in fig.get_axes():
            legend = ax.get_legend()
            if legend is None:
                continue
            box = legend.get_window_extent(renderer)
            # neither the panel's data area nor its x label
            for other in (ax.get_window_extent(renderer),
                          ax.xaxis.label.get_window_extent(renderer)):
                width = min(box.x1, other.x1) - max(box.x0, other.x0)
                height = min(box.y1, other.y1) - max(box.y0, other.y0)
                if width > 1 and height > 1:
                    overlaps.append(ax.get_title())
        inspected.append((Path(path).name, unlabelled_axes(fig), overlaps))
        return out

    monkeypatch.setattr(Figure, "savefig", inspect)
    images = 0
    for name in SCENARIOS:
        report = (tiny_sweep.run(seed=0, quick=True) if name == "sweeps"
                  else quick_report(name))
        report.images = {}
        importlib.import_module(f"fir_gym.scenarios.{name}").plot(report, tmp_path)
        images += len(report.images)
    written = sorted(p.name for p in (tmp_path / "figures").glob("*.png"))
    assert len(inspected) == len(written) == images >= len(SCENARIOS)
    assert sorted(name for name, _, _ in inspected) == written
    for name, unlabelled, overlaps in inspected:
        assert not unlabelled, f"{name}: panels without an axis label: {unlabelled}"
        assert not overlaps, f"{name}: legends over the data of {overlaps}"


def test_coinciding_curves_are_found_from_their_values():
    from fir_gym.scenarios._plotting import coincidence_note, coincident

    same = coincident({"a": [1.0, 2.0], "b": [1.001, 2.0], "c": [1.2, 2.0], "d": [1.0]})
    assert same == {"b": "a"}
    assert coincidence_note("b", same) == "b (coincides with a)"
    assert coincidence_note("c", same) == "c"
