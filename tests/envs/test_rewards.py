"""Each plant's reward against the cost its docstring states, computed here from the true
state after the step (``info["state"]``) and the action: a sign or a weight slipped in a
``_reward`` would otherwise go unseen (mutation testing found one in every plant's reward,
docs/mutation.md). Orbit's is in test_orbit.py."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fir_gym  # noqa: F401  (registers the ids)


def rollout(env_id: str, steps: int = 40, seed: int = 1, **kwargs):
    """``(state after, action, reward)`` of each step of a random-action episode."""
    env = gym.make(env_id, **kwargs).unwrapped
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        a = rng.uniform(-1.0, 1.0, size=1)
        _, reward, terminated, _, info = env.step(a)
        if terminated:
            break
        out.append((info["state"], a[0], reward))
    return env, out


def test_uncertain_oscillator_reward():
    """``−min((x1' − setpoint)² + 1e-3 a², 2.25)``."""
    env, steps = rollout("fir_gym/UncertainOscillator-v0")
    assert steps
    for x, a, reward in steps:
        cost = (x[0] - env.setpoint) ** 2 + 1e-3 * a * a
        assert reward == pytest.approx(-min(cost, 2.25), rel=1e-12, abs=1e-15)


def test_van_der_pol_reward():
    """``−min((x1'² + x2'²)/4 + 0.01 a², state_bound²/2 + 0.01)``."""
    env, steps = rollout("fir_gym/VanDerPol-v0")
    assert steps
    cap = env.state_bound ** 2 / 2 + 0.01
    for x, a, reward in steps:
        cost = (x[0] ** 2 + x[1] ** 2) / 4 + 0.01 * a * a
        assert reward == pytest.approx(-min(cost, cap), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("state_bound", [20.0, 5.0])
def test_van_der_pol_cap_is_the_largest_cost_inside_the_domain(state_bound: float):
    """Leaving the domain pays ``cost_cap`` for every step left, so that ending an episode
    early cannot pay better than staying, the cap is at least every per-step cost inside
    ``|x1|, |x2| <= state_bound``, ``|a| <= 1`` — and it is that largest cost (the
    docstring), not more: found here by brute force over the domain's grid."""
    env = gym.make("fir_gym/VanDerPol-v0", state_bound=state_bound).unwrapped
    side = np.linspace(-state_bound, state_bound, 41)
    x1, x2, a = np.meshgrid(side, side, np.linspace(-1.0, 1.0, 9), indexing="ij")
    largest = ((x1 ** 2 + x2 ** 2) / 4 + 0.01 * a * a).max()
    assert env.cost_cap == pytest.approx(largest, rel=1e-14)


def test_carrier_motion_reward():
    """``−min(((x1' − a c_max) / σ1)², 100)``: the residual of the compensated deck over a
    constant σ1 (so ``−reward / (x1' − a c_max)²`` is one number over the episode), and the
    cap where the residual is huge."""
    env, steps = rollout("fir_gym/CarrierMotion-v0", c_max=0.7)
    assert steps
    scale = [-reward / (x[0] - a * 0.7) ** 2 for x, a, reward in steps]
    np.testing.assert_allclose(scale, scale[0], rtol=1e-9)
    env.reset(seed=0, options={"state": [1e3, 0.0]})
    _, reward, *_ = env.step(np.array([0.0]))
    assert reward == -100.0


@pytest.mark.parametrize("env_id", ["fir_gym/CarrierMotion-v0", "fir_gym/VanDerPol-v0"])
def test_the_lqg_design_weights_are_the_rewards_cost(env_id: str) -> None:
    """Where the operating point is the origin (``x* = 0``, ``u* = 0``), the design point's
    weights ``M`` on ``[x[k+1]; a[k]]`` are the reward's cost exactly: ``zᵀ M z = −reward``
    below the cap (mutation testing found a weight free to change)."""
    from fir_gym.controllers import design_point
    env, steps = rollout(env_id)
    point = design_point(env)
    assert not point.x.any() and not point.u.any()
    assert steps
    for x, a, reward in steps:
        z = np.concatenate([x, [a]])
        assert z @ point.M @ z == pytest.approx(-reward, rel=1e-10, abs=1e-14)
