"""The gradients a PPO update hands to Adam, captured: what the JAX update computes, for the
tests that compare it with torch's autograd through SB3's and sb3-contrib's losses."""

from __future__ import annotations

from typing import Any


class _Capture:
    """A train state that records the gradients it is given instead of applying them."""

    def __init__(self, name: str, params: Any, captured: dict[str, Any]) -> None:
        self.name, self.params, self.captured = name, params, captured

    def apply_gradients(self, grads: Any) -> _Capture:
        self.captured[self.name] = grads
        return self


class _TrainState:
    def __init__(self, actor: Any, critic: Any, captured: dict[str, Any]) -> None:
        self.actor_ts = _Capture("actor", actor, captured)
        self.critic_ts = _Capture("critic", critic, captured)

    def replace(self, **kw: Any) -> _TrainState:
        return self


def update_gradients(algo: Any, actor: Any, critic: Any, minibatch: Any) -> dict[str, Any]:
    """``{"actor": grads, "critic": grads}``: what ``algo.update`` (the actor's, then the
    critic's step on ``minibatch``) hands to each optimiser from these parameters."""
    captured: dict[str, Any] = {}
    algo.update(_TrainState(actor, critic, captured), minibatch)
    return captured
