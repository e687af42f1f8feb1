"""The scenarios' figures drawn on the runner's workers, as one more task per scenario.

Drawing a reproduction's figures costs several seconds of matplotlib. Drawn in the
client after the Monte Carlo, that time is serial whatever the backend; as a task,
a scenario's figures are drawn by a worker as soon as its report is final, beside
the tasks of the scenarios still running. The task draws into a temporary folder
and hands back the PNG files' bytes, so it also serves a Dask cluster whose workers
share no disk with the client; the client writes them under its ``--out`` folder.

    plan = with_figures(paper001.plan(seed=0), "paper001")
    report = save_figures(run_plan(plan, runner), out_dir)
"""

from __future__ import annotations

import importlib
import tempfile
from pathlib import Path
from typing import Any

from .plan import Task, followed_by
from .report import Report

#: the hand-out cost of a figure task (seconds, as the Monte Carlo tasks' ``cost``)
FIGURE_COST = 1.0

Drawn = tuple[Report, tuple[dict[str, str], dict[str, bytes]]]


def draw_task(arg: tuple[str, Report]) -> tuple[dict[str, str], dict[str, bytes]]:
    """Draw scenario ``name``'s figures of ``report``: its images (caption -> relative path)
    and each file's bytes (relative path -> PNG)."""
    name, report = arg
    module = importlib.import_module(f"fir_gym.scenarios.{name}")
    with tempfile.TemporaryDirectory(prefix="fir-gym-figures-") as tmp:
        module.plot(report, tmp)
        files = {path: (Path(tmp) / path).read_bytes() for path in report.images.values()}
    return dict(report.images), files


def with_figures(plan: Any, name: str) -> Any:
    """``plan`` (of scenario module ``name``), then its figures drawn as one more task;
    its final value becomes ``(report, drawn)`` for :func:`save_figures`."""
    return followed_by(plan, lambda report: Task(draw_task, (name, report), FIGURE_COST))


def save_figures(done: Drawn, out_dir: str | Path) -> Report:
    """Write the files drawn by :func:`draw_task` under ``out_dir`` and record them in the
    report (as ``plot(report, out_dir)`` would have); the report."""
    report, (images, files) = done
    for path, data in files.items():
        target = Path(out_dir) / path
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    report.images = dict(images)
    return report
