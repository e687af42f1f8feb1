"""The machine a figure was measured on: CPU model, cores, load.

Every absolute time fir-gym publishes names them (README, ``fir-gym speed --json``, the
robustness benchmark's results.json), since machines of one kind differ in speed by up to
3x and load changes a figure within minutes.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

__all__ = ["cores", "cpu_model", "load_average"]


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``, else the platform's processor string)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def cores() -> int:
    """The cores this process may run on (its CPU affinity, else the CPU count)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def load_average() -> list[float] | None:
    """The 1, 5 and 15-minute load averages, to 0.01 (None where the system has none)."""
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except (AttributeError, OSError):
        return None
