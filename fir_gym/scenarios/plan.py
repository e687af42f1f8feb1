"""A scenario as a plan: independent tasks for the runner, then assembly in the client.

Each scenario's ``plan(seed, quick, runs)`` returns a :class:`Stage` — its Monte
Carlo split into :class:`Task` s (a module-level function and one argument, each
carrying its own seed), and ``then``, which turns the task results into the report
or into a further stage (work that needs the results of the first, e.g. filters
run on simulated data). :func:`execute` runs the stages of several plans
together, so that one :meth:`Runner.map` call holds the tasks of every scenario
and the workers stay busy across scenario boundaries; tasks are handed out
costliest first (their ``cost`` is a rough estimate in seconds), and the results
come back in task order. The task split never depends on the backend, and every
task draws only from its own seed, so the reports are identical on every backend.

    reports = execute([paper000.plan(seed=0), paper001.plan(seed=0)], Runner("joblib", jobs=2))
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from .runner import SERIAL, Runner


@dataclass(frozen=True)
class Task:
    """``fn(arg)`` on a worker; ``cost`` orders the hand-out (largest first)."""

    fn: Callable[[Any], Any]
    arg: Any
    cost: float = 1.0


def run_task(task: Task) -> Any:
    """Run one :class:`Task` (the function the runner maps)."""
    return task.fn(task.arg)


@dataclass
class Stage:
    """Tasks, and what to make of their results (in task order): a value or the next stage."""

    tasks: Sequence[Task]
    then: Callable[[list[Any]], Any]
    desc: str = field(default="")


def execute(plans: Sequence[Any], runner: Runner | None = None, *,
            desc: str | None = None) -> list[Any]:
    """Run every :class:`Stage` of ``plans`` on ``runner``; the final values, in order.

    A plan that is not a :class:`Stage` is already final. The first stages of all
    plans are mapped together, then their follow-up stages, and so on.
    """
    runner = runner or SERIAL
    pending = list(plans)
    while True:
        open_ = [i for i, p in enumerate(pending) if isinstance(p, Stage)]
        if not open_:
            return pending
        batch = [(i, j, t) for i in open_ for j, t in enumerate(pending[i].tasks)]
        order = sorted(range(len(batch)), key=lambda b: -batch[b][2].cost)   # stable: ties keep
        label = desc or ", ".join(dict.fromkeys(pending[i].desc for i in open_ if pending[i].desc))
        out = runner.map(run_task, [batch[b][2] for b in order], desc=label or None)
        results: dict[int, list[Any]] = {i: [None] * len(pending[i].tasks) for i in open_}
        for b, value in zip(order, out, strict=True):
            i, j, _ = batch[b]
            results[i][j] = value
        for i in open_:
            pending[i] = pending[i].then(results[i])


def gather(plans: Sequence[Any], then: Callable[[list[Any]], Any], desc: str = "") -> Any:
    """One plan that advances ``plans`` side by side, stage by stage, then ``then(values)``.

    A scenario with two experiments of different depths (one stage, two stages) is
    ``gather([plan_a, plan_b], assemble)``: each stage of the result holds the next
    tasks of every plan that still has some.
    """
    plans = list(plans)
    open_ = [i for i, p in enumerate(plans) if isinstance(p, Stage)]
    if not open_:
        return then(plans)
    sizes = [len(plans[i].tasks) for i in open_]

    def advance(results: list[Any]) -> Any:
        nxt, start = list(plans), 0
        for i, n in zip(open_, sizes, strict=True):
            nxt[i] = plans[i].then(results[start:start + n])
            start += n
        return gather(nxt, then, desc)

    return Stage([t for i in open_ for t in plans[i].tasks], advance,
                 desc=desc or ", ".join(dict.fromkeys(plans[i].desc for i in open_)))


def followed_by(plan: Any, task: Callable[[Any], Task]) -> Any:
    """``plan``, then one more task made from its final value by ``task(value)``: the final
    value becomes ``(value, result)``. The task joins the next map of :func:`execute`, beside
    the tasks of plans still running (a scenario's figures: :mod:`.figures`)."""
    if isinstance(plan, Stage):
        return Stage(plan.tasks, lambda results: followed_by(plan.then(results), task),
                     desc=plan.desc)
    return Stage([task(plan)], lambda out: (plan, out[0]))


def run_plan(plan: Any, runner: Runner | None = None) -> Any:
    """``execute([plan], runner)[0]``: one scenario on its own."""
    return execute([plan], runner)[0]
