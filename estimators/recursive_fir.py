"""The recursive FIR filter of paper 004 §IV (Theorem 4.1, Cor 4.1), corrected.

The FIR filter ``f_i = x̂(i|N)`` and smoother ``s_i = x̂_s(i−N|N)`` over the window
``z(i−N..i)`` (``L = N + 1`` measurements) drive each other (eq 4.13)::

    [f; s]_{i+1} = [[M1, M1 H_N C M2], [−H_sN C A, M4]] [f; s]_i
                   + [[H_0, −M1 H_N (I + C M2 H_s0)],
                      [H_sN, −M4 H_s0 + H_sN C A H_N]] [z(i+1); z(i−N)]

with ``H_0 = H(0;N)``, ``H_N = H(N;N)`` the filter's weights on the newest and
oldest measurement, ``H_s0 = H_s(0;N)``, ``H_sN = H_s(−N;N)`` the smoother's on the
oldest and newest, ``M1 = (I − H_0 C) A``, ``M2 = (I − H_s0 C)⁻¹`` and, corrected
(docs/papers.md#004-recursive-form)::

    M4 = [A − H_sN C A H_N C] M2                       (printed: [A − H_sN C A] H_N C M2)

and the smoother's ``z(i−N)`` weight ``−M4 H_s0 + H_sN C A H_N`` (printed without
the second term). Derivation: dropping ``z(i−N)`` gives ``s' = A M2 (s − H_s0
z(i−N))`` (eq 4.11) and ``f' = f − H_N (z(i−N) − C M2 (s − H_s0 z(i−N)))`` (eq 4.9,
the back-prediction of ``x(i−N)`` being ``A⁻¹ s' = M2(·)``); adding ``z(i+1)`` is a
Kalman update, eqs (4.6), (4.10). Theorem 4.1 (stationary prior) replaces ``A`` by
``[I − BQBᵀP⁻¹(0)]⁻¹ A`` in ``M4`` (its ``M3``). Known inputs enter as
``+(I − H_0 C) B u(i)`` in ``f`` and ``+B u(i−N) − H_sN C B u(i)`` in ``s``.

**Why re-initialise.** The 2n x 2n transition has its eigenvalues in reciprocal
pairs ``(λ, 1/λ)`` — the forward (filter) and backward (smoother) dynamics are
coupled — so it is unstable whenever the filter is stable: round-off is
amplified by ``ρ^k`` (``ρ`` = its spectral radius, :attr:`spectral_radius`)
and grows by orders of magnitude within a few tens of steps. The recursion is
therefore restarted from the direct (non-recursive) FIR filter and smoother
every ``reinit_every`` steps; ``"auto"`` picks the largest interval over which
``ρ^k`` stays below 1e6. The paper also warns that the recursive form loses the
FIR properties under model error (an error injected once is never forgotten).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray, positive
from .errors import needs_linear
from .fir import FIRFilter, _combined_gain
from .fir_gains import input_gain
from .model import StateSpaceModel
from .registry import register_estimator

#: largest round-off amplification allowed between re-initialisations for ``"auto"``
AUTO_GROWTH = 1e6


class RecursiveFIRFilter(FIRFilter):
    """Recursive FIR filter and smoother (paper 004 §IV) for time-invariant models.

    Args:
        model: a :class:`~.model.LinearModel` with invertible ``A``.
        horizon: ``L = N + 1`` measurements (window ``y[k-L+1..k]``); without a prior
            ``L − 1`` measurements must already determine the state.
        prior: ``None`` (Cor 4.1, unbiased) or ``"stationary"`` (Theorem 4.1; stable
            A, no inputs).
        reinit_every: re-initialise from the direct form every so many steps;
            ``"auto"`` (default, see the module docstring) or ``None`` (never — for
            demonstrating the round-off growth).
        gain: the path used for the direct gains (as in :class:`FIRFilter`).

    ``step`` returns the filter estimate; :attr:`x_smoothed` is the window-start
    estimate ``s``; ``last_info["reinitialised"]`` says whether this step used the
    direct form (per system: a restarted system re-initialises when its window
    fills). It needs every measurement: a missing one (``step(None)``, a masked or NaN
    row, ``nan_policy="skip"``) is refused with a ValueError — the recursion has no
    missing-data form, and the window would otherwise read it as 0. ``P`` is the direct
    filter's error covariance. For the same reason it
    refuses ``gate`` (the innovation gate treats a rejected measurement as missing): use
    :class:`FIRFilter`, whose estimate it equals, to gate.
    """

    name: ClassVar[str] = "rfir"
    _extra_slots: ClassVar[int] = 1
    can_gate: ClassVar[bool] = False
    accepts_missing: ClassVar[bool] = False
    no_gate_reason: ClassVar[str] = ("the recursion needs every measurement, and a rejected "
                                     "one would be a missing one; FIRFilter gates")

    def __init__(self, model: StateSpaceModel, *, horizon: int, prior: str | None = None,
                 reinit_every: int | str | None = "auto", gain: str = "two-stage",
                 x0: ArrayLike | None = None, P0: ArrayLike | None = None,
                 **options: Any) -> None:
        if not getattr(model, "time_invariant", False) or not model.is_linear:
            raise needs_linear("RecursiveFIRFilter (time-invariant)", model,
                               "'efir' (ExtendedFIRFilter), the FIR filter of a nonlinear model")
        if options.get("nan_policy", "raise") != "raise":
            raise ValueError("RecursiveFIRFilter needs every measurement: nan_policy must be "
                             "'raise' (use FIRFilter for missing data)")
        if prior not in (None, "stationary"):
            raise ValueError(f"prior must be None or 'stationary'; got {prior!r}")
        if prior is not None and model.n_u:
            raise ValueError("prior='stationary' (Theorem 4.1) is for a zero-mean process "
                             "without inputs")
        A = np.asarray(model.A)                                     # type: ignore[attr-defined]
        if np.linalg.cond(A) > 1e12:
            raise ValueError("RecursiveFIRFilter needs an invertible A (paper 004 Theorem 4.1)")
        if prior is None and positive("horizon", horizon, integer=True) < 2:
            raise ValueError(f"horizon={horizon}: the recursion needs horizon >= 2")
        super().__init__(model, horizon=horizon, form="filter", gain=gain, prior=prior,
                         x0=x0, P0=P0, **options)
        if reinit_every == "auto":
            self.reinit_every = None if self.spectral_radius <= 1.0 + 1e-12 else max(
                1, int(np.log(AUTO_GROWTH) / np.log(self.spectral_radius)))
        else:
            self.reinit_every = (None if reinit_every is None
                                 else positive("reinit_every", reinit_every, integer=True))

    def _fixed_gain(self) -> None:
        super()._fixed_gain()                              # filter gain → self._G, _P_fir
        if self._prior is None:                            # the N-measurement sub-window
            sub = self._win._replace(**{f: getattr(self._win, f)[1:]
                                        for f in self._win._fields})
            try:
                self._compute_gain(sub)
            except ValueError:
                raise ValueError(f"horizon={self.horizon}: the recursion drops a measurement, "
                                 f"so horizon - 1 measurements must determine the state; "
                                 f"use horizon >= {self.horizon + 1}") from None
        self._target = "smoother"
        Ss = self._compute_gain(self._win, self._prior).S
        self._Gs = _combined_gain(Ss, input_gain(self._win, Ss, "smoother"), "filter",
                                  self._p, self._nu)
        self._target = "filter"
        self._build_recursion(self._G[:, :, :self._p], self._Gs[:, :, :self._p])

    def _build_recursion(self, H: FloatArray, Hs: FloatArray) -> None:
        """Eq (4.13) corrected (module docstring), as one matrix on ``[f, s, z⁺, z⁻, u⁺, u⁻]``."""
        win = self._win
        A, C, B, I = win.A[0], win.C[0], win.B[0], np.eye(self._n)
        H0, HN, Hs0, HsN = H[:, -1], H[:, 0], Hs[:, 0], Hs[:, -1]
        M1 = (I - H0 @ C) @ A
        M2 = np.linalg.solve(I - Hs0 @ C, I)
        if self._prior is not None and np.linalg.cond(self._prior) > 1e12:
            raise ValueError("prior='stationary' (Theorem 4.1) needs {A, B Q½} controllable: "
                             "the stationary covariance P(0) is singular")
        D = A if self._prior is None else np.linalg.solve(
            I - np.linalg.solve(self._prior, win.Qx[0]).T, A)      # [I − BQB'P⁻¹]⁻¹ A
        M4 = (D - HsN @ C @ A @ HN @ C) @ M2
        Phi = np.block([[M1, M1 @ HN @ C @ M2], [-HsN @ C @ A, M4]])
        Gam = np.block([[H0, -M1 @ HN @ (np.eye(self._p) + C @ M2 @ Hs0)],
                        [HsN, -M4 @ Hs0 + HsN @ C @ A @ HN]])
        Lam = np.block([[(I - H0 @ C) @ B, np.zeros_like(B)], [-HsN @ C @ B, B]])
        self.transition = Phi
        self.spectral_radius = float(np.max(np.abs(np.linalg.eigvals(Phi))))
        self._M = np.hstack([Phi, Gam, Lam]).T                      # row-vector form
        self._fs: FloatArray | None = None

    @property
    def x_smoothed(self) -> FloatArray | None:
        """The smoother estimate ``x̂_s`` of the window-start state (after start-up)."""
        if self._fs is None:
            return None
        s = self._fs[:, self._n:]
        return s[0].copy() if self._state.single else s.copy()

    def _reset_state(self) -> None:
        super()._reset_state()
        self._fs = None
        self._info_reinit: bool | np.ndarray = False

    def _init_batch(self, n_batch: int) -> None:
        super()._init_batch(n_batch)
        self._since = np.zeros(n_batch, int)

    def _step_info(self) -> dict[str, Any]:
        r = self._info_reinit
        reinit = bool(np.asarray(r).ravel()[0]) if self._state.single else np.array(r)
        return {**super()._step_info(), "reinitialised": reinit}

    def _advance(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                 ) -> tuple[FloatArray, FloatArray, None]:
        if not valid.all():
            raise ValueError("y: RecursiveFIRFilter needs every measurement (its recursion has "
                             "no missing-data form; a missing one would enter the window as "
                             "0); got none for system(s) "
                             f"{np.flatnonzero(~valid).tolist()}: use FIRFilter ('fir'), whose "
                             "estimate it equals")
        return super()._advance(y, u, valid)

    def _gain_step(self) -> tuple[FloatArray, FloatArray, np.ndarray]:
        nb, n, p, L = self._buf.shape[0], self._n, self._p, self.horizon
        due = self._age == L - 1                            # a window just became full
        if self._fs is None:
            due[:] = True
        elif self.reinit_every is not None:
            due |= self._since >= self.reinit_every
        if self._fs is not None:                            # eq (4.13)
            Z, _ = self._window_data(L + 1)                # slots k−L .. k
            v = np.hstack([self._fs, Z[:, -1, :p], Z[:, 0, :p], Z[:, -1, p:], Z[:, 1, p:]])
            fs = v @ self._M
        if due.any():                                       # eq (4.12): the direct form
            flat = self._window_data(L)[0].reshape(nb, -1)
            direct = np.hstack([flat @ self._G.reshape(n, -1).T,
                                flat @ self._Gs.reshape(n, -1).T])
            fs = direct if self._fs is None else np.where(due[:, None], direct, fs)
        self._fs = fs
        self._since = np.where(due, 1, self._since + 1)
        self._info_reinit = due
        return fs[:, :n], np.broadcast_to(self._P_fir, (nb, n, n)), np.ones(nb, bool)


register_estimator("rfir", RecursiveFIRFilter)
