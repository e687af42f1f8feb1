"""The Monte Carlo runner and the plans on it: identical numbers serially, with joblib and on a
local Dask cluster; stages of several plans mapped together, results back in task order."""

import numpy as np
import pytest

from fir_gym.scenarios.plan import (
    Stage,
    Task,
    execute,
    followed_by,
    gather,
    ready_tasks,
    run_plan,
)
from fir_gym.scenarios.runner import Runner, blas_threads
from fir_gym.scenarios.runner import seeded_normals as noisy_task

TASKS = [(seed, 2.0) for seed in range(7)]


def test_serial_and_joblib_agree_bit_for_bit():
    serial = Runner("serial").map(noisy_task, TASKS)
    parallel = Runner("joblib", jobs=2).map(noisy_task, TASKS)
    assert len(serial) == len(TASKS)
    for a, b in zip(serial, parallel, strict=True):
        np.testing.assert_array_equal(a, b)


def test_workers_run_tasks_with_the_blas_threads_asked_for():
    """The tasks see the BLAS thread limit in the worker (threadpoolctl's own report)."""
    limited = Runner("joblib", jobs=2).map(blas_threads, [0, 1])
    assert all(n <= 1 for n in limited)
    assert Runner("joblib", jobs=2, blas_threads=None).map(blas_threads, [0]) is not None


def test_dask_local_cluster_agrees_bit_for_bit():
    pytest.importorskip("distributed")
    serial = Runner("serial").map(noisy_task, TASKS)
    with Runner("dask", jobs=2) as runner:
        distributed = runner.map(noisy_task, TASKS)
        # the local cluster's workers run without the statistical profiler
        import dask

        profiling = runner._dask_client().run(dask.config.get,
                                              "distributed.worker.profile.enabled")
        assert len(profiling) == 2 and not any(profiling.values())
    for a, b in zip(serial, distributed, strict=True):
        np.testing.assert_array_equal(a, b)


def test_bad_arguments():
    with pytest.raises(ValueError, match="backend"):
        Runner("spark")
    with pytest.raises(ValueError, match="jobs"):
        Runner("joblib", jobs=0)
    with pytest.raises(ValueError, match="scheduler"):
        Runner("joblib", scheduler="tcp://x:1")
    with pytest.raises(ValueError, match="blas_threads"):
        Runner("joblib", blas_threads=0)
    assert Runner().map(noisy_task, []) == []


class Recording(Runner):
    """A serial runner that records the arguments of the tasks in the order handed out."""

    def __init__(self):
        super().__init__("serial")
        self.handed = []

    def submit(self, fn, item):
        self.handed.append(item.arg)
        return super().submit(fn, item)


class VirtualWorkers(Recording):
    """``workers`` idle workers on a virtual clock: a task takes its ``cost`` in seconds.
    Records (arg, start) as handed out."""

    def __init__(self, workers):
        super().__init__()
        self.workers, self.now, self.finish = workers, 0.0, {}

    def slots(self):
        return self.workers

    def submit(self, fn, item):
        future = super().submit(fn, item)
        self.handed[-1] = (item.arg, self.now)
        self.finish[future] = self.now + item.cost
        return future

    def wait_any(self, futures):
        first = min(futures, key=self.finish.__getitem__)
        self.now = self.finish.pop(first)
        return {first}


def _two_stage(seed):
    first = [Task(noisy_task, (seed + i, 1.0), cost=float(i)) for i in range(3)]

    def second(values):
        total = sum(v.sum() for v in values)
        return Stage([Task(noisy_task, (seed + 10, total))], lambda out: ("done", out[0]))

    return Stage(first, second)


def test_execute_hands_out_costliest_first_and_a_follow_up_as_soon_as_its_stage_is_done():
    """Serially (one slot): the first stages by cost; plan a's second stage (cost 1) goes
    out as soon as a's last first-stage task is in, before b's cost-0 task still waiting."""
    runner = Recording()
    a, b, c = execute([_two_stage(0), _two_stage(100), "already final"], runner)
    assert c == "already final" and a[0] == b[0] == "done"
    seeds = [arg[0] for arg in runner.handed]
    assert seeds == [2, 102, 1, 101, 0, 10, 100, 110]
    # the results are those of each plan on its own, whatever the order of the work
    np.testing.assert_array_equal(a[1], run_plan(_two_stage(0))[1])
    np.testing.assert_array_equal(b[1], run_plan(_two_stage(100))[1])


def test_a_follow_up_stage_runs_beside_another_plans_long_task():
    """Two workers: plan ``slow`` is one 10 s task; the two-stage plan's second stage starts
    at 2 s (its first stage: 0 + 1 + 2 s on the other worker), not after the 10 s task, as
    one map per stage would have it; the run ends at 10 s."""
    slow = Stage([Task(noisy_task, (50, 1.0), cost=10.0)], lambda out: out[0])
    runner = VirtualWorkers(2)
    done_slow, done_fast = execute([slow, _two_stage(0)], runner)
    started = {arg[0]: at for arg, at in runner.handed}
    assert started == {50: 0.0, 2: 0.0, 1: 2.0, 0: 3.0, 10: 3.0}
    assert runner.now == 10.0
    np.testing.assert_array_equal(done_slow, noisy_task((50, 1.0)))
    assert done_fast[0] == "done"


def test_gather_advances_plans_of_different_depths_each_on_its_own():
    one = Stage([Task(noisy_task, (1, 1.0))], lambda out: out[0])
    runner = Recording()
    value = run_plan(gather([_two_stage(5), one, "final"], lambda values: values), runner)
    np.testing.assert_array_equal(value[1], noisy_task((1, 1.0)))
    assert value[0][0] == "done" and value[2] == "final"
    assert len(runner.handed) == 5
    # nested groups, empty stages and empty groups reach their values too
    nested = gather([gather([one, Stage([], lambda out: "empty")], tuple), gather([], len)],
                    lambda values: values)
    inner, zero = run_plan(nested)
    np.testing.assert_array_equal(inner[0], noisy_task((1, 1.0)))
    assert inner[1] == "empty" and zero == 0
    assert [t.arg for t in ready_tasks(nested)] == [(1, 1.0)]


def test_an_error_in_a_task_or_an_assembly_reaches_the_caller():
    broken = Stage([Task(noisy_task, ("not a seed", 1.0))], lambda out: out)
    with pytest.raises(TypeError):
        execute([_two_stage(0), broken])
    with pytest.raises(ZeroDivisionError):
        run_plan(Stage([Task(noisy_task, (1, 1.0))], lambda out: 1 / 0))
    with Runner("joblib", jobs=2) as runner:
        with pytest.raises(TypeError):
            execute([_two_stage(0), broken], runner)
        assert execute([_two_stage(0)], runner)[0][0] == "done"        # still usable


@pytest.mark.parametrize("backend", ["serial", "joblib", "dask"])
def test_submit_wait_any_and_slots(backend):
    if backend == "dask":
        pytest.importorskip("distributed")
    serial = Runner("serial").map(noisy_task, TASKS)
    with Runner(backend, jobs=2) as runner:
        assert runner.slots() == (1 if backend == "serial" else 3)
        futures = {runner.submit(noisy_task, task): k for k, task in enumerate(TASKS)}
        got = {}
        while futures:
            for future in runner.wait_any(list(futures)):
                got[futures.pop(future)] = future.result()
    for k, ref in enumerate(serial):
        np.testing.assert_array_equal(got[k], ref)


def test_plans_give_the_serial_numbers_on_joblib_and_dask():
    pytest.importorskip("distributed")
    serial = execute([_two_stage(3), _two_stage(4)])
    with Runner("joblib", jobs=2) as joblib, Runner("dask", jobs=2) as dask:
        for runner in (joblib, dask):
            for mine, ref in zip(execute([_two_stage(3), _two_stage(4)], runner), serial,
                                 strict=True):
                np.testing.assert_array_equal(mine[1], ref[1])


def test_followed_by_runs_one_more_task_beside_the_plans_still_running():
    """A one-stage plan's extra task is handed out as soon as that plan is final, before
    the two-stage plan's cheaper first-stage tasks; the final value is the plan's value and
    the task's result. A group can be followed too."""
    one = Stage([Task(noisy_task, (1, 1.0), cost=5.0)], lambda out: out[0])
    runner = Recording()
    extra, deep = execute([followed_by(one, lambda v: Task(noisy_task, (2, float(v.sum())),
                                                           cost=3.0)),
                           _two_stage(5)], runner)
    assert [arg[0] for arg in runner.handed] == [1, 2, 7, 6, 5, 15]
    np.testing.assert_array_equal(extra[0], noisy_task((1, 1.0)))
    np.testing.assert_array_equal(extra[1], noisy_task((2, float(noisy_task((1, 1.0)).sum()))))
    assert deep[0] == "done"
    value, result = run_plan(followed_by("final", lambda v: Task(len, v)))
    assert (value, result) == ("final", 5)
    grouped = followed_by(gather([one, "x"], lambda values: values[1]), lambda v: Task(len, v))
    assert run_plan(grouped) == ("x", 1)


@pytest.mark.parametrize("backend", ["joblib", "dask"])
def test_start_warms_the_workers_and_the_first_map_waits_for_it(backend):
    """``start`` imports the modules on the workers in the background; the numbers of the
    maps after it are the serial ones, and a module that cannot be imported fails the
    first map (in the caller's thread), not silently."""
    if backend == "dask":
        pytest.importorskip("distributed")
    serial = Runner("serial").map(noisy_task, TASKS)
    with Runner(backend, jobs=2) as runner:
        runner.start(["fir_gym.scenarios.plan", "json"])
        for a, b in zip(runner.map(noisy_task, TASKS), serial, strict=True):
            np.testing.assert_array_equal(a, b)
    with Runner(backend, jobs=2) as runner:
        runner.start(["fir_gym.no_such_module"])
        with pytest.raises(ModuleNotFoundError, match="no_such_module"):
            runner.map(noisy_task, TASKS)
        assert len(runner.map(noisy_task, TASKS)) == len(TASKS)     # reported once
    Runner("serial").start(["fir_gym.no_such_module"])             # serially: nothing to do


def test_a_failing_task_fails_the_map_and_the_runner_stays_usable():
    with Runner("joblib", jobs=2) as runner:
        with pytest.raises(TypeError):
            runner.map(noisy_task, [*TASKS, ("not a seed", 1.0)])
        assert len(runner.map(noisy_task, TASKS)) == len(TASKS)


def test_the_reproduce_bar_shows_counts_and_no_time_remaining():
    """The total of :meth:`Runner.bar` grows as follow-up stages become known, so its line
    shows the tasks done and known so far and the time elapsed, never a percentage or an
    ETA (tqdm's ``<remaining``); rendered as text, no terminal needed. Without ``progress``
    it draws nothing."""
    bar = Runner("serial", progress=True).bar("reproduce")
    try:
        bar.add(3)
        bar.update()
        bar.add(2)                        # a follow-up stage: the total grows
        bar.update(2)
        line = bar.line()
    finally:
        bar.close()
    assert line.startswith("reproduce: 3 tasks done of 5 known so far [")
    assert "%" not in line and "<" not in line and "?" not in line and "it/s" not in line
    silent = Runner("serial").bar("reproduce")
    silent.add(3)
    silent.update()
    assert silent.line() == ""
