"""Bad input is refused at the plants' boundary, naming the argument (issue 18, item 6)."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym

ENV_IDS = fir_gym.ENV_IDS

#: actions that numpy would convert silently ('0.5' -> 0.5, True -> 1, 0.5+1j -> 0.5, ...)
BAD_ACTIONS = {
    "string": "0.5",
    "string array": np.array(["0.5"]),
    "bool": True,
    "bool array": np.array([True]),
    "complex": 0.5 + 1j,
    "complex array": np.array([0.5 + 0j]),
    "datetime64": np.datetime64("2020-01-01"),
    "timedelta64": np.array([np.timedelta64(1, "s")]),
    "None": None,
    "object": object(),
    "ragged": [0.5, [1.0]],
}

#: what the message says each was
KIND_WORDS = {"string": "str", "string array": "strings", "bool": "booleans",
              "bool array": "booleans", "complex": "complex", "complex array": "complex",
              "datetime64": "dates", "timedelta64": "time deltas", "None": "None",
              "object": "object", "ragged": "list"}


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("kind", sorted(BAD_ACTIONS))
def test_non_numeric_actions_are_refused_naming_action(env_id, kind):
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    state = env.state.copy()
    with pytest.raises(ValueError, match=r"action must be 1 real number") as err:
        env.step(BAD_ACTIONS[kind])
    assert KIND_WORDS[kind] in str(err.value)
    np.testing.assert_array_equal(env.state, state)          # nothing happened


@pytest.mark.parametrize("action", [0.25, 0, np.int64(0), np.float32(0.25), [0.25],
                                    np.array(0.25), np.array([0.25], dtype=np.float16),
                                    np.array([1], dtype=np.uint8), (0.25,)])
def test_real_numbers_of_any_numeric_type_are_accepted(action):
    """Ints and floats, Python or numpy, scalars, lists, tuples and arrays: the same step
    as the float64 array of the same value."""
    reference, env = gym.make("fir_gym/Orbit-v0").unwrapped, gym.make("fir_gym/Orbit-v0").unwrapped
    reference.reset(seed=3)
    env.reset(seed=3)
    value = np.asarray(action, dtype=np.float64).item()
    expected = reference.step(np.array([value]))
    got = env.step(action)
    np.testing.assert_array_equal(got[0], expected[0])
    np.testing.assert_array_equal(got[4]["action"], expected[4]["action"])


MALFORMED_OPTIONS = [("state", TypeError), (["state"], TypeError), (42, TypeError),
                     (("state", [0.0]), TypeError), ({"state": "abc"}, ValueError),
                     ({"state": ["a", "b"]}, ValueError), ({"state": None}, ValueError),
                     ({"state": True}, ValueError), ({"state": {"r": 1.0}}, ValueError),
                     ({"state": [[1.0, 2.0]]}, ValueError), ({"seed": 3}, ValueError),
                     ({1: 2}, ValueError)]


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize(("options", "error"), MALFORMED_OPTIONS)
def test_malformed_reset_options_are_refused_naming_options(env_id, options, error):
    """Issue 18: ``options="state"`` said "reset options ['a', 'e', 's', 't'] are not
    understood", ``["state"]`` and ``42`` raised TypeErrors from inside."""
    env = gym.make(env_id)
    with pytest.raises(error, match="options") as err:
        env.reset(seed=0, options=options)
    assert "['a', 'e', 's', 't']" not in str(err.value)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_a_boolean_state_is_refused_not_read_as_ones(env_id):
    env = gym.make(env_id).unwrapped
    with pytest.raises(ValueError, match=r"options\['state'\] must be .* real numbers.*booleans"):
        env.reset(options={"state": np.ones(len(env.state_names), dtype=bool)})


# ---------------------------------------------------------------------------- vector envs
VECTOR_IDS = fir_gym.VECTOR_ENV_IDS


def make_vector(env_id, num_envs=3, **kwargs):
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


@pytest.mark.parametrize("env_id", VECTOR_IDS)
@pytest.mark.parametrize("kind", ["string array", "bool array", "complex array",
                                  "datetime64", "timedelta64", "None"])
def test_vector_env_refuses_non_numeric_actions(env_id, kind):
    venv = make_vector(env_id)
    venv.reset(seed=0)
    bad = BAD_ACTIONS[kind]
    batch = np.broadcast_to(np.asarray(bad), (3, 1)) if kind != "None" else None
    with pytest.raises(ValueError, match=r"actions must be real numbers"):
        venv.step(batch)


def test_vector_env_accepts_integer_actions_as_their_floats():
    a, b = make_vector("fir_gym/Orbit-v0"), make_vector("fir_gym/Orbit-v0")
    a.reset(seed=1)
    b.reset(seed=1)
    np.testing.assert_array_equal(a.step(np.zeros((3, 1), dtype=np.int64))[0],
                                  b.step(np.zeros((3, 1)))[0])


@pytest.mark.parametrize("env_id", VECTOR_IDS)
@pytest.mark.parametrize(("options", "error"), MALFORMED_OPTIONS)
def test_vector_env_refuses_malformed_reset_options_naming_options(env_id, options, error):
    venv = make_vector(env_id)
    with pytest.raises(error, match="options"):
        venv.reset(seed=0, options=options)


def test_vector_env_resets_to_given_states():
    venv = make_vector("fir_gym/Orbit-v0")
    _, info = venv.reset(seed=0, options={"state": [8.0, 2.0]})
    np.testing.assert_array_equal(info["state"], np.tile([8.0, 2.0], (3, 1)))
    each = [[8.0, 2.0], [9.0, 1.0], [7.5, 0.0]]
    _, info = venv.reset(seed=0, options={"state": each})
    np.testing.assert_array_equal(info["state"], each)
    with pytest.raises(ValueError, match=r"options\['state'\]\[1\] = .* outside the domain"):
        venv.reset(seed=0, options={"state": [[8.0, 2.0], [0.5, 0.0], [8.0, 2.0]]})
    with pytest.raises(ValueError, match=r"options\['state'\] must have shape"):
        venv.reset(seed=0, options={"state": np.zeros((2, 2))})


def test_a_given_state_is_copied_not_kept_by_reference():
    env = gym.make("fir_gym/Orbit-v0").unwrapped
    x0 = np.array([8.0, 2.0])
    env.reset(seed=0, options={"state": x0})
    x0[:] = 50.0
    np.testing.assert_array_equal(env.state, [8.0, 2.0])
    venv = make_vector("fir_gym/Orbit-v0")
    each = np.array([[8.0, 2.0], [9.0, 1.0], [7.5, 0.0]])
    venv.reset(seed=0, options={"state": each})
    each[:] = 50.0
    assert np.all(venv.unwrapped.states < 50.0)
