"""fir_gym.jax.stacked_loop: the stacked carry computes what ``jax.lax.fori_loop`` computes
with the tuple — bit for bit on Orbit-v0's three Euler loops, vmapped over a batch as the
envs step (the fusing differs, so this is checked, not assumed) — and refuses a carry that
is not scalars of one dtype."""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import jax.numpy as jnp  # noqa: E402

from fir_gym.jax import orbit  # noqa: E402
from fir_gym.jax.stacked_loop import stacked_fori_loop  # noqa: E402


def plain_fori_loop(lower, upper, body, carry, *, unroll=1):  # type: ignore[no-untyped-def]
    return jax.lax.fori_loop(lower, upper, body, tuple(carry), unroll=unroll)


def orbit_loops(x, xf, a, mu, d):  # type: ignore[no-untyped-def]
    return (orbit.orbit_interval(xf, a, mu, d, 100),
            orbit.orbit_plant_interval(x, a, mu, d, 100),
            orbit.orbit_plant_and_model_intervals(x, a, mu, d, xf, a * 0.97, 19.91, d, 100))


def test_orbit_loops_are_the_plain_loops_bit_for_bit(monkeypatch: pytest.MonkeyPatch
                                                     ) -> None:
    rng = np.random.default_rng(0)
    n = 2048
    x = jnp.asarray(np.stack([rng.uniform(6, 10, n), rng.normal(0, 0.05, n)], axis=1))
    xf = x + jnp.asarray(rng.normal(0, 0.01, (n, 2)))
    a = jnp.asarray(rng.uniform(-0.3, 0.3, n))
    mu = jnp.asarray(rng.uniform(19.5, 20.5, n))
    d = jnp.full(n, 1e-4)
    stacked = jax.jit(jax.vmap(orbit_loops))(x, xf, a, mu, d)
    monkeypatch.setattr(orbit, "stacked_fori_loop", plain_fori_loop)
    plain = jax.jit(jax.vmap(orbit_loops))(x, xf, a, mu, d)
    for got, want in zip(jax.tree.leaves(stacked), jax.tree.leaves(plain), strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    # and the loops moved the state: not a comparison of two untouched copies
    assert float(jnp.max(jnp.abs(stacked[1] - x))) > 1e-3


def test_stacked_loop_returns_the_tuple_and_indexes_the_step() -> None:
    def body(i, c):  # type: ignore[no-untyped-def]
        s, t = c
        return s + i, t * 2.0

    s, t = stacked_fori_loop(0, 5, body, (jnp.asarray(1.0), jnp.asarray(1.0)), unroll=2)
    assert float(s) == 1.0 + 0 + 1 + 2 + 3 + 4 and float(t) == 32.0


@pytest.mark.parametrize("carry", [(jnp.zeros(2), jnp.zeros(())),
                                   (jnp.zeros((), jnp.float32), jnp.zeros((), jnp.float64))])
def test_stacked_loop_refuses_what_it_cannot_stack(carry: tuple) -> None:
    with pytest.raises(ValueError, match="carry must be scalars of one dtype"):
        stacked_fori_loop(0, 2, lambda i, c: c, carry)
