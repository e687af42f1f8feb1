#!/usr/bin/env python
"""Time ``fir-gym reproduce`` serially, on two joblib workers and on a two-worker Dask cluster.

    python scripts/reproduce_scaling.py [--quick] [--cold] [--backends serial,joblib,dask]
                                        [--repeat N] [--out DIR] [--no-figures]
    python scripts/reproduce_scaling.py --model [--quick] [--workers 2]
    python scripts/reproduce_scaling.py --ceiling

Each backend runs back to back in a fresh process (``python -m fir_gym.cli reproduce``,
imports and kernel loading included), the load average is printed before each run,
and the speed-ups are the serial wall time over each backend's, measured in the same
call. With ``--repeat N`` the backends take turns N times (serial, joblib, dask, serial,
...), so that a slow spell of a shared or virtual machine falls on all of them, and
a backend's speed-up is the median over the rounds of the round's serial wall time over
the backend's (the runs of a round are minutes apart and share the machine's state;
the spread and the ratio of the median wall times are printed too). The REPORT.md
files and the figures are compared byte for byte. ``--cold`` first deletes the numba
cache (the ``*.nbi``/``*.nbc`` files under the installed ``fir_gym.estimators`` and
``fir_gym.envs``), so the first run also compiles the kernels. Timings on a shared
machine are depressed in proportion to its load: read the ratios with the load beside
them.

``--model`` measures what a loaded machine cannot: it runs every task serially in this
process, records each one's CPU time (which the load barely changes), and schedules
them on ``--workers`` ideal workers on a virtual clock, in the order ``execute`` hands
them out (costliest waiting task first, a follow-up stage as soon as its own stage is
done), adding the client's own CPU time (imports, assembly). The figures are tasks too,
as in ``fir-gym reproduce --out``.
The ratio is the speed-up an idle machine would give, before the workers' start-up.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

JOBS = 2


def clear_numba_cache() -> int:
    """Delete the compiled-kernel cache of the installed package; the number of files."""
    import fir_gym.envs
    import fir_gym.estimators

    removed = 0
    for package in (fir_gym.estimators, fir_gym.envs):
        for path in Path(package.__file__).parent.rglob("__pycache__/*.nb[ic]"):
            path.unlink()
            removed += 1
    return removed


def run(backend: str, out: Path, quick: bool, figures: bool) -> float:
    args = [sys.executable, "-m", "fir_gym.cli", "reproduce", "--no-progress"]
    args += ["--quick"] if quick else []
    args += ["--out", str(out.resolve())] if figures else []
    if backend != "serial":
        args += ["--backend", backend, "--jobs", str(JOBS)]
    start = time.perf_counter()
    # run outside any checkout: `python -m` puts the working directory first on sys.path,
    # and a repository's top-level fir_gym/ (without envs/ and estimators/) would shadow
    # the installed package
    done = subprocess.run(args, capture_output=True, text=True, check=False,
                          cwd=tempfile.gettempdir())
    wall = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"{backend} failed:\n{done.stderr[-2000:]}")
    with open(out.parent / f"{backend}.stderr", "a") as log:   # warnings, worker restarts
        log.write(done.stderr)
    if not figures:                                    # the text report on stdout
        out.mkdir(parents=True, exist_ok=True)
        (out / "REPORT.md").write_text(done.stdout)
    return wall


def model(quick: bool, workers: int) -> None:
    """Per-task CPU times, scheduled on ``workers`` ideal workers (see the module docstring)."""
    import concurrent.futures
    import importlib

    from fir_gym.scenarios import SCENARIOS, episodes
    from fir_gym.scenarios.figures import with_figures
    from fir_gym.scenarios.plan import execute
    from fir_gym.scenarios.runner import Runner

    class Simulated(Runner):
        """Runs each task here when it is handed out, timing its CPU, and reports it done
        on a virtual clock as ``workers`` idle workers would: the hand-out order is
        execute's own, with its dependencies between stages."""

        def __init__(self) -> None:
            super().__init__("serial")
            self.now, self.busy, self.tasks = 0.0, 0.0, 0
            self.finish: dict[concurrent.futures.Future, float] = {}

        def slots(self) -> int:
            return workers

        def submit(self, fn, item):  # type: ignore[no-untyped-def]
            t = time.process_time()
            future = super().submit(fn, item)
            took = time.process_time() - t
            self.finish[future] = self.now + took
            self.busy, self.tasks = self.busy + took, self.tasks + 1
            return future

        def wait_any(self, futures):  # type: ignore[no-untyped-def]
            first = min(futures, key=self.finish.__getitem__)
            self.now = self.finish.pop(first)
            return {first}

    start = time.process_time()
    modules = [importlib.import_module(f"fir_gym.scenarios.{n}") for n in SCENARIOS]
    plans = [episodes.plan(0)] + [with_figures(m.plan(seed=0, quick=quick), n)
                                  for m, n in zip(modules, SCENARIOS, strict=True)]
    runner = Simulated()
    t0 = time.process_time()
    execute(plans, runner)
    t1 = time.process_time()

    client = (t0 - start) + (t1 - t0 - runner.busy)
    serial, parallel = client + runner.busy, client + runner.now
    print(f"tasks {runner.tasks}: {runner.busy:.1f} s CPU; client (imports, assembly) "
          f"{client:.1f} s")
    print(f"modelled serial {serial:.1f} s, {workers} workers {parallel:.1f} s: speed-up "
          f"{serial / parallel:.2f}x (before the workers' start-up)")


def _quick_tasks() -> list:  # type: ignore[type-arg]
    """The first-stage tasks of the quick reproduction (the work of the ceiling)."""
    import importlib

    from fir_gym.scenarios import SCENARIOS
    from fir_gym.scenarios.plan import ready_tasks

    plans = [importlib.import_module(f"fir_gym.scenarios.{n}").plan(seed=0, quick=True)
             for n in SCENARIOS]
    return [t for p in plans for t in ready_tasks(p)]


def _run_tasks(_: int) -> float:
    """Run :func:`_quick_tasks` in this process; its wall time."""
    from threadpoolctl import threadpool_limits

    from fir_gym.scenarios.plan import run_task

    tasks = _quick_tasks()
    with threadpool_limits(limits=1, user_api="blas"):
        start = time.perf_counter()
        for task in tasks:
            run_task(task)
        return time.perf_counter() - start


def ceiling() -> None:
    """How much faster two processes get through twice the work than one through once.

    Two worker processes first run the quick reproduction's tasks once each (imports,
    kernels loaded: untimed); then one worker runs them alone, then both run them at
    the same time. ``2 × alone / together`` is the most two workers can give on this
    machine for this work whatever the runner does: below 2 when the two CPUs share a
    physical core, memory bandwidth or a host's time.
    """
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(2) as pool:
        list(pool.map(_run_tasks, [0, 1]))                       # warm, untimed
        alone = pool.submit(_run_tasks, 0).result()
        start = time.perf_counter()
        list(pool.map(_run_tasks, [0, 1]))
        together = time.perf_counter() - start
    print(f"the quick reproduction's tasks: one process alone {alone:.1f} s; two processes, "
          f"each the same work at once, {together:.1f} s; two-worker ceiling "
          f"{2 * alone / together:.2f}x")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fir-gym reproduce --quick")
    p.add_argument("--cold", action="store_true", help="clear the numba cache first")
    p.add_argument("--backends", default="serial,joblib,dask")
    p.add_argument("--repeat", type=int, default=1,
                   help="rounds of the backends in turn; medians are compared (default 1)")
    p.add_argument("--out", default=None, help="where the reports go (default: a temp dir)")
    p.add_argument("--no-figures", action="store_true",
                   help="no --out for fir-gym: time the computation and the text report only")
    p.add_argument("--model", action="store_true",
                   help="per-task CPU times scheduled on ideal workers (module docstring)")
    p.add_argument("--workers", type=int, default=JOBS, help="workers of --model")
    p.add_argument("--ceiling", action="store_true",
                   help="the machine's two-process ceiling for this work (ceiling())")
    args = p.parse_args(argv)
    if args.model:
        model(args.quick, args.workers)
        return 0
    if args.ceiling:
        ceiling()
        return 0
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    root = Path(args.out or tempfile.mkdtemp(prefix="fir-gym-scaling-"))
    if args.cold:
        print(f"cleared {clear_numba_cache()} cached kernel files")
    walls: dict[str, list[float]] = {b: [] for b in backends}
    for round_ in range(args.repeat):
        for b in backends:
            load = os.getloadavg()
            walls[b].append(run(b, root / b, args.quick, not args.no_figures))
            print(f"{b:7s} {walls[b][-1]:7.1f} s   (load average before: {load[0]:.2f} "
                  f"{load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} CPUs)", flush=True)
        if args.repeat > 1 and "serial" in walls:
            print(f"round {round_ + 1}: " + ", ".join(
                f"{b} {walls['serial'][-1] / walls[b][-1]:.2f}x" for b in backends
                if b != "serial"), flush=True)
    same = len({_outputs(root / b) for b in backends}) == 1
    median = {b: statistics.median(w) for b, w in walls.items()}
    if args.repeat > 1:
        print("median wall: " + ", ".join(f"{b} {median[b]:.1f} s" for b in backends))
    if "serial" in walls:
        for b in backends:
            if b != "serial":
                rounds = [s / w for s, w in zip(walls["serial"], walls[b], strict=True)]
                spread = (f" (rounds {min(rounds):.2f}-{max(rounds):.2f}x; median serial over "
                          f"median {b}: {median['serial'] / median[b]:.2f}x)"
                          if args.repeat > 1 else "")
                print(f"speed-up {b} ({JOBS} workers) over serial: "
                      f"{statistics.median(rounds):.2f}x{spread}")
    what = "REPORT.md" if args.no_figures else "REPORT.md and figures"
    print(f"{what} identical on {', '.join(backends)}: {same}   ({root})")
    return 0 if same else 1


def _outputs(folder: Path) -> tuple[tuple[str, bytes], ...]:
    """Every file a run wrote (REPORT.md, the figures), path and bytes."""
    return tuple((str(p.relative_to(folder)), p.read_bytes())
                 for p in sorted(folder.rglob("*")) if p.is_file())


if __name__ == "__main__":
    raise SystemExit(main())
