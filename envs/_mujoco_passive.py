"""Exact state-dependent forces inside MuJoCo's integrator, via its passive-force callback.

MuJoCo's RK4 evaluates the forces at four stages per step. A force written to
``qfrc_applied`` is held across the stages, which is not the ODE's force (for
paper 003's friction term it costs ~3e-3 rad/s over 2 s). The passive-force
callback ``mjcb_passive`` is called at every stage, so a force computed there is
the ODE's. But the callback is global to the process, and (MuJoCo 4.0) while a
*Python* passive callback is installed every model compilation in the process
fails — ``MjModel.from_xml_path`` and ``MjSpec.compile`` raise "engine error:
Python exception raised" — so a callback left installed would break every other
MuJoCo environment. :func:`passive_force` therefore installs a force law only
for the duration of its own ``with`` block (the env's ``mj_step`` calls), under a
lock, and restores whatever callback was there before. Several environments in
one process take turns; a thread that compiles a model while another thread is
inside the block would still fail, which is why the block is kept to the steps.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import mujoco

ForceLaw = Callable[[mujoco.MjModel, mujoco.MjData], None]

_lock = threading.RLock()


@contextmanager
def passive_force(law: ForceLaw | None) -> Iterator[None]:
    """Within the block, MuJoCo calls ``law(m, d)`` (which adds to ``d.qfrc_passive``)."""
    if law is None:
        yield
        return
    with _lock:
        previous = mujoco.get_mjcb_passive()
        mujoco.set_mjcb_passive(law)
        try:
            yield
        finally:
            mujoco.set_mjcb_passive(previous)


def step(m: mujoco.MjModel, d: mujoco.MjData, nstep: int, law: ForceLaw | None) -> None:
    """``nstep`` calls of ``mj_step`` with ``law`` installed as in :func:`passive_force`.

    The same as ``with passive_force(law): for _ in range(nstep): mujoco.mj_step(m, d)``,
    without the generator-based context manager (it runs at every env step).
    """
    if law is None:
        mujoco.mj_step(m, d, nstep)
        return
    with _lock:
        previous = mujoco.get_mjcb_passive()
        mujoco.set_mjcb_passive(law)
        try:
            mujoco.mj_step(m, d, nstep)
        finally:
            mujoco.set_mjcb_passive(previous)
