"""The kinds of controller fir-gym trains and compares, their options, and their checks.

A *kind* names what a controller sees and how it is made:

* learned (stable-baselines3), on ``true`` (the true state), ``measurement`` (the raw
  noisy measurement), ``measurement-stack`` (the last K measurements and actions;
  option ``horizon``, default the plant's ``default_horizon``), ``recurrent``
  (sb3-contrib's RecurrentPPO, an LSTM policy on the raw measurements) or an
  estimator's estimate (any registry name: ``ekf``, ``ukf``, ``efir``, ...; options:
  the estimator's, e.g. ``horizon``);
* classical, nothing to train: ``lqg`` (the LQR of the nominal model on an estimate;
  options ``estimator`` — a registry name, default ``ekf``, or ``true`` for the LQR on
  the true state — ``input_weight``, the design's weight of ``a²``
  (:class:`~fir_gym.controllers.LQGController`), and that estimator's options) and
  ``pid`` (on the measured output; options ``kp``, ``ki``, ``kd``, ``setpoint``,
  ``output``, ``tau``, ``feedforward``).

Options travel in one format everywhere (``train``, ``evaluate``,
``compare-controllers``, ``benchmark-controllers``): a JSON object mapping each kind to
its options, ``{"efir": {"horizon": 50}, "lqg": {"estimator": "ukf"}}``. A key that is
not among the kinds run, or an option a kind does not take, is an error naming it —
nothing is dropped.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from fir_gym.estimators import estimator_names

LEARNED_PLAIN = ("true", "measurement", "measurement-stack", "recurrent")
CLASSICAL = ("lqg", "pid")
PID_OPTIONS = ("kp", "ki", "kd", "setpoint", "output", "tau", "feedforward")
LQG_OPTIONS = ("input_weight",)


def kind_names() -> list[str]:
    """Every kind: the plain learned ones, each estimator's, then the classical ones."""
    return [*LEARNED_PLAIN, *estimator_names(), *CLASSICAL]


def is_learned(kind: str) -> bool:
    return kind not in CLASSICAL


@dataclass(frozen=True)
class EnvRecipe:
    """How to build a kind's env: the arguments of :func:`~.vec_env.make_sb3_vec_env`."""

    estimator: str | None
    estimator_kwargs: dict[str, Any]
    observation: str
    stack_horizon: int | None = None

    def kwargs(self) -> dict[str, Any]:
        out: dict[str, Any] = {"estimator": self.estimator, "observation": self.observation,
                               "estimator_kwargs": dict(self.estimator_kwargs) or None}
        if self.stack_horizon is not None:
            out["stack_horizon"] = self.stack_horizon
        return out


def check_kind(kind: str) -> None:
    """A ValueError listing the kinds if ``kind`` is not one."""
    names = kind_names()
    if kind not in names:
        raise ValueError(f"unknown kind {kind!r}; kinds are {', '.join(names)}")


def recipe(kind: str, options: Mapping[str, Any], observation: str = "estimate") -> EnvRecipe:
    """The env a controller of ``kind`` with ``options`` sees (options checked by name)."""
    check_kind(kind)
    options = dict(options)
    if kind in ("true", "measurement", "recurrent"):
        _no_options(kind, options, ())
        return EnvRecipe(None, {}, "true" if kind == "true" else "measurement")
    if kind == "measurement-stack":
        _no_options(kind, options, ("horizon",))
        return EnvRecipe(None, {}, "measurement-stack", options.get("horizon"))
    if kind == "pid":
        _no_options(kind, options, PID_OPTIONS)
        return EnvRecipe(None, {}, "measurement")
    if kind == "lqg":
        estimator = options.pop("estimator", "ekf")
        options.pop("input_weight", None)               # the controller's (checked there)
        if estimator == "true":
            _no_options("lqg with estimator 'true'", options, ())
            return EnvRecipe(None, {}, "true")
        if estimator not in estimator_names():
            raise ValueError(f"lqg: estimator must be 'true' or one of "
                             f"{', '.join(estimator_names())}; got {estimator!r}")
        _estimator_options(estimator, options, f"lqg ({estimator})")
        return EnvRecipe(estimator, options, "estimate")
    _estimator_options(kind, options, kind)
    return EnvRecipe(kind, options, observation)


def controller_options(kind: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """The options of a classical kind that go to the controller (PID's gains, the LQG's
    input weight)."""
    allowed = PID_OPTIONS if kind == "pid" else LQG_OPTIONS if kind == "lqg" else ()
    return {k: v for k, v in options.items() if k in allowed}


def kind_options(mapping: Mapping[str, Any] | None, kinds: Iterable[str]
                 ) -> dict[str, dict[str, Any]]:
    """Per-kind options from the one documented format, checked against ``kinds``.

    ``mapping`` is ``{kind: {option: value}}``; a key that is not among ``kinds`` or a
    value that is not an object is a ValueError that names it (a flat
    ``{"horizon": 50}`` is rejected with the nested form to use).
    """
    kinds = list(kinds)
    out: dict[str, dict[str, Any]] = {k: {} for k in kinds}
    for key, value in dict(mapping or {}).items():
        if key not in kinds:
            hint = ""
            if len(kinds) == 1 and not isinstance(value, Mapping):
                hint = f' (options go under their kind: {{"{kinds[0]}": {{"{key}": ...}}}})'
            raise ValueError(f"kind options name {key!r}, which is not among the kinds run "
                             f"({', '.join(kinds)}){hint}")
        if not isinstance(value, Mapping):
            raise ValueError(f"the options of {key!r} must be a JSON object; got {value!r}")
        out[key] = dict(value)
    return out


def _no_options(kind: str, options: Mapping[str, Any], allowed: tuple[str, ...]) -> None:
    bad = sorted(set(options) - set(allowed))
    if bad:
        valid = ", ".join(allowed) if allowed else "none"
        raise ValueError(f"{kind} takes no option {', '.join(map(repr, bad))}; its options: "
                         f"{valid}")


def _estimator_options(name: str, options: Mapping[str, Any], label: str) -> None:
    """Option names the estimator's constructor (or the base Estimator) accepts."""
    from fir_gym.estimators import Estimator, estimator_class

    accepted: set[str] = set()
    for cls in estimator_class(name).__mro__:
        if isinstance(cls, type) and issubclass(cls, Estimator):
            accepted |= set(inspect.signature(cls.__init__).parameters) - {"self", "model"}
    if any(p.kind == p.VAR_KEYWORD for p in inspect.signature(
            estimator_class(name).__init__).parameters.values()):
        accepted.discard("options")
    accepted -= {"options", "kwargs"}
    bad = sorted(set(options) - accepted)
    if bad:
        raise ValueError(f"{label} takes no option {', '.join(map(repr, bad))}; its options: "
                         f"{', '.join(sorted(accepted))}")
