"""``uses_prior`` — the class attribute that tells a wrapper whether a filter needs the prior
``(x0, P0)`` — says what the filter does: the estimates of a filter that declares it depend
on the prior for as long as the run lasts (it is a recursion from it); those of one that does
not (the FIR family: the prior at most seeds the start-up) depend on it only while the
first window fills.

Oracle: two runs on the same measurements from two very different priors, compared after the
start-up window. Found by mutation testing (docs/mutation.md): the EFIR's attribute could be
flipped with no test failing.
"""

from __future__ import annotations

import numpy as np
import pytest

from fir_gym.estimators import LinearModel
from fir_gym.estimators.registry import estimator_class, estimator_names, make_estimator

HORIZON = 8
#: the discrete-time filters (the continuous ones take a ContinuousModel, not this one)
DISCRETE = [n for n in estimator_names() if n not in ("bpf-kf", "cd-ekf")]


@pytest.mark.parametrize("name", DISCRETE)
def test_uses_prior_says_whether_the_estimates_after_start_up_depend_on_the_prior(name: str
                                                                                  ) -> None:
    model = LinearModel(A=[[1.0, 0.1], [0.0, 1.0]], C=[[1.0, 0.0]], Q=np.eye(2) * 0.01,
                        R=[[0.1]], dt=0.1)
    options = {"horizon": HORIZON} if "horizon" in _parameters(name) else {}
    a = make_estimator(name, model, x0=[0.0, 0.0], P0=np.eye(2), **options)
    b = make_estimator(name, model, x0=[5.0, -3.0], P0=100 * np.eye(2), **options)
    ys = np.random.default_rng(0).normal(size=(5 * HORIZON, 1))
    late = slice(2 * HORIZON, None)
    ea, eb = (np.array([f.step(y) for y in ys])[late] for f in (a, b))
    assert estimator_class(name).uses_prior == (not np.allclose(ea, eb, rtol=0, atol=1e-9))


def _parameters(name: str) -> set[str]:
    import inspect
    return set(inspect.signature(estimator_class(name)).parameters)
