"""MuJoCo's RK4 step with a force law applied at every stage, and no global callback.

MuJoCo's RK4 evaluates the accelerations at four stages per step. A force written to
``qfrc_applied`` is held across the stages, which is not the ODE's force (for paper
003's friction term it costs ~3e-3 rad/s over 2 s). MuJoCo's passive-force callback
``mjcb_passive`` is called at every stage, but it is global to the process: two
environments in two threads run under each other's force law, and (MuJoCo 4.0) while
a *Python* callback is installed every model compilation in the process fails with
"engine error: Python exception raised".

:class:`StageRK4` therefore runs MuJoCo's RK4 itself, from Python, on one ``MjData``:
the same stages (``mj_forward`` at the start of the step, ``mj_forwardSkip`` at the
three others), the same Butcher tableau and the same floating-point operations in
the same order as ``mj_RungeKutta``, and MuJoCo's own checks (``mj_checkPos``,
``mj_checkVel``, ``mj_checkAcc``, which count a warning in ``d.warning`` and reset
the data when a value is NaN or beyond 1e10). Between MuJoCo's evaluation of a stage
and its use, the stage's accelerations pass through ``law``, which adds the effect of
a force that depends on the stage's state and accelerations. With a law that changes
nothing the step is ``mj_step`` bit for bit (tested), so the law is the only
difference. Nothing is shared between environments: each steps its own model and
data, so threads need no lock.

The step is written for two scalar joints (slide or hinge: ``nq = nv = 2``, no
activations), the pendulum slider's; :class:`StageRK4` refuses any other model.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np
from numpy.typing import NDArray

#: ``law(q0, q1, v0, v1, a0, a1) -> (a0, a1)``: a stage's accelerations with the force
#: applied, from the stage's positions, velocities and MuJoCo's accelerations without it
StageLaw = Callable[[float, float, float, float, float, float], tuple[float, float]]

#: the MuJoCo warnings after which its step resets the data (``mj_checkPos`` and friends)
RESET_WARNINGS = (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                  mujoco.mjtWarning.mjWARN_BADQACC)
_RESET_INDICES = tuple(int(w) for w in RESET_WARNINGS)


def reset_warning(counts: NDArray[np.int32]) -> str | None:
    """The name of the first of :data:`RESET_WARNINGS` counted, else ``None``.

    ``counts`` is ``d.warning.number`` (a live view: take it once). These are the
    warnings after which MuJoCo resets the simulation (``mj_resetData``) and carries on
    from the model's reference state; ``mj_resetData`` clears the counters.
    """
    numbers = counts.tolist()                     # one read; plain-int indices below
    q, v, a = _RESET_INDICES
    if not (numbers[q] or numbers[v] or numbers[a]):                 # the common case
        return None
    return next(str(w.name) for w in RESET_WARNINGS if numbers[int(w)])


class StageRK4:
    """``mj_step`` for RK4 on ``(m, d)``, with each stage's accelerations passed through ``law``.

    ``step(nstep)`` is ``nstep`` such steps; the controls, applied forces and every
    model option are MuJoCo's, read at each stage as ``mj_step`` reads them.
    """

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData, law: StageLaw) -> None:
        if m.nq != 2 or m.nv != 2 or m.na != 0:
            raise ValueError("StageRK4 steps models of two scalar joints (nq = nv = 2, no "
                             f"activations); got nq={m.nq}, nv={m.nv}, na={m.na}")
        if m.opt.integrator != mujoco.mjtIntegrator.mjINT_RK4:
            raise ValueError("StageRK4 reproduces MuJoCo's RK4; the model's integrator is "
                             f"{mujoco.mjtIntegrator(m.opt.integrator).name}")
        self.m, self.d, self.law = m, d, law
        qpos, qvel, qacc = d.qpos, d.qvel, d.qacc          # views, taken once
        forward_skip, no_skip = mujoco.mj_forwardSkip, int(mujoco.mjtStage.mjSTAGE_NONE)

        def stage(x: float, th: float, v: float, w: float, t: float) -> tuple[float, float]:
            """The accelerations at one stage (MuJoCo's, then the law's)."""
            qpos[0], qpos[1], qvel[0], qvel[1] = x, th, v, w
            d.time = t
            forward_skip(m, d, no_skip, 1)                  # 1: skip the sensors
            a0, a1 = qacc.tolist()
            return law(x, th, v, w, a0, a1)
        self._stage = stage

    def step(self, nstep: int = 1) -> None:
        """``nstep`` RK4 steps (``mj_RungeKutta`` with ``A = [½; 0 ½; 0 0 1]``,
        ``b = [⅙ ⅓ ⅓ ⅙]``, after MuJoCo's checks, as in ``mj_step``)."""
        m, d, law, stage = self.m, self.d, self.law, self._stage
        h = m.opt.timestep
        qpos, qvel, qacc = d.qpos, d.qvel, d.qacc
        b0, b1 = 1.0 / 6.0, 1.0 / 3.0
        for _ in range(nstep):
            mujoco.mj_checkPos(m, d)
            mujoco.mj_checkVel(m, d)
            mujoco.mj_forward(m, d)
            mujoco.mj_checkAcc(m, d)
            t0 = d.time
            (x0, th0), (v0, w0) = qpos.tolist(), qvel.tolist()
            ax0, aw0 = law(x0, th0, v0, w0, *qacc.tolist())
            # stage i: X_i = X_0 + h Σ_j A_ij F_j, in mj_RungeKutta's order of operations
            v1, w1 = v0 + h * (0.5 * ax0), w0 + h * (0.5 * aw0)
            ax1, aw1 = stage(x0 + (0.5 * v0) * h, th0 + (0.5 * w0) * h, v1, w1, t0 + 0.5 * h)
            v2, w2 = v0 + h * (0.5 * ax1), w0 + h * (0.5 * aw1)
            ax2, aw2 = stage(x0 + (0.5 * v1) * h, th0 + (0.5 * w1) * h, v2, w2, t0 + 0.5 * h)
            v3, w3 = v0 + h * ax2, w0 + h * aw2
            ax3, aw3 = stage(x0 + v2 * h, th0 + w2 * h, v3, w3, t0 + h)
            # X⁺ = X_0 + h Σ_j b_j F_j (mj_advance: velocities, then positions, then time)
            qvel[0] = v0 + (b0 * ax0 + b1 * ax1 + b1 * ax2 + b0 * ax3) * h
            qvel[1] = w0 + (b0 * aw0 + b1 * aw1 + b1 * aw2 + b0 * aw3) * h
            qpos[0] = x0 + (b0 * v0 + b1 * v1 + b1 * v2 + b0 * v3) * h
            qpos[1] = th0 + (b0 * w0 + b1 * w1 + b1 * w2 + b0 * w3) * h
            d.time = t0 + h
