"""The Monte Carlo runner and the plans on it: identical numbers serially, with joblib and on a
local Dask cluster; stages of several plans mapped together, results back in task order."""

import numpy as np
import pytest

from fir_gym.scenarios.plan import Stage, Task, execute, followed_by, gather, run_plan
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
    """A serial runner that records the tasks of every map call."""

    def __init__(self):
        super().__init__("serial")
        self.calls = []

    def map(self, fn, items, *, desc=None):
        items = list(items)
        self.calls.append(items)
        return super().map(fn, items, desc=desc)


def _two_stage(seed):
    first = [Task(noisy_task, (seed + i, 1.0), cost=float(i)) for i in range(3)]

    def second(values):
        total = sum(v.sum() for v in values)
        return Stage([Task(noisy_task, (seed + 10, total))], lambda out: ("done", out[0]))

    return Stage(first, second)


def test_execute_maps_the_stages_of_all_plans_together_costliest_first():
    runner = Recording()
    a, b, c = execute([_two_stage(0), _two_stage(100), "already final"], runner)
    assert c == "already final" and a[0] == b[0] == "done"
    assert len(runner.calls) == 2                             # one map per stage, not per plan
    assert [t.cost for t in runner.calls[0]] == [2.0, 2.0, 1.0, 1.0, 0.0, 0.0]
    # the results are those of each plan on its own, whatever the order of the map
    np.testing.assert_array_equal(a[1], run_plan(_two_stage(0))[1])
    np.testing.assert_array_equal(b[1], run_plan(_two_stage(100))[1])


def test_gather_advances_plans_of_different_depths_side_by_side():
    one = Stage([Task(noisy_task, (1, 1.0))], lambda out: out[0])
    runner = Recording()
    value = run_plan(gather([_two_stage(5), one], lambda values: values), runner)
    assert len(runner.calls) == 2 and len(runner.calls[0]) == 4 and len(runner.calls[1]) == 1
    np.testing.assert_array_equal(value[1], noisy_task((1, 1.0)))
    assert value[0][0] == "done"


def test_plans_give_the_serial_numbers_on_joblib_and_dask():
    pytest.importorskip("distributed")
    serial = execute([_two_stage(3), _two_stage(4)])
    with Runner("joblib", jobs=2) as joblib, Runner("dask", jobs=2) as dask:
        for runner in (joblib, dask):
            for mine, ref in zip(execute([_two_stage(3), _two_stage(4)], runner), serial,
                                 strict=True):
                np.testing.assert_array_equal(mine[1], ref[1])


def test_followed_by_runs_one_more_task_beside_the_plans_still_running():
    """A one-stage plan's extra task joins the second map, with the two-stage plan's second
    stage; the final value is the plan's value and the task's result."""
    one = Stage([Task(noisy_task, (1, 1.0))], lambda out: out[0])
    runner = Recording()
    extra, deep = execute([followed_by(one, lambda v: Task(noisy_task, (2, float(v.sum())))),
                           _two_stage(5)], runner)
    assert [len(c) for c in runner.calls] == [4, 2]
    np.testing.assert_array_equal(extra[0], noisy_task((1, 1.0)))
    np.testing.assert_array_equal(extra[1], noisy_task((2, float(noisy_task((1, 1.0)).sum()))))
    assert deep[0] == "done"
    value, result = run_plan(followed_by("final", lambda v: Task(len, v)))
    assert (value, result) == ("final", 5)


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
