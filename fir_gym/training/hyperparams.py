"""Per-plant hyperparameters in RL Zoo's YAML format, shipped with the package.

``fir_gym/training/hyperparams/<algo>.yml`` (``ppo``, ``ppo_lstm`` for sb3-contrib's
RecurrentPPO, ``sac``) holds one entry per env id (and ``default``), as
``rl_zoo3/hyperparams/<algo>.yml`` does: ``n_timesteps``, ``policy``, ``n_envs``,
``normalize`` (``true``/``false`` or a mapping of ``VecNormalize`` options) and the
algorithm's keyword arguments. ``policy_kwargs`` may be a mapping or RL Zoo's string
``"dict(log_std_init=-1.0, net_arch=dict(pi=[64], vf=[64]), activation_fn=nn.Tanh)"``,
read here without ``eval`` (literals, nested ``dict(...)`` and ``nn.<Activation>``).
The YAML anchors (``<<: *default``) are plain YAML; an entry per env id is what RL
Zoo's ``train.py -f <folder>`` looks up.
"""

from __future__ import annotations

import ast
from importlib import resources
from pathlib import Path
from typing import Any

#: fir-gym's algorithm names -> the YAML file (RL Zoo's algorithm name)
FILES = {"ppo": "ppo", "recurrent-ppo": "ppo_lstm", "sac": "sac"}
#: keys that are RL Zoo's, not the algorithm's
ZOO_KEYS = ("n_timesteps", "policy", "n_envs", "normalize")


def load(algo: str, path: str | Path | None = None) -> dict[str, Any]:
    """Every entry of ``algo``'s YAML file (the shipped one, or ``path``)."""
    import yaml

    if path is None:
        if algo not in FILES:
            raise ValueError(f"algo must be one of {sorted(FILES)}; got {algo!r}")
        text = resources.files("fir_gym.training").joinpath(
            "hyperparams").joinpath(FILES[algo] + ".yml").read_text(encoding="utf-8")
    else:
        text = Path(path).read_text(encoding="utf-8")
    data = yaml.safe_load(text) or {}
    if not isinstance(data, dict):
        raise ValueError(f"a hyperparameter file maps env ids to settings; got {type(data)}")
    return data


def hyperparameters(algo: str, env_id: str, path: str | Path | None = None) -> dict[str, Any]:
    """The settings of ``env_id`` (else ``default``) with ``policy_kwargs`` parsed."""
    data = load(algo, path)
    entry = data.get(env_id, data.get("default"))
    if entry is None:
        raise ValueError(f"no hyperparameters for {env_id} (nor a default) in {algo}'s file")
    entry = dict(entry)
    if isinstance(entry.get("policy_kwargs"), str):
        entry["policy_kwargs"] = parse_policy_kwargs(entry["policy_kwargs"])
    return entry


def split(entry: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(RL Zoo's keys, the algorithm's keyword arguments)`` of one entry."""
    zoo = {k: entry[k] for k in ZOO_KEYS if k in entry}
    algo = {k: v for k, v in entry.items() if k not in ZOO_KEYS}
    return zoo, algo


def normalize_options(value: Any) -> dict[str, Any] | None:
    """RL Zoo's ``normalize`` as ``VecNormalize`` options, or None for no normalisation."""
    if value is None or value is False:
        return None
    if value is True:
        return {}
    if isinstance(value, str):
        value = _literal(ast.parse(value, mode="eval").body)
    if not isinstance(value, dict):
        raise ValueError(f"normalize must be true, false or a mapping; got {value!r}")
    return dict(value)


def parse_policy_kwargs(text: str) -> dict[str, Any]:
    """RL Zoo's ``policy_kwargs`` string (``"dict(...)"``) as a dict, without ``eval``."""
    try:
        value = _literal(ast.parse(text.strip(), mode="eval").body)
    except (SyntaxError, ValueError) as err:
        raise ValueError(f"policy_kwargs {text!r} is not a dict(...) of literals: {err}") from None
    if not isinstance(value, dict):
        raise ValueError(f"policy_kwargs must be a dict; got {text!r}")
    return value


def _literal(node: ast.AST) -> Any:
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict":
        if node.args:
            raise ValueError("dict(...) takes keyword arguments only")
        return {kw.arg: _literal(kw.value) for kw in node.keywords}
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
            and node.value.id == "nn":
        import torch.nn as nn

        cls = getattr(nn, node.attr, None)
        if not isinstance(cls, type):
            raise ValueError(f"nn.{node.attr} is not a torch.nn class")
        return cls
    if isinstance(node, (ast.List, ast.Tuple)):
        items = [_literal(e) for e in node.elts]
        return items if isinstance(node, ast.List) else tuple(items)
    if isinstance(node, ast.Dict):
        return {_literal(k): _literal(v) for k, v in zip(node.keys, node.values, strict=True)
                if k is not None}
    return ast.literal_eval(node)
