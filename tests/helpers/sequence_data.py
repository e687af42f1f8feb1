"""Data sets of the sequence and smoother tests (importable: pytest's ``pythonpath`` has this
folder): pykalman's robot and a generated constant-velocity track."""

from __future__ import annotations

import numpy as np

from fir_gym.estimators import LinearModel


def robot(initial: bool = False) -> tuple[LinearModel, dict, np.ma.MaskedArray, np.ndarray]:
    """pykalman's robot: its offsets become an input ``B = I``, ``u[k] = offset[k]``, and the
    observation offset is subtracted from the (masked) observations."""
    from pykalman.datasets import load_robot

    d = load_robot()
    pre = "initial_" if initial else ""
    model = LinearModel(A=d["transition_matrix"], C=d["observation_matrix"],
                        Q=d[pre + "transition_covariance"], R=d[pre + "observation_covariance"],
                        B=np.eye(5))
    return model, d, d["observations"] - d["observation_offset"], d["transition_offsets"]



def tracking(T: int = 80, B: int = 3, seed: int = 0
             ) -> tuple[LinearModel, np.ndarray, np.ndarray]:
    """A constant-velocity target with a commanded acceleration, position measured: ``B``
    independent runs ``(T, B, 1)`` and their inputs ``(T - 1, B, 1)``."""
    dt = 0.1
    model = LinearModel(A=[[1, dt], [0, 1]], C=[[1.0, 0.0]], B=[[0.5 * dt**2], [dt]],
                        G=[[0.5 * dt**2], [dt]], Q=0.5, R=0.04, dt=dt)
    rng = np.random.default_rng(seed)
    U = rng.normal(size=(T - 1, B, 1))
    x = np.zeros((B, 2))
    ys = []
    for k in range(T):
        ys.append(x @ model.C.T + 0.2 * rng.normal(size=(B, 1)))
        if k < T - 1:
            x = x @ model.A.T + U[k] @ model.B.T + rng.normal(size=(B, 1)) @ model.G.T * 0.7
    return model, np.stack(ys), U


def pykalman_robot(d: dict, initial: bool = False, **options: object) -> object:
    """pykalman's own ``KalmanFilter`` on the robot data set (its offsets as they are)."""
    import pykalman

    pre = "initial_" if initial else ""
    return pykalman.KalmanFilter(
        transition_matrices=d["transition_matrix"],
        observation_matrices=d["observation_matrix"],
        transition_covariance=d[pre + "transition_covariance"],
        observation_covariance=d[pre + "observation_covariance"],
        transition_offsets=d["transition_offsets"], observation_offsets=d["observation_offset"],
        initial_state_mean=d["initial_state_mean"],
        initial_state_covariance=d["initial_state_covariance"], **options)
