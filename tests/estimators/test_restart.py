"""Restarting some systems of a batch (what a vector env's autoreset needs).

Oracle: a restarted system must equal a fresh one-system filter fed the same
measurements from the restart on; the other systems must equal a batch that
never restarted.
"""

import numpy as np
import pytest
from compiled_paths import on_path

from fir_gym.estimators import LinearModel, StateSpaceModel, make_estimator


class Pendulum:
    def f(self, x, u):
        return np.stack([x[..., 0] + 0.05 * x[..., 1],
                         x[..., 1] - 0.05 * (9.8 * np.sin(x[..., 0]) - u[..., 0])], -1)

    def h(self, x):
        return np.sin(x[..., :1]) + 0.1 * x[..., 1:]


def models():
    p = Pendulum()
    return {
        "linear": LinearModel(A=[[1.0, 0.1], [-0.1, 0.98]], B=[[0.0], [0.1]], C=[[1.0, 0.0]],
                              Q=np.diag([1e-3, 1e-2]), R=0.05),
        "nonlinear": StateSpaceModel(f=p.f, h=p.h, Q=np.diag([1e-4, 1e-3]), R=0.01, n_u=1),
    }


CASES = [("kf", "linear"), ("ekf", "nonlinear"), ("ukf", "nonlinear"), ("lkf", "nonlinear"),
         ("ekf", "linear"), ("efir", "nonlinear")]
#: the options a filter needs beyond the prior
OPTIONS = {"efir": {"horizon": 4}}


@pytest.mark.parametrize(("name", "model_name"), CASES)
@pytest.mark.parametrize("batched_prior", [False, True])
@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_restarted_system_equals_a_fresh_filter_and_others_are_untouched(name, model_name,
                                                                         batched_prior, path):
    with on_path(path):
        check_restart(name, model_name, batched_prior)


def check_restart(name, model_name, batched_prior):
    model = models()[model_name]
    rng = np.random.default_rng(1)
    B, K, k_restart = 3, 12, 5
    Y = rng.normal(scale=0.3, size=(K, B, 1))
    U = rng.normal(scale=0.5, size=(K, B, 1))
    x0 = np.array([[0.1, 0.0], [0.2, -0.1], [0.0, 0.3]])
    P0 = np.stack([np.eye(2) * s for s in (0.5, 1.0, 2.0)])
    prior = {"x0": x0, "P0": P0} if batched_prior else {"x0": x0[0], "P0": P0[0]}
    batch = make_estimator(name, model, **prior, **OPTIONS.get(name, {}))
    plain = make_estimator(name, model, **prior, **OPTIONS.get(name, {}))
    out, ref, infos = [], [], []
    for k in range(K):
        if k == k_restart:
            batch.restart(np.array([True, True, False]))   # two systems: a block of them
        u = None if k == 0 else U[k]
        out.append(batch.step(Y[k], u))
        ref.append(plain.step(Y[k], u))
        infos.append(batch.last_info)
    out, ref = np.array(out), np.array(ref)
    np.testing.assert_allclose(out[:, 2], ref[:, 2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[:k_restart], ref[:k_restart], rtol=0, atol=1e-12)
    # the reference is the same system in a fresh batch (the same arithmetic path: with
    # central-difference Jacobians, summing in another order moves F by ~eps/h ~ 1e-11)
    i = [0, 1]
    fresh = make_estimator(name, model, **prior, **OPTIONS.get(name, {}))
    for k in range(k_restart, K):
        expected = fresh.step(Y[k], None if k == k_restart else U[k])[i]
        np.testing.assert_allclose(out[k, i], expected, rtol=0, atol=1e-12)
        # and so do their NIS and log-likelihood (the restarted systems' own, not the pass's)
        for key in ("nis", "log_likelihood"):
            if fresh.last_info.get(key) is not None:
                np.testing.assert_allclose(infos[k][key][i], fresh.last_info[key][i],
                                           rtol=1e-10, atol=1e-12, err_msg=key)
    np.testing.assert_allclose(batch.P[i], fresh.P[i], rtol=0, atol=1e-12)


def test_restart_arguments():
    model = models()["linear"]
    filt = make_estimator("kf", model)
    filt.restart([0])                                   # before the first step: nothing to do
    filt.step(np.zeros((2, 1)))
    with pytest.raises(ValueError, match="systems must be"):
        filt.restart(np.array([True, False, True]))
    with pytest.raises(ValueError, match="systems must be"):
        filt.restart([5])
    filt.restart([0, 1])                                # all of them: a reset
    assert filt.time_step == 0
