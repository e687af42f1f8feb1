"""fir_gym.jax.permutation against what it replaces: ``jax.random.permutation`` (the same
integers, for sizes of one and two rounds and many keys) and, for the stable sort inside it,
``lax.sort_key_val`` on keys drawn from a few values, so that almost every key is tied."""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import jax.numpy as jnp  # noqa: E402

import fir_gym.jax  # noqa: E402,F401  (x64 on)
from fir_gym.jax.permutation import permutation, rounds, stable_order  # noqa: E402


@pytest.mark.parametrize("n", [1, 2, 7, 1024, 4096, 5000])
def test_permutation_is_jax_random_permutation(n: int) -> None:
    ours = jax.jit(jax.vmap(lambda k: permutation(k, n)))
    theirs = jax.jit(jax.vmap(lambda k: jax.random.permutation(k, n)))
    keys = jax.random.split(jax.random.key(n), 50)
    got, want = np.asarray(ours(keys)), np.asarray(theirs(keys))
    np.testing.assert_array_equal(got, want)
    assert got.dtype == want.dtype
    assert (np.sort(got, axis=1) == np.arange(n)).all()


def test_rounds_are_jaxs() -> None:
    # jax draws two rounds from 1626 elements on (3 ln n > ln(2³² − 1)); the sizes of PPO's
    # recipes (4096, 2048 …) are on the two-round side, small ones on the one-round side
    assert [rounds(n) for n in (1, 2, 1625, 1626, 4096)] == [0, 1, 1, 2, 2]
    for n in (1000, 1626, 4096):
        k = jax.random.key(3)
        assert np.asarray(permutation(k, n)).tolist() == \
            np.asarray(jax.random.permutation(k, n)).tolist()


@pytest.mark.parametrize("values", [1, 3, 2 ** 32 - 1])
def test_stable_order_is_a_stable_key_value_sort(values: int) -> None:
    rng = np.random.default_rng(values % 1000)
    for n in (1, 5, 300, 4096):
        keys = rng.integers(0, values, size=n, endpoint=True, dtype=np.uint64)
        keys = jnp.asarray(np.minimum(keys, 2 ** 32 - 1).astype(np.uint32))
        want = jax.lax.sort_key_val(keys, jnp.arange(n))[1]
        np.testing.assert_array_equal(np.asarray(stable_order(keys)), np.asarray(want))
        # and the oracle that shares nothing with XLA: numpy's stable argsort
        np.testing.assert_array_equal(np.asarray(stable_order(keys)),
                                      np.argsort(np.asarray(keys), kind="stable"))


def test_ppo_minibatches_are_rejaxs() -> None:
    """SB3LikePPO's ``shuffle_and_split`` (this permutation) cuts the same minibatches as
    rejax's own (``jax.random.permutation``), on a rollout-shaped batch."""
    pytest.importorskip("rejax")
    from rejax.algos.mixins import OnPolicyMixin

    from fir_gym.jax import train as jt

    env, params = jt.make_env("fir_gym/Orbit-v0", "ekf")
    algo = jt.make_algorithm(env, params, jt.recipe("fir_gym/Orbit-v0", steps=8192))
    steps, envs = algo.num_steps, algo.num_envs
    rng = np.random.default_rng(1)
    data = {"obs": jnp.asarray(rng.normal(size=(steps, envs, 2))),
            "done": jnp.asarray(rng.random((steps, envs)) < 0.1)}
    for seed in range(3):
        key = jax.random.key(seed)
        ours = algo.shuffle_and_split(data, key)
        theirs = OnPolicyMixin.shuffle_and_split(algo, data, key)
        for a, b in zip(jax.tree.leaves(ours), jax.tree.leaves(theirs), strict=True):
            assert a.shape == b.shape == (algo.num_minibatches, steps * envs
                                          // algo.num_minibatches, *a.shape[2:])
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
