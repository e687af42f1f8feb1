"""Building an estimator by name: one exception type per mistake, with the accepted keys."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym  # noqa: F401  (registers the ids)
from fir_gym.estimators import (
    EstimatorOptionError,
    IncompatibleModelError,
    LinearModel,
    estimator_names,
    make_estimator,
)
from fir_gym.estimators.errors import accepted_options


def _linear():
    return LinearModel(A=[[1.0, 0.1], [0.0, 1.0]], C=[[1.0, 0.0]], Q=[[0.01]], R=[[0.1]],
                       G=[[0.0], [1.0]])


@pytest.mark.parametrize("name", ["ekf", "ukf", "efir", "fir", "ufir", "rfir", "kf"])
def test_an_unknown_option_names_the_filter_and_lists_the_accepted_keys(name):
    with pytest.raises(EstimatorOptionError) as err:
        gym.make("fir_gym/CarrierMotion-v0", estimator=name, estimator_kwargs={"x_0": 1})
    message = str(err.value)
    assert f"{name} (" in message and "'x_0'" in message
    assert "did you mean 'x0'" in message
    from fir_gym.estimators import estimator_class

    for key in accepted_options(estimator_class(name)):
        assert key in message
    assert isinstance(err.value, TypeError)      # Python's type for an unexpected keyword


@pytest.mark.parametrize("key", ["Q", "R"])
def test_noise_given_as_an_option_points_to_nominal(key):
    with pytest.raises(EstimatorOptionError, match="nominal="):
        gym.make("fir_gym/Orbit-v0", estimator="ekf", estimator_kwargs={key: 1.0})
    with pytest.raises(EstimatorOptionError, match="nominal="):
        make_estimator("kf", _linear(), **{key: 1.0})


def test_accepted_options_are_what_the_constructors_take():
    from fir_gym.estimators import estimator_class

    for name in estimator_names():
        cls = estimator_class(name)
        keys = accepted_options(cls)
        assert "x0" in keys and "model" not in keys and "self" not in keys
        assert "options" not in keys and "kwargs" not in keys


@pytest.mark.parametrize("name", ["fir", "ufir", "rfir", "fir-smoother"])
def test_fir_family_on_a_nonlinear_plant_suggests_efir(name):
    with pytest.raises(IncompatibleModelError, match="efir"):
        gym.make("fir_gym/VanDerPol-v0", estimator=name)


def test_linear_kalman_on_a_nonlinear_plant_suggests_ekf():
    with pytest.raises(IncompatibleModelError, match="'ekf'"):
        gym.make("fir_gym/Orbit-v0", estimator="kf")


@pytest.mark.parametrize("name", ["bpf-kf", "cd-ekf"])
def test_continuous_filters_on_a_discrete_plant_are_the_same_error(name):
    with pytest.raises(IncompatibleModelError, match="continuous_model"):
        gym.make("fir_gym/Orbit-v0", estimator=name)


def test_one_type_for_a_model_mismatch_is_both_former_types():
    """fir/ufir/rfir raised TypeError and bpf-kf ValueError: one type, caught as either."""
    assert issubclass(IncompatibleModelError, TypeError)
    assert issubclass(IncompatibleModelError, ValueError)


def test_good_options_still_build():
    est = make_estimator("kf", _linear(), x0=np.zeros(2), P0=np.eye(2))
    assert est.x.shape == (2,)
