"""The LSTM of the recurrent policy: one layer of ``torch.nn.LSTM``, in torch's own layout.

sb3-contrib's ``RecurrentActorCriticPolicy`` (the SB3 backend's ``recurrent`` kind) runs its
observations through a one-layer ``torch.nn.LSTM`` before the MLP; this is that layer, so a
policy trained by either backend is the same function of the same parameters. Torch's
equations (``torch.nn.LSTM``'s documentation), gates in torch's order *i, f, g, o*::

    [i; f; g; o] = W_ih x + b_ih + W_hh h + b_hh
    c' = σ(f) ⊙ c + σ(i) ⊙ tanh(g)
    h' = σ(o) ⊙ tanh(c')

with the parameters named and shaped as torch's (``weight_ih (4H, n)``, ``weight_hh (4H, H)``,
``bias_ih (4H)``, ``bias_hh (4H)``) and initialised as torch's (every one uniform in
``±1/√H``: sb3-contrib's orthogonal initialisation touches only its linear layers). At the
start of an episode the carry is cleared before the step, as sb3-contrib's
``_process_sequence`` multiplies it by ``1 − episode_start``.

:func:`step` is one step for a batch, :func:`unroll` a sequence (time first) with the clearing
at each episode start, :func:`replay` a sequence that also takes stored carries where
sb3-contrib's minibatches begin their sequences — what training replays.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
from flax import linen as nn

#: ``(h, c)``: the LSTM's hidden and cell state, each ``(batch, H)``
Carry = tuple[Any, Any]


def _uniform(bound: float) -> Any:
    def init(key: Any, shape: tuple[int, ...], dtype: Any = jnp.float32) -> Any:
        return jax.random.uniform(key, shape, dtype, -bound, bound)

    return init


class LSTMCell(nn.Module):
    """One step of ``torch.nn.LSTM`` (one layer): ``(carry, x) -> carry`` (module
    docstring)."""

    features: int
    #: the parameters' and the arithmetic's dtype (the input and the carry are cast to it)
    dtype: Any = jnp.float32

    @nn.compact
    def __call__(self, carry: Carry, x: Any) -> Carry:
        h, c = (part.astype(self.dtype) for part in carry)
        x = x.astype(self.dtype)
        init = _uniform(1.0 / math.sqrt(self.features))
        w_ih = self.param("weight_ih", init, (4 * self.features, x.shape[-1]), self.dtype)
        w_hh = self.param("weight_hh", init, (4 * self.features, self.features), self.dtype)
        b_ih = self.param("bias_ih", init, (4 * self.features,), self.dtype)
        b_hh = self.param("bias_hh", init, (4 * self.features,), self.dtype)
        gates = x @ w_ih.T + b_ih + h @ w_hh.T + b_hh
        i, f, g, o = jnp.split(gates, 4, axis=-1)
        c = nn.sigmoid(f) * c + nn.sigmoid(i) * jnp.tanh(g)
        return nn.sigmoid(o) * jnp.tanh(c), c


def zeros(batch: int, features: int, dtype: Any = jnp.float32) -> Carry:
    """The carry an episode starts from (torch's and sb3-contrib's: zeros)."""
    return jnp.zeros((batch, features), dtype), jnp.zeros((batch, features), dtype)


def step(cell: LSTMCell, params: Any, carry: Carry, x: Any, start: Any) -> Carry:
    """One step for a batch: ``x (batch, n)``; ``start (batch,)`` marks the first step of an
    episode, where the carry is cleared first. Returns the new carry (its ``h`` is the output)."""
    keep = 1.0 - jnp.asarray(start, dtype=carry[0].dtype)[:, None]
    return cell.apply(params, (carry[0] * keep, carry[1] * keep), x)


def unroll(cell: LSTMCell, params: Any, carry: Carry, xs: Any, starts: Any,
           restarts: tuple[Carry, Any] | None = None) -> tuple[Carry, Any]:
    """A sequence: ``xs (T, batch, n)``, ``starts (T, batch)``. Returns ``(final carry,
    outputs (T, batch, H))``. ``restarts = (stored, begins)``: before each step where
    ``begins (T, batch)`` is set the carry is replaced by ``stored``'s carry of that step
    (``(h, c)``, each ``(T, batch, H)``) — see :func:`replay`."""
    def one(carry: Carry, inputs: tuple[Any, ...]) -> tuple[Carry, Any]:
        x, start, *restart = inputs
        if restart:
            (h, c), begin = restart[0]
            carry = (jnp.where(begin[:, None], h, carry[0]),
                     jnp.where(begin[:, None], c, carry[1]))
        carry = step(cell, params, carry, x, start)
        return carry, carry[0]

    return jax.lax.scan(one, carry, (xs, starts, *([restarts] if restarts else [])))


def replay(cell: LSTMCell, params: Any, stored: Carry, xs: Any, starts: Any, begins: Any
           ) -> Any:
    """:func:`unroll` whose carry is replaced by ``stored`` where ``begins`` is set: rows of
    sb3-contrib's minibatch sequences, each begun from the LSTM states the rollout stored at
    its first step (``RecurrentRolloutBuffer._get_samples``' ``lstm_states``). ``stored (T,
    batch, H)`` each is the carry before each step as the rollout had it (a constant: no
    gradient flows through it to earlier steps), ``xs (T, batch, n)``, ``starts`` and
    ``begins (T, batch)``. A row begins from its first stored carry; where an episode starts
    the carry is cleared after the replacement, as ``_process_sequence`` multiplies the
    stored state by ``1 − episode_start``. Returns the outputs ``(T, batch, H)``."""
    first = (stored[0][0], stored[1][0])
    return unroll(cell, params, first, xs, starts, (stored, begins))[1]
