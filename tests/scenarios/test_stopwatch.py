"""The stopwatch of ``fir-gym reproduce``: wall and CPU time, worker processes included."""

import subprocess
import sys
import time

from fir_gym.scenarios.stopwatch import Stopwatch

BUSY = "import time\nend = time.process_time() + 0.3\nwhile time.process_time() < end: pass"


def test_the_stopwatch_counts_this_process_and_a_child_process():
    """0.3 s of CPU in this process and 0.3 s in a child (which ended: RUSAGE_CHILDREN)."""
    with Stopwatch() as watch:
        end = time.process_time() + 0.3
        while time.process_time() < end:
            pass
        subprocess.run([sys.executable, "-c", BUSY], check=True)
    assert watch.cpu_self >= 0.3 and watch.cpu_workers >= 0.3
    assert watch.wall >= 0.6 and watch.cpu == watch.cpu_self + watch.cpu_workers
    assert watch.line("x").startswith("x took ") and "worker processes" in watch.line("x")
