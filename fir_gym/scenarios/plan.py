"""A scenario as a plan: independent tasks for the runner, then assembly in the client.

Each scenario's ``plan(seed, quick, runs)`` returns a :class:`Stage` — its Monte
Carlo split into :class:`Task` s (a module-level function and one argument, each
carrying its own seed), and ``then``, which turns the task results into the report
or into a further plan (work that needs the results of the first, e.g. filters run
on simulated data) — or a :class:`Group` of plans advanced side by side
(:func:`gather`). :func:`execute` runs several plans together as one pool of work:
a task is handed out as soon as it is known, costliest first among those waiting
(``cost`` is a rough estimate in seconds), and a plan's follow-up stage is handed
out as soon as its own stage is done, while the other plans' tasks are still
running, so the workers never wait for a stage of every scenario to end. The task
split never depends on the backend, and every task draws only from its own seed,
so the reports are identical on every backend whatever the order of the work.

    reports = execute([paper000.plan(seed=0), paper001.plan(seed=0)], Runner("joblib", jobs=2))
"""

from __future__ import annotations

import heapq
import itertools
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


@dataclass
class Group:
    """Plans advanced independently, then ``then(values)`` of their final values (in order):
    a value or a further plan. Made by :func:`gather`."""

    plans: Sequence[Any]
    then: Callable[[list[Any]], Any]
    desc: str = field(default="")


def _label(plans: Sequence[Any]) -> str:
    """The descriptions of ``plans``, each once, in order (a progress bar's label)."""
    return ", ".join(dict.fromkeys(p.desc for p in plans if isinstance(p, Stage | Group)
                                   and p.desc))


class _Node:
    """A plan being executed: its current value, and the group waiting for it (if any)."""

    def __init__(self, value: Any, parent: _Node | None = None) -> None:
        self.value, self.parent = value, parent
        self.results: list[Any] = []
        self.left = 0            # tasks of the current stage, or sub-plans of the group, unfinished
        self.children: list[_Node] = []


def execute(plans: Sequence[Any], runner: Runner | None = None, *,
            desc: str | None = None) -> list[Any]:
    """Run ``plans`` to their final values on ``runner``; the values, in order.

    A plan that is neither a :class:`Stage` nor a :class:`Group` is already final.
    Every task known is waiting or running; the runner keeps :meth:`Runner.slots`
    of them handed out, and the costliest waiting task goes next.
    """
    runner = runner or SERIAL
    slots = runner.slots()        # first: a runner that cannot start fails before any work
    waiting: list[tuple[float, int, _Node, int]] = []          # a heap: costliest first
    order = itertools.count()                                 # ties: first known, first out
    bar = runner.bar(desc or _label(plans) or None)

    def advance(node: _Node) -> None:
        """Open ``node``'s current stage or group; once its value is final, tell its group."""
        while True:
            value = node.value
            if isinstance(value, Stage) and value.tasks:
                node.results, node.left = [None] * len(value.tasks), len(value.tasks)
                for j, task in enumerate(value.tasks):
                    heapq.heappush(waiting, (-task.cost, next(order), node, j))
                bar.add(len(value.tasks))
                return
            if isinstance(value, Stage):                       # no tasks: straight on
                node.value = value.then([])
                continue
            if isinstance(value, Group) and value.plans:
                node.children = [_Node(p, node) for p in value.plans]
                node.left = len(node.children)
                for child in node.children:
                    advance(child)
                return
            if isinstance(value, Group):
                node.value = value.then([])
                continue
            parent = node.parent
            if parent is not None:
                parent.left -= 1
                if parent.left == 0:
                    parent.value = parent.value.then([c.value for c in parent.children])
                    parent.children = []
                    advance(parent)
            return

    roots = [_Node(p) for p in plans]
    running: dict[Any, tuple[_Node, int]] = {}
    try:
        for root in roots:
            advance(root)
        while waiting or running:
            while waiting and len(running) < slots:
                _, _, node, j = heapq.heappop(waiting)
                running[runner.submit(run_task, node.value.tasks[j])] = (node, j)
            for future in runner.wait_any(running):
                node, j = running.pop(future)
                node.results[j] = future.result()
                node.left -= 1
                bar.update()
                if node.left == 0:
                    results, node.results = node.results, []
                    node.value = node.value.then(results)
                    advance(node)
    finally:
        for future in running:     # after an error: what has not started does not start
            future.cancel()
        bar.close()
    return [root.value for root in roots]


def gather(plans: Sequence[Any], then: Callable[[list[Any]], Any], desc: str = "") -> Group:
    """One plan of ``plans``, each advanced on its own, then ``then(values)`` of their final
    values: a scenario with two experiments of different depths (one stage, two stages)
    is ``gather([plan_a, plan_b], assemble)``."""
    plans = list(plans)
    return Group(plans, then, desc=desc or _label(plans))


def ready_tasks(plan: Any) -> list[Task]:
    """The tasks ``plan`` can hand out before any result is in (those of its first stages)."""
    if isinstance(plan, Stage):
        return list(plan.tasks)
    if isinstance(plan, Group):
        return [t for p in plan.plans for t in ready_tasks(p)]
    return []


def followed_by(plan: Any, task: Callable[[Any], Task]) -> Any:
    """``plan``, then one more task made from its final value by ``task(value)``: the final
    value becomes ``(value, result)``. The task is handed out as soon as that value is
    known, beside the tasks of plans still running (a scenario's figures: :mod:`.figures`)."""
    if isinstance(plan, Stage):
        return Stage(plan.tasks, lambda results: followed_by(plan.then(results), task),
                     desc=plan.desc)
    if isinstance(plan, Group):
        return Group(plan.plans, lambda values: followed_by(plan.then(values), task),
                     desc=plan.desc)
    return Stage([task(plan)], lambda out: (plan, out[0]))


def run_plan(plan: Any, runner: Runner | None = None) -> Any:
    """``execute([plan], runner)[0]``: one scenario on its own."""
    return execute([plan], runner)[0]
