"""Pendulum on a spring-loaded slider, simulated in MuJoCo: paper 003's plant."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from fir_gym.estimators._validation import FloatArray, as_covariance, one_of, positive

from ._base import PlantEnv, saturated_cost, state_failure
from ._conditions import per_system
from ._design import DesignPoint
from ._mujoco_rk4 import StageLaw, StageRK4, reset_warning
from ._overlay import CameraView
from .pendulum_slider_dynamics import (
    EQUATIONS,
    FRICTION_MODES,
    PAPER_PARAMS,
    PendulumSliderDynamics,
)

ASSET = Path(__file__).parent / "assets" / "pendulum_slider.xml"
PAPER_R_STD = (0.003, 0.03, 0.03, 0.3)
#: contact settings of the "coulomb" mode: stiff enough that the stick band does not creep
RAIL_SOLREF = (0.002, 1.0)
RAIL_SOLIMP = (0.99, 0.9999, 0.0001, 0.5, 2.0)


def refuse_batch(friction: Any) -> None:
    """Refuse, in one line, an option the native vector env's analytic equations cannot
    reproduce: ``friction="coulomb"`` is MuJoCo's rail contact, not an ODE."""
    if friction == "coulomb":
        raise ValueError("friction='coulomb' is MuJoCo's rail contact, which the native vector "
                         "env of PendulumSlider-v0 (the analytic equations of motion) cannot "
                         "reproduce; use friction='paper' or 'none', or single MuJoCo envs "
                         "(gym.make_vec(..., vectorization_mode='sync'))")


class PaperFrictionForce:
    """Paper 003's sign-free friction term, solved exactly at every RK4 stage.

    Eq (15) (with the errata of docs/papers.md#003-eq-15) adds to the slider the force
    ``F = -μ [(m1 + m2) g + m2 l cosθ θ̇² + m2 l sinθ θ̈]`` (μ times the rail's normal
    force, without sign(ẋ)). It depends on θ̈, which depends on ``F``: with
    ``q̈ = q̈₀ + M⁻¹ e_x F`` (``q̈₀`` MuJoCo's accelerations without ``F``), ``F = c₀ + c₁ θ̈``
    gives ``F = (c₀ + c₁ θ̈₀) / (1 - c₁ [M⁻¹]_θx)``.

    :attr:`law` is that force as a :data:`~fir_gym.envs._mujoco_rk4.StageLaw`: from a
    stage's state and MuJoCo's accelerations ``q̈₀`` (spring, hinge damping, gravity,
    Coriolis, motor and applied forces, all MuJoCo's), the accelerations with ``F``. It
    runs at each of the four RK4 stages, so it is float arithmetic with the 2-DOF mass
    matrix of this MJCF model in closed form, ``M = [[m1 + m2, −m2 l cosθ], [−m2 l cosθ,
    I_c + m2 l²]]``. :meth:`reference_force` computes ``F`` from MuJoCo's own bias
    forces (``mj_rne``) and mass-matrix solve (``mj_solveM``); the tests check that
    MuJoCo's accelerations with that force applied are the law's to round-off.
    """

    def __init__(self, model: mujoco.MjModel, mu: float, m1: float, m2: float, l: float,
                 g: float, I_c: float) -> None:
        self.mu, self.weight, self.m2l = mu, (m1 + m2) * g, m2 * l
        self.mt, self.J = m1 + m2, I_c + m2 * l * l
        self.x_dof = int(model.jnt_dofadr[model.joint("x").id])
        self.th_dof = int(model.jnt_dofadr[model.joint("theta").id])
        self.th_qpos = int(model.jnt_qposadr[model.joint("theta").id])
        self.gear = float(model.actuator_gear[0, 0])
        if model.nv != 2 or (self.x_dof, self.th_dof) != (0, 1):
            raise ValueError("PaperFrictionForce is for the 2-DOF pendulum slider")
        nv = model.nv
        self._bias = np.zeros(nv)
        self._rhs = np.zeros((2, nv))
        self._rhs[1, self.x_dof] = 1.0
        self._sol = np.zeros((2, nv))
        #: the stage law (a closure over the constants: it runs four times per step)
        self.law = self._make_law()

    def _make_law(self) -> StageLaw:
        m2l, mt, J = self.m2l, self.mt, self.J
        mu, weight, sin, cos = self.mu, self.weight, math.sin, math.cos

        def law(x: float, th: float, v: float, w: float, ax: float, aw: float
                ) -> tuple[float, float]:
            s, c = sin(th), cos(th)
            M12 = -m2l * c
            det = mt * J - M12 * M12
            minv_tx = -M12 / det                         # [M⁻¹]_θx (= [M⁻¹]_xθ)
            c0 = -mu * (weight + m2l * c * w * w)
            c1 = -mu * m2l * s
            force = (c0 + c1 * aw) / (1.0 - c1 * minv_tx)
            return ax + (J / det) * force, aw + minv_tx * force
        return law

    def reference_force(self, m: mujoco.MjModel, d: mujoco.MjData) -> float:
        """The same force from MuJoCo's ``mj_rne`` and ``mj_solveM`` (the law's oracle)."""
        mujoco.mj_rne(m, d, 0, self._bias)           # bias forces at this stage's state
        rhs = self._rhs[0]
        np.subtract(d.qfrc_passive, self._bias, out=rhs)
        rhs += d.qfrc_applied
        rhs[self.x_dof] += self.gear * d.ctrl[0]
        mujoco.mj_solveM(m, d, self._sol, self._rhs)
        th, w = float(d.qpos[self.th_qpos]), float(d.qvel[self.th_dof])
        c0 = -self.mu * (self.weight + self.m2l * math.cos(th) * w * w)
        c1 = -self.mu * self.m2l * math.sin(th)
        sol = self._sol
        return (c0 + c1 * sol[0, self.th_dof]) / (1.0 - c1 * sol[1, self.th_dof])


class PendulumSliderEnv(PlantEnv):
    """
    ## Description

    A slider on a horizontal rail, held by a spring (stiffness 2k, rest position
    l0), carries a pendulum hinged with viscous friction M0; a motor pushes the
    slider. Paper 003 ("UKF-based state and parameter estimation of a
    pendulum-slider") estimates the states and the friction parameters μ and M0
    with a UKF on the state augmented with [μ, M0] and compares it with least
    squares. The plant is modelled in MuJoCo (``envs/assets/pendulum_slider.xml``,
    Table 3: m1 = 0.654 kg, m2 = 0.7925 kg, l = 0.2 m, I_c = 0.0014 kg m², k = 100
    N/m, l0 = 0.025 m, M0 = 0.2 N m s/rad, μ = 0.2, g = 9.8) with RK4 at 1 ms.

    Friction of the slider on the rail (``friction``):

    * ``"paper"`` — eq (15)'s term ``-μ N`` with the true normal force ``N`` and no
      sign(ẋ): a constant push that moves the rest position from 25 mm to
      10.8 mm. It is applied exactly at every RK4 stage: the env runs MuJoCo's RK4
      step itself with the force added to each stage's accelerations (no global
      callback, so envs in several threads do not disturb each other; see
      ``fir_gym.envs._mujoco_rk4``), and the plant equals an RK4 integration of the
      corrected ODE to round-off;
    * ``"coulomb"`` — real dry friction: the slider rests on the rail (a vertical
      joint and a box-on-plane contact with friction μ, stiff ``solref``), so the
      friction is ``μ N sign(ẋ)`` with the true normal force and the slider sticks
      inside the band ``|2k (x - l0)| < μ N`` without creeping;
    * ``"none"``.

    Equations of motion (``dynamics``):

    * ``"physical"`` (default) — the Lagrangian's, simulated by MuJoCo as above;
    * ``"printed-eq15"``, ``"printed-eq5"`` — paper 003's printed eq (15) or eq (5)
      (:mod:`fir_gym.envs.pendulum_slider_dynamics` gives their errata: the wrong
      centripetal sign, ``m1 l²`` for ``m2 l²`` and, in eq 5, an asymmetric mass
      matrix that creates energy). They are **unphysical** and offered only to run
      the paper's experiment as printed. MuJoCo cannot simulate them (its mass matrix
      is the physical one), so the plant integrates the printed ODE by the same RK4
      (1 ms, ``frame_skip`` substeps per env step, the input held) that the filter's
      model uses, and copies the state into MuJoCo only for rendering. They carry the
      paper's sign-free friction term: ``friction`` must be ``"paper"``.

    ## Action Space

    | Num | Action                                  | Min | Max |
    |-----|-----------------------------------------|-----|-----|
    | 0   | motor force U, in units of `force_max`  | -1  | 1   |

    ``U = action * force_max`` (10 N) is held over the env step.

    ## Observation Space

    All four states measured with Gaussian noise ``R = diag([0.003, 0.03, 0.03,
    0.3]²)`` (paper 003; drawn in Python from the env's generator):

    | Num | Observation    | Unit  |
    |-----|----------------|-------|
    | 0   | x + v0         | m     |
    | 1   | ẋ + v1         | m/s   |
    | 2   | θ + v2         | rad   |
    | 3   | θ̇ + v3         | rad/s |

    (±inf bounds: the noise is Gaussian; Gymnasium's checker warns.)

    ## State (``info["state"]``)

    ``[x, ẋ, θ, θ̇]`` (θ = 0 hanging down). ``info["force"]`` is the applied force (N).

    ## Rewards

    Damp the swing and hold the slider at its rest position ``x_rest`` (10.8 mm
    with the paper's friction, l0 otherwise) with little force, per second of
    simulated time: the cost ``c = θ² + 0.1 θ̇² + 100 (x - x_rest)² + 0.01 action²``,
    saturated at 20 (the slider at the end of the rail with the pendulum upside down
    costs about 19), times ``Δt / 0.01`` (``Δt`` = 1 ms × ``frame_skip``): the reward
    is ``-min(c, 20) · Δt / 0.01``, in ``[-cost_cap, 0]`` with
    ``cost_cap = 2 · frame_skip`` (θ is not wrapped: a pendulum that spins over the
    top pays the cap).

    ## Starting State

    ``[x_rest, 0, 0.5, 0]`` plus ``N(0, diag(0, 0, 0.1², 0))``: a swing to damp.
    Paper 003's experiment starts from rest: ``initial_state=(x_rest, 0, 0, 0),
    initial_state_cov=None``.

    ## Episode End

    Termination when the slider leaves the rail (``|x - l0| > 0.3`` m) or the state
    is not finite; the terminating step is paid
    ``-cost_cap * (1 + steps left to max_episode_steps)``, so leaving the rail early
    never pays. Truncation at ``max_episode_steps`` = 5000 steps (5 s at the default
    1 kHz) by the registered ``TimeLimit``.

    ## Arguments

    ``gym.make("fir_gym/PendulumSlider-v0", friction="paper", dynamics="physical", frame_skip=1,
    force_max=10.0, R=diag(PAPER_R_STD²), Q=None, nominal=None, initial_state=None,
    initial_state_cov=None, max_episode_steps=5000, randomize=None, burst=None,
    render_mode=None, width=480, height=360, **params)``,
    ``params`` among ``m1, m2, l, I_c, k, l0, M0, mu, g``. ``frame_skip`` MuJoCo
    steps of 1 ms make one env step. ``Q`` is the true process noise added to the
    state after each env step (none by default: MuJoCo is deterministic); the
    model's ``Q`` defaults to paper 003's 1e-6 per state (``nominal={"Q": ...}``).
    ``nominal`` may change any physical parameter, ``R``, ``Q``, ``friction`` or
    ``dynamics`` for the model, a :class:`~fir_gym.estimators.augment.ParametricModel` whose
    parameters ``[μ, M0]`` can be estimated jointly with the state.
    ``randomize`` draws the true ``mu`` and ``M0`` (the two parameters paper 003
    identifies) and ``force_max`` (the motor's gain) around the nominal ones every episode
    (the simulation's hinge damping, friction law and force scale follow the draw; the
    reward's ``x_rest`` and the starting state stay the constructor's: the task does not
    move with the draw); ``burst`` stretches the increments over a window of steps and
    puts the stretched state back into MuJoCo, where the next step starts
    (docs/robustness.md#plant-conditions).

    ``gym.make_vec("fir_gym/PendulumSlider-v0", n, vectorization_mode="vector_entry_point")``
    steps ``n`` systems at once by the RK4 of the equations above (the physical ones equal
    MuJoCo's step to round-off), the conditions per system; it refuses
    ``friction="coulomb"``, MuJoCo's rail contact (docs/envs/pendulum-slider.md#vector-env).

    ## Version History

    * v0: initial version.
    """

    state_names: ClassVar[tuple[str, ...]] = ("x", "x_dot", "theta", "theta_dot")
    measurement_names: ClassVar[tuple[str, ...]] = ("x_measured", "x_dot_measured",
                                                    "theta_measured", "theta_dot_measured")
    action_names: ClassVar[tuple[str, ...]] = ("force",)
    #: default FIR window (20 ms at 1 kHz)
    default_horizon: ClassVar[int] = 20
    #: the slider's colour in the MJCF (the legend's "truth")
    truth_color: ClassVar[tuple[int, int, int]] = (209, 84, 46)
    #: MuJoCo's ``mjMAXVAL``: beyond it MuJoCo resets its simulation at the next step
    state_limit: ClassVar[float] = 1e10
    metadata = {"render_modes": ["rgb_array"], "render_fps": 100}  # noqa: RUF012
    default_max_episode_steps: ClassVar[int] = 5000
    #: the cap of the bracketed cost (before the Δt / 0.01 scaling)
    BRACKET_CAP: ClassVar[float] = 20.0
    #: the rail friction μ and hinge damping M0 (what paper 003 identifies), the motor's gain
    randomizable: ClassVar[tuple[str, ...]] = ("mu", "M0", "force_max")

    def __init__(
        self,
        *,
        friction: str = "paper",
        dynamics: str = "physical",
        frame_skip: int = 1,
        force_max: float = 10.0,
        R: ArrayLike | None = None,
        Q: ArrayLike | None = None,
        nominal: Mapping[str, Any] | None = None,
        initial_state: ArrayLike | None = None,
        initial_state_cov: ArrayLike | None = "swing",
        max_episode_steps: int | None = None,
        randomize: Mapping[str, float] | None = None,
        burst: Any = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 360,
        **physical: float,
    ) -> None:
        unknown = sorted(set(physical) - set(PAPER_PARAMS))
        if unknown:
            raise TypeError(f"unexpected keyword argument(s) {unknown}; physical parameters are "
                            f"{sorted(PAPER_PARAMS)}")
        one_of("friction", friction, FRICTION_MODES)
        one_of("dynamics", dynamics, EQUATIONS)
        if dynamics != "physical" and friction != "paper":
            raise ValueError(f"dynamics={dynamics!r} (paper 003's printed equations) carries the "
                             f"paper's own friction term; friction must be 'paper', got "
                             f"{friction!r}")
        phys = {**PAPER_PARAMS, **{k: float(v) for k, v in physical.items()}}
        for name in ("m1", "m2", "l", "I_c", "k", "g"):
            positive(name, phys[name])
        for name in ("M0", "mu"):
            if not np.isfinite(phys[name]) or phys[name] < 0:
                raise ValueError(f"{name} must be a finite non-negative number; got {phys[name]!r}")
        params: dict[str, Any] = {
            **phys,
            "friction": friction,
            "dynamics": dynamics,
            "frame_skip": positive("frame_skip", frame_skip, integer=True),
            "force_max": positive("force_max", force_max),
            "R": as_covariance("R", np.square(PAPER_R_STD) if R is None else R, 4, definite=True),
            "Q": np.zeros((4, 4)) if Q is None else as_covariance("Q", Q, 4),
        }
        self.x_rest = self._rest_position(params)
        if initial_state is None:
            initial_state = (self.x_rest, 0.0, 0.5, 0.0)
        if isinstance(initial_state_cov, str):
            if initial_state_cov != "swing":
                raise ValueError(f"initial_state_cov must be 'swing', None or a 4x4 covariance; "
                                 f"got {initial_state_cov!r}")
            initial_state_cov = np.diag([0.0, 0.0, 0.1**2, 0.0])
        super().__init__(params=params, nominal=nominal,
                         default_nominal={"Q": np.full(4, 1e-6)},
                         initial_state=initial_state, initial_state_cov=initial_state_cov,
                         measurement_cov=params["R"], render_mode=render_mode,
                         max_episode_steps=max_episode_steps, randomize=randomize, burst=burst)
        self._reward_scale = self.params["frame_skip"] * 0.1
        self.cost_cap = self.BRACKET_CAP * self._reward_scale
        self.width, self.height = positive("width", width, integer=True), \
            positive("height", height, integer=True)
        self._set_process_noise(self.params["Q"])
        #: the equations of motion with forces in newtons and no parameters of their own:
        #: the printed ODE a single env integrates in place of MuJoCo, and every batched step
        self._ode = self._make_dynamics({**self.params, "force_max": 1.0})
        #: the true ``[μ, M0]`` (``(2,)``, or ``(B, 2)`` per system) and force scale (N per
        #: unit of action: a float, or ``(B,)``) the transition reads (:meth:`_apply_params`)
        self._theta: FloatArray = np.array([self.params["mu"], self.params["M0"]])
        self._force_max: Any = self.params["force_max"]
        #: the ``(μ, M0)`` MuJoCo simulates (restored when a copy rebuilds the simulation)
        self._simulated = (float(self.params["mu"]), float(self.params["M0"]))
        self._drawing_data: mujoco.MjData | None = None
        self._build_simulation()

    # ------------------------------------------------------------------ simulation
    @staticmethod
    def _rest_position(params: Mapping[str, Any]) -> float:
        """Slider rest position: ``l0 - μ (m1 + m2) g / 2k`` with the paper's push, else ``l0``."""
        if params["friction"] != "paper":
            return float(params["l0"])
        return float(params["l0"] - params["mu"] * (params["m1"] + params["m2"]) * params["g"]
                     / (2.0 * params["k"]))

    def _build_simulation(self) -> None:
        p = self.params
        spec = mujoco.MjSpec.from_file(str(ASSET))
        x_joint, th_joint = spec.joint("x"), spec.joint("theta")
        # MuJoCo 4 keeps polynomial coefficients [linear, quadratic, cubic]: set the linear one
        x_joint.stiffness = [2.0 * p["k"], 0.0, 0.0]
        x_joint.springref = p["l0"]
        th_joint.damping = [p["M0"], 0.0, 0.0]
        slider, pendulum = spec.body("slider"), spec.body("pendulum")
        slider.mass = p["m1"]
        pendulum.mass = p["m2"]
        pendulum.ipos = [0.0, 0.0, -p["l"]]
        pendulum.inertia = [p["I_c"]] * 3
        spec.option.gravity = [0.0, 0.0, -p["g"]]
        if p["friction"] == "coulomb":
            slider.add_joint(name="z", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1])
            for geom in (spec.geom("slider"), spec.geom("rail")):
                geom.contype = geom.conaffinity = 1
                geom.condim = 3
                geom.friction = [p["mu"], 0.0, 0.0]
                geom.solref = list(RAIL_SOLREF)
                geom.solimp = list(RAIL_SOLIMP)
            # the slider box's bottom face (z = -0.015) rests on the rail's top face
        self.mj_model = spec.compile()
        self.mj_data = mujoco.MjData(self.mj_model)
        m = self.mj_model
        self._qpos = [int(m.jnt_qposadr[m.joint(n).id]) for n in ("x", "theta")]
        self._dof = [int(m.jnt_dofadr[m.joint(n).id]) for n in ("x", "theta")]
        self._z_rest = self._settle_vertical() if p["friction"] == "coulomb" else None
        # views into mj_data, read at every step (a view per attribute access costs more)
        self._qpos_view, self._qvel_view = self.mj_data.qpos, self.mj_data.qvel
        self._ctrl_view = self.mj_data.ctrl
        self._warning_counts = self.mj_data.warning.number
        self._renderer: mujoco.Renderer | None = None
        self._configure_simulation(*self._simulated)
        mujoco.mj_forward(m, self.mj_data)           # its drawing is its state (see _scene)

    def _configure_simulation(self, mu: float, M0: float) -> None:
        """Make MuJoCo simulate the friction ``μ`` and hinge damping ``M0``: the θ joint's
        damping, and the paper's friction law at every RK4 stage (``"paper"``) or the rail
        contact's friction coefficient (``"coulomb"``)."""
        p, m = self.params, self.mj_model
        m.dof_damping[self._dof[1]] = M0
        self._friction_law: PaperFrictionForce | None = None
        self._stage_rk4: StageRK4 | None = None
        if p["friction"] == "paper":
            self._friction_law = PaperFrictionForce(m, mu, p["m1"], p["m2"], p["l"], p["g"],
                                                    p["I_c"])
            self._stage_rk4 = StageRK4(m, self.mj_data, self._friction_law.law)
        elif p["friction"] == "coulomb":
            for geom in ("slider", "rail"):
                m.geom_friction[m.geom(geom).id, 0] = mu
        self._simulated = (mu, M0)

    def _apply_params(self, params: Mapping[str, Any]) -> None:
        """The true ``μ``, ``M0`` and ``force_max`` (numbers, or ``(B,)`` arrays: a native vector
        env's per-system draws) for the transition; a single env's MuJoCo simulation too."""
        mu, M0, force_max = params["mu"], params["M0"], params["force_max"]
        self._force_max = force_max
        if per_system(mu, M0, force_max):        # a batch: the analytic equations read them
            self._theta = np.stack(np.broadcast_arrays(np.asarray(mu, dtype=np.float64),
                                                       np.asarray(M0, dtype=np.float64)), -1)
            return
        self._theta = np.array([float(mu), float(M0)])
        self._configure_simulation(float(mu), float(M0))

    def _settle_vertical(self) -> float:
        """The slider's resting height on the rail (contact penetration), found once."""
        m, d = self.mj_model, self.mj_data
        z_adr = int(m.jnt_qposadr[m.joint("z").id])
        mujoco.mj_resetData(m, d)
        d.qpos[self._qpos[0]] = self.params["l0"]
        for _ in range(300):
            mujoco.mj_step(m, d)
        return float(d.qpos[z_adr])

    def _write_state(self, x: FloatArray, data: mujoco.MjData | None = None) -> None:
        """Put MuJoCo's data (the simulation's, or ``data``) at the state ``x``."""
        m, d = self.mj_model, self.mj_data if data is None else data
        mujoco.mj_resetData(m, d)
        d.qpos[self._qpos] = x[[0, 2]]
        d.qvel[self._dof] = x[[1, 3]]
        if self._z_rest is not None:
            d.qpos[int(m.jnt_qposadr[m.joint("z").id])] = self._z_rest
        mujoco.mj_forward(m, d)

    def _read_state(self) -> FloatArray:
        return np.array(self._simulated_state())

    def _simulated_state(self) -> list[float]:
        """MuJoCo's ``[x, ẋ, θ, θ̇]``, as Python floats."""
        qpos, qvel = self._qpos_view, self._qvel_view
        return [qpos.item(self._qpos[0]), qvel.item(self._dof[0]),
                qpos.item(self._qpos[1]), qvel.item(self._dof[1])]

    def _holds(self, x: FloatArray) -> bool:
        """Whether MuJoCo's data is at the state ``x`` (a single env's, after its step)."""
        return bool(x.tolist() == self._simulated_state())

    # ------------------------------------------------------------------ plant hooks
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[FloatArray, dict[str, Any]]:
        obs, info = super().reset(seed=seed, options=options)
        self._write_state(self.state)
        return obs, info

    def _transition(self, x: FloatArray, a: FloatArray, k: Any, rng: np.random.Generator
                    ) -> tuple[FloatArray, dict[str, Any]]:
        if x.ndim != 1:
            return self._batched_transition(x, a, rng)
        force = float(a[0]) * self._force_max
        if self.params["dynamics"] != "physical":
            return self._printed_transition(x, a, force, rng)
        if not self._holds(x):      # a state MuJoCo does not hold (set by hand): start there
            self._write_state(x)
        d = self.mj_data
        self._ctrl_view[0] = force
        self.advance_physics()
        failure = reset_warning(self._warning_counts)
        if failure is not None:
            # MuJoCo found a NaN or a value beyond 1e10 and reset its data: the step failed
            # (the base class ends the episode and restores ``x``, see _restore)
            return x.copy(), {"force": force, "simulation_failure": failure}
        x_next = self._read_state()
        if self._has_process_noise:
            x_next = x_next + self._process_sqrt @ rng.standard_normal(4)
            self._write_state(x_next)
            d.ctrl[0] = force
        return x_next, {"force": force}

    def _printed_transition(self, x: FloatArray, a: FloatArray, force: float,
                            rng: np.random.Generator) -> tuple[FloatArray, dict[str, Any]]:
        """One env step of the printed ODE (RK4); MuJoCo only mirrors the state for drawing."""
        x_next = self._ode.propagate(x, a * self._force_max, self._theta)[0]
        if self._has_process_noise:
            x_next = x_next + self._process_sqrt @ rng.standard_normal(4)
        if np.isfinite(x_next).all():      # a failed step is the base class's to report
            self._write_state(x_next)
        return x_next, {"force": force}

    @classmethod
    def check_vector_options(cls, options: dict[str, Any]) -> None:
        """``friction="coulomb"`` (MuJoCo's rail contact) is refused by the native vector env."""
        refuse_batch(options.get("friction"))

    def advance_physics(self) -> None:
        """MuJoCo's steps of one env step (``frame_skip`` of them, with the friction law's
        stage-wise force where there is one), from ``mj_data`` as it is: the physics alone,
        no measurement, reward or checks."""
        if self._stage_rk4 is None:
            mujoco.mj_step(self.mj_model, self.mj_data, self.params["frame_skip"])
        else:
            self._stage_rk4.step(self.params["frame_skip"])

    def _batched_transition(self, x: FloatArray, a: FloatArray, rng: np.random.Generator
                            ) -> tuple[FloatArray, dict[str, Any]]:
        """One env step of ``B`` systems (a native vector env): the RK4 of the equations of
        motion (:class:`PendulumSliderDynamics`, compiled for the physical ones), each system
        with its true ``[μ, M0]`` and force scale. With the paper's friction (or none) it is
        the ODE MuJoCo integrates, by the same RK4 and step: the two agree to round-off."""
        refuse_batch(self.params["friction"])
        U = a[:, 0] * self._force_max                                  # (B,) newtons
        x_next = self._ode.propagate(x, U[:, None], self._theta)[0]
        if self._has_process_noise:
            # drawn batch first, (B, 4): row i is the standard_normal(4) a single env draws;
            # a stacked matrix-vector product, so each row is a single env's ``S @ n`` bits
            n = rng.standard_normal(x.shape)
            x_next = x_next + (self._process_sqrt @ n[:, :, None])[:, :, 0]
        return x_next, {"force": U}

    def _sample_initial_state(self, rng: np.random.Generator, n: int | None = None
                              ) -> FloatArray:
        if n is not None:                      # the first batched hook of a vector env
            refuse_batch(self.params["friction"])
        return super()._sample_initial_state(rng, n)

    def _perturb(self, x: FloatArray, x_next: FloatArray, extra: dict[str, Any], delta: Any
                 ) -> tuple[FloatArray, dict[str, Any]]:
        """The burst's stretched state, put back into MuJoCo (one system): the next step starts
        from MuJoCo's data."""
        x_next, extra = super()._perturb(x, x_next, extra, delta)
        if x_next.ndim == 1 and state_failure(x_next, self.state_limit) is None:
            self._write_state(x_next)
            self.mj_data.ctrl[0] = extra["force"]
        return x_next, extra

    def _restore(self, x: FloatArray) -> None:
        self._write_state(x)

    def _noise_free_measurement(self, x: FloatArray, extra: dict[str, Any] | None) -> FloatArray:
        return x.copy()

    def _reward(self, x: FloatArray, a: FloatArray, x_next: FloatArray) -> Any:
        p: Any                                 # floats (one system) or (B,) arrays
        th: Any
        w: Any
        u: Any
        if x_next.ndim == 1:
            # Python floats, without numpy's per-scalar overhead; products, not ``**``, so
            # that a huge finite state overflows to inf (then the cap), never raises
            p, _, th, w = x_next.tolist()
            u = a.item(0)
        else:                                  # the same operations, in the same order
            p, th, w, u = x_next[:, 0], x_next[:, 2], x_next[:, 3], a[:, 0]
        e = p - self.x_rest
        cost = th * th + 0.1 * w * w + 100.0 * e * e + 0.01 * u * u
        return -saturated_cost(cost, self.BRACKET_CAP) * self._reward_scale

    def _in_domain(self, x: FloatArray) -> Any:
        if x.ndim != 1:
            return np.isfinite(x).all(axis=-1) & (np.abs(x[..., 0] - self.params["l0"]) <= 0.3)
        xs = x.tolist()
        return all(map(math.isfinite, xs)) and abs(xs[0] - self.params["l0"]) <= 0.3

    @staticmethod
    def _make_dynamics(params: Mapping[str, Any]) -> PendulumSliderDynamics:
        skip = params["frame_skip"]
        return PendulumSliderDynamics(**{key: params[key] for key in PAPER_PARAMS},
                                      dt=1e-3 * skip, substeps=skip, friction=params["friction"],
                                      input_scale=params["force_max"],
                                      equations=params["dynamics"])

    @property
    def dynamics(self) -> PendulumSliderDynamics:
        """The ODE with the *nominal* parameters (the model's), e.g. for least squares."""
        return self._make_dynamics(self.nominal_params)

    def _build_model(self, params: Mapping[str, Any]) -> Any:
        name = (f"PendulumSlider({params['friction']})" if params["dynamics"] == "physical"
                else f"PendulumSlider({params['dynamics']})")
        return self._make_dynamics(params).model(Q=params["Q"], R=params["R"], name=name)

    def design_point(self) -> DesignPoint:
        """The slider at the *nominal* rest position, the pendulum hanging, ``u = 0``.

        The rest position ``l0 − μ (m1 + m2) g / 2k`` of the nominal parameters (with the
        paper's friction push; ``l0`` otherwise) is the model's fixed point, paper 003's
        equations of motion. The weights are the reward's per-step cost,
        ``θ² + 0.1 θ̇² + 100 (x − x_rest)² + 0.01 a²`` (its constant time scale does not
        change the LQR's gain); PID holds the measured slider position at that rest.
        """
        x_rest = self._rest_position(self.nominal_params)
        M = np.diag([100.0, 0.0, 1.0, 0.1, 0.01])
        return DesignPoint(x=np.array([x_rest, 0.0, 0.0, 0.0]), u=np.zeros(1), M=M,
                           states=(0, 1, 2, 3), output=0, setpoint=x_rest,
                           pid={"kp": 5.0, "ki": 0.0, "kd": 0.5},
                           note="slider at the nominal rest position, pendulum hanging")

    # ------------------------------------------------------------------ rendering, pickling
    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode is None:
            return super().render()
        if self._renderer is None:
            try:
                self._renderer = mujoco.Renderer(self.mj_model, self.height, self.width)
            except Exception as err:  # no OpenGL context: say how to get one
                raise RuntimeError(
                    "MuJoCo could not create an OpenGL context for rgb_array rendering; "
                    "without a display set MUJOCO_GL=egl (or osmesa) before importing mujoco"
                ) from err
        data = self._scene()
        self._renderer.update_scene(data, camera="side")
        frame = self._renderer.render()
        self._frame_view = self._camera_view(data)
        return frame

    def _scene(self) -> mujoco.MjData:
        """The MuJoCo data that draws :attr:`state`: the simulation's own when it holds the
        state (a single env), else a drawing copy put at it (a native vector env's sub-env,
        whose state the vector env sets before drawing). A state that is not valid draws the
        simulation's own data."""
        x = np.asarray(self.state, dtype=np.float64)
        if state_failure(x, self.state_limit) is not None or self._holds(x):
            return self.mj_data
        if self._drawing_data is None:
            self._drawing_data = mujoco.MjData(self.mj_model)
        self._write_state(x, self._drawing_data)
        return self._drawing_data

    def _camera_view(self, d: mujoco.MjData) -> CameraView:
        """The "side" camera as the frame just rendered (from ``d``) sees the world."""
        m = self.mj_model
        cam = m.camera("side").id
        (px, py, pz), axes = d.cam_xpos[cam].tolist(), d.cam_xmat[cam].reshape(3, 3).T
        right, up, back = (tuple(row) for row in axes.tolist())  # rows of the transpose
        return CameraView(self.width, self.height, int(self.time_step), self._sample_period(),
                          (px, py, pz), (right, up, back), float(m.cam_fovy[cam]))

    def _picture(self, x: FloatArray) -> FloatArray:
        """The slider's and the bob's centres in MuJoCo's world (the bodies it draws).

        The slider sits at ``(x, 0, z)`` (``z`` is 0, or its resting height on the rail
        in the "coulomb" mode); the hinge about +y turns the bob's ``(0, 0, −L)`` into
        ``(−L sin θ, 0, −L cos θ)`` (``L``: the bob geom's distance, 0.2 m).
        """
        z = self._z_rest or 0.0
        L = -float(self.mj_model.geom("bob").pos[2])
        p, th = float(x[0]), float(x[2])
        return np.array([[p, 0.0, z], [p - L * math.sin(th), 0.0, z - L * math.cos(th)]])

    def _measurement_picture(self, y: FloatArray) -> list[tuple[FloatArray, FloatArray | None]]:
        """The measured slider position and angle place both bodies."""
        return [(point, None) for point in self._picture(y)]

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = state["_drawing_data"] = None
        state.pop("_friction_law")
        state.pop("_stage_rk4")
        state["_saved_sim"] = (self.mj_data.qpos.copy(), self.mj_data.qvel.copy(),
                               self.mj_data.ctrl.copy(), float(self.mj_data.time))
        for key in ("mj_model", "mj_data"):
            state.pop(key)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        qpos, qvel, ctrl, time = state.pop("_saved_sim")
        self.__dict__.update(state)
        self._build_simulation()
        self.mj_data.qpos[:], self.mj_data.qvel[:], self.mj_data.ctrl[:] = qpos, qvel, ctrl
        self.mj_data.time = time
        mujoco.mj_forward(self.mj_model, self.mj_data)
