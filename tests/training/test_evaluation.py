"""evaluate's closed-loop NEES statistics against the same episodes replayed by hand."""

import numpy as np
import pytest
import scipy.stats

from fir_gym.controllers import LQGController
from fir_gym.training import RunConfig, evaluate
from fir_gym.training.evaluation import make_eval_env


def test_anees_nees_median_and_in_band_are_those_of_the_replayed_steps():
    """An LQG run (nothing to train) on VanDerPol-v0's EKF: the same episodes replayed by
    hand, every step's (x − x̂)ᵀ P⁻¹ (x − x̂) by a plain solve, and the three numbers from
    numpy and scipy: mean / n_x, median / median of χ²(n_x), fraction in the 95 % band."""
    config = RunConfig(env_id="fir_gym/VanDerPol-v0", observation_kind="lqg",
                       env_kwargs={"max_episode_steps": 30})
    result = evaluate(config, episodes=3, seed=7)
    env = make_eval_env(config)
    controller = LQGController(env)
    estimator = env.get_wrapper_attr("estimator")
    values = []
    for episode in range(3):
        obs, info = env.reset(seed=7 + episode)
        while True:
            e = info["state"] - info["estimate"]
            values.append(float(e @ np.linalg.solve(estimator.P, e)))
            obs, _, terminated, truncated, info = env.step(controller.predict(obs)[0])
            if terminated or truncated:
                break
    env.close()
    values = np.array(values)
    lo, hi = scipy.stats.chi2.ppf([0.025, 0.975], 2)
    assert result.anees == pytest.approx(values.mean() / 2, rel=1e-9)
    assert result.nees_median == pytest.approx(np.median(values) / scipy.stats.chi2.median(2),
                                               rel=1e-9)
    assert result.nees_in_band == pytest.approx(np.mean((values >= lo) & (values <= hi)))
    d = result.to_dict()
    assert d["nees_median"] == result.nees_median and d["nees_in_band"] == result.nees_in_band


def test_no_covariance_no_nees_statistics():
    result = evaluate(RunConfig(env_id="fir_gym/VanDerPol-v0", observation_kind="pid",
                                env_kwargs={"max_episode_steps": 5}), episodes=1)
    assert result.anees is None and result.nees_median is None and result.nees_in_band is None
