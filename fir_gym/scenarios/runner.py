"""Where the Monte Carlo runs: in this process, on local cores (joblib) or on a Dask cluster.

A scenario splits its Monte Carlo into independent tasks — a module-level
function and one argument per task, each task carrying its own seed — and hands
them to :meth:`Runner.map`. The result list is in the order of the arguments
whatever the backend, and every random draw of a task comes from its own seed,
so the same seeds give bit-identical numbers serially, with joblib and on Dask.

    runner = Runner("joblib", jobs=2)
    results = runner.map(simulate_one, [(seed, settings) for seed in seeds])

:meth:`Runner.submit` and :meth:`Runner.wait_any` hand out one task at a time, as
:class:`concurrent.futures.Future`-like objects, for a caller that decides what to
run next from what has finished (:func:`.plan.execute`); :meth:`Runner.slots` says
how many to keep handed out.
"""

from __future__ import annotations

import concurrent.futures
import importlib
import os
import threading
import warnings
from collections.abc import Callable, Collection, Iterable, Sequence
from typing import Any

from fir_gym.estimators._validation import one_of

BACKENDS = ("serial", "joblib", "dask")

#: the Dask configuration of the workers of a local cluster the runner starts
LOCAL_WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                       "distributed.worker.memory.monitor-interval": "1s",
                       "distributed.admin.system-monitor.interval": "2s"}


class Runner:
    """Map a picklable function over task arguments with one of :data:`BACKENDS`.

    Args:
        backend: ``"serial"`` (this process), ``"joblib"`` (local processes: joblib's
            ``loky`` process pool) or ``"dask"`` (a ``distributed`` cluster).
        jobs: worker processes for joblib (default: the number of CPUs); for a
            Dask *local* cluster, its number of workers.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``); with
            ``backend="dask"`` and no address a local cluster is started (and closed
            by :meth:`close`).
        progress: show a progress bar (tqdm, when installed) per :meth:`map` call.
        blas_threads: BLAS threads per worker task on joblib and Dask (default 1: the
            scenarios' matrices are small, and more threads per worker only oversubscribe
            the cores); ``None`` leaves the workers' BLAS alone.
    """

    def __init__(self, backend: str = "serial", *, jobs: int | None = None,
                 scheduler: str | None = None, progress: bool = False,
                 blas_threads: int | None = 1) -> None:
        one_of("backend", backend, BACKENDS)
        if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1):
            raise ValueError(f"jobs must be a positive integer or None; got {jobs!r}")
        if scheduler is not None and backend != "dask":
            raise ValueError("scheduler is an option of the dask backend")
        if blas_threads is not None and (isinstance(blas_threads, bool)
                                         or not isinstance(blas_threads, int) or blas_threads < 1):
            raise ValueError(f"blas_threads must be a positive integer or None; got "
                             f"{blas_threads!r}")
        self.backend, self.jobs, self.scheduler, self.progress = backend, jobs, scheduler, progress
        self.blas_threads = blas_threads
        self._client: Any = None
        self._cluster: Any = None
        self._warming: threading.Thread | None = None
        self._warm_error: BaseException | None = None

    def start(self, modules: Sequence[str] = ()) -> None:
        """Start the workers now, in the background, each importing ``modules``.

        A worker's start-up (spawning, importing the scenarios and their estimators)
        then overlaps the client's own imports and planning instead of delaying the
        first :meth:`map`, which waits for it. Serially it does nothing. A failure
        here (a missing extra, an unreachable scheduler) is raised by that first map.
        """
        if self._in_process() or self._warming is not None:
            return
        if self.backend == "joblib":
            self._loky_executor()          # created here, not in the thread

        def warm() -> None:
            try:
                if self.backend == "joblib":
                    self._map_now(import_modules, [tuple(modules)] * self._n_jobs(), None)
                else:
                    self._dask_client().run(import_modules, tuple(modules))
            except BaseException as err:   # handed to the first map, in the caller's thread
                self._warm_error = err

        self._warming = threading.Thread(target=warm, name="fir-gym runner start",
                                         daemon=True)
        self._warming.start()

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any], *, desc: str | None = None
            ) -> list[Any]:
        """``[fn(item) for item in items]``, in order, on the chosen backend."""
        items = list(items)
        self._wait_for_start()
        if not items:
            return []
        return self._map_now(fn, items, desc)

    def submit(self, fn: Callable[[Any], Any], item: Any) -> Any:
        """Hand out ``fn(item)``; a future whose ``result()`` is its value (or raises its
        error). In this process the task runs before ``submit`` returns."""
        self._wait_for_start()
        if self._in_process():
            future: concurrent.futures.Future[Any] = concurrent.futures.Future()
            try:
                future.set_result(fn(item))
            except Exception as err:      # raised by result(), as from a worker
                future.set_exception(err)
            return future
        fn = self._limited(fn)
        if self.backend == "joblib":
            return self._loky_executor().submit(fn, item)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Sending large graph")
            return self._dask_client().submit(fn, item, pure=False)

    def wait_any(self, futures: Collection[Any]) -> set[Any]:
        """Block until at least one of ``futures`` (from :meth:`submit`) is done; the done ones."""
        if self.backend == "dask":
            from distributed import wait

            return set(wait(list(futures), return_when="FIRST_COMPLETED").done)
        done, _ = concurrent.futures.wait(futures, return_when=concurrent.futures.FIRST_COMPLETED)
        return done

    def slots(self) -> int:
        """How many tasks to keep handed out at once: one in this process; elsewhere one per
        worker and one more, waiting, so that a worker that finishes finds its next task."""
        self._wait_for_start()
        if self._in_process():
            return 1
        if self.backend == "joblib":
            return self._n_jobs() + 1
        return sum(self._dask_client().nthreads().values()) + 1

    def bar(self, desc: str | None = None) -> _Progress:
        """A progress bar for work whose size is learnt on the way (``add(n)`` as tasks become
        known, ``update()``, ``close()``); silent without ``progress`` or tqdm.

        A plan's follow-up stage is known only once its own stage is done, so the total
        grows: the bar shows the tasks done and those known so far, and no percentage or
        time remaining (:data:`GROWING_BAR_FORMAT`), which a growing total would make a guess.
        """
        bar = self._bar([], desc, total=0, bar_format=GROWING_BAR_FORMAT)
        return _Progress(bar if hasattr(bar, "update") else None)

    def _map_now(self, fn: Callable[[Any], Any], items: list[Any], desc: str | None
                 ) -> list[Any]:
        if self._in_process():
            return [fn(item) for item in self._bar(items, desc)]
        fn = self._limited(fn)
        if self.backend == "joblib":
            executor = self._loky_executor()
            pending = [executor.submit(fn, item) for item in items]
            try:
                return [f.result() for f in self._bar(pending, desc, total=len(items))]
            except BaseException:
                for future in pending:   # a task failed: those not started do not start
                    future.cancel()
                raise
        client = self._dask_client()
        with warnings.catch_warnings():
            # each task's argument is its own data, sent once: dask's advice to scatter
            # large graphs does not apply
            warnings.filterwarnings("ignore", message="Sending large graph")
            futures = client.map(fn, items, pure=False)
        if self.progress:
            from distributed import as_completed

            for _ in self._bar(as_completed(futures), desc, total=len(futures)):
                pass
        return client.gather(futures)

    def close(self) -> None:
        """Shut down a local Dask cluster started by this runner."""
        if self._warming is not None:
            self._warming.join()
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self) -> Runner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"Runner(backend={self.backend!r}, jobs={self.jobs}, "
                f"scheduler={self.scheduler!r})")

    # ------------------------------------------------------------------ helpers
    def _wait_for_start(self) -> None:
        if self._warming is not None:
            self._warming.join()
            self._warming = None
        if self._warm_error is not None:
            err, self._warm_error = self._warm_error, None
            raise err

    def _in_process(self) -> bool:
        """Whether tasks run in this process: serially, or on a single joblib job."""
        return self.backend == "serial" or (self.backend == "joblib" and self._n_jobs() == 1)

    def _n_jobs(self) -> int:
        return self.jobs or os.cpu_count() or 1

    def _limited(self, fn: Callable[[Any], Any]) -> Callable[[Any], Any]:
        return fn if self.blas_threads is None else LimitedBlas(fn, self.blas_threads)

    def _loky_executor(self) -> Any:
        """joblib's process pool (loky's reusable executor: its workers outlive a map, and
        one pool serves every runner of this process with the same number of jobs)."""
        from joblib.externals.loky import get_reusable_executor

        return get_reusable_executor(max_workers=self._n_jobs())

    def _dask_client(self) -> Any:
        if self._client is None:
            from distributed import Client, LocalCluster

            if self.scheduler:
                self._client = Client(self.scheduler)
            else:
                import dask

                # the tasks are seconds of CPU each: a worker's statistical profiler (a
                # stack sample every 10 ms) and its 0.1 s memory monitor only take the GIL
                # from them
                with dask.config.set(LOCAL_WORKER_CONFIG):
                    self._cluster = LocalCluster(n_workers=self.jobs or 2, threads_per_worker=1,
                                                 processes=True, dashboard_address=None)
                self._client = Client(self._cluster)
        return self._client

    def _bar(self, iterable: Iterable[Any], desc: str | None, total: int | None = None,
             bar_format: str | None = None) -> Iterable[Any]:
        if not self.progress:
            return iterable
        try:
            from tqdm.auto import tqdm
        except ImportError:  # tqdm is a dependency; a stripped install just shows no bars
            return iterable
        return tqdm(iterable, desc=desc, total=total, leave=False, bar_format=bar_format)


#: the line of :meth:`Runner.bar`: counts and the time elapsed, no percentage and no ETA
GROWING_BAR_FORMAT = "{desc}: {n_fmt} tasks done of {total_fmt} known so far [{elapsed}]"


class _Progress:
    """A tqdm bar whose total grows (or nothing, for ``None``)."""

    def __init__(self, bar: Any) -> None:
        self._bar = bar

    def add(self, n: int) -> None:
        if self._bar is not None:
            self._bar.total += n          # shown at the next update

    def update(self, n: int = 1) -> None:
        if self._bar is not None:
            self._bar.update(n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()

    def line(self) -> str:
        """The bar's current line as drawn ("" without a bar)."""
        return "" if self._bar is None else str(self._bar)


class LimitedBlas:
    """``fn`` run with at most ``threads`` BLAS threads (the ``fir-gym`` command runs its own
    process with one): a picklable wrapper for the workers.
    """

    def __init__(self, fn: Callable[[Any], Any], threads: int = 1) -> None:
        self.fn, self.threads = fn, threads

    def __call__(self, item: Any) -> Any:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=self.threads, user_api="blas"):
            return self.fn(item)


def import_modules(modules: Sequence[str]) -> None:
    """Import ``modules`` in this process (:meth:`Runner.start`'s task for each worker)."""
    for name in modules:
        importlib.import_module(name)


def seeded_normals(task: tuple[int, float]) -> Any:
    """An example task: ``scale`` times three standard normals drawn from ``seed``.

    Tasks must be importable by worker processes (a module-level function of an
    installed module); this one serves the runner's tests and examples.
    """
    import numpy as np

    seed, scale = task
    return scale * np.random.default_rng(seed).standard_normal(3)


def blas_threads(_: Any = None) -> int:
    """The largest BLAS thread count this process allows (a task for the runner's tests)."""
    from threadpoolctl import threadpool_info

    return max((int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"),
               default=0)


#: the runner used when a scenario is called without one
SERIAL = Runner("serial")
