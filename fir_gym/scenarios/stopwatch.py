"""The wall and CPU time of a block of work, its worker processes' CPU included.

``fir-gym reproduce`` prints this at its end (on stderr, never in REPORT.md, which stays
the same bytes for the same seed). The CPU time is this process's
(:func:`time.process_time`) plus its child processes': those that ended during the block
and were waited for (:func:`resource.getrusage` of ``RUSAGE_CHILDREN``: a local Dask
cluster's workers, closed with the runner), and those still running at its end (joblib's
reusable workers, which outlive a run), read with psutil when it is installed.

    with Stopwatch() as watch:
        ...
    print(watch.line("reproduce"))
"""

from __future__ import annotations

import importlib
import os
import time
from dataclasses import dataclass, field
from typing import Any


def _ended_children_cpu() -> float:
    """User + system seconds of this process's children that ended and were waited for."""
    try:
        import resource
    except ImportError:                   # not on Windows
        return 0.0
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _running_children_cpu() -> dict[int, float]:
    """User + system seconds of each child process still running (pid -> seconds); empty
    without psutil."""
    try:                                  # optional: not a dependency of fir-gym
        psutil: Any = importlib.import_module("psutil")
    except ImportError:
        return {}
    out: dict[int, float] = {}
    for child in psutil.Process(os.getpid()).children(recursive=True):
        try:
            cpu = child.cpu_times()
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        out[child.pid] = cpu.user + cpu.system
    return out


@dataclass
class Stopwatch:
    """Times the ``with`` block: :attr:`wall`, :attr:`cpu_self` and :attr:`cpu_workers`
    (seconds), set on exit."""

    wall: float = 0.0
    cpu_self: float = 0.0
    cpu_workers: float = 0.0
    _start: dict[str, Any] = field(default_factory=dict, repr=False)

    def __enter__(self) -> Stopwatch:
        self._start = {"wall": time.perf_counter(), "cpu": time.process_time(),
                       "ended": _ended_children_cpu(), "running": _running_children_cpu()}
        return self

    def __exit__(self, *exc: object) -> None:
        start = self._start
        self.wall = time.perf_counter() - start["wall"]
        self.cpu_self = time.process_time() - start["cpu"]
        running = _running_children_cpu()
        # a child already running at the start counts from where it was then
        self.cpu_workers = (_ended_children_cpu() - start["ended"]
                            + sum(cpu - start["running"].get(pid, 0.0)
                                  for pid, cpu in running.items()))

    @property
    def cpu(self) -> float:
        """This process's CPU seconds and its workers'."""
        return self.cpu_self + self.cpu_workers

    def line(self, what: str) -> str:
        """One line: ``what took W s wall, C s CPU (S s this process, K s workers)``."""
        return (f"{what} took {self.wall:.1f} s wall, {self.cpu:.1f} s CPU ({self.cpu_self:.1f} s "
                f"this process, {self.cpu_workers:.1f} s worker processes)")
