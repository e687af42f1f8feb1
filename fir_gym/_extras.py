"""The optional extras: which ``pip install`` brings back a missing package.

fir-gym's core (plants, estimators, ``fir-gym reproduce``) needs only its dependencies;
training, Dask, videos, the filterpy references and the JAX backend come with extras
(``pyproject.toml``'s ``[project.optional-dependencies]``). :func:`install_hint` turns
the name of a missing module into the command that installs it, so an error can say
what fixes it instead of ``No module named 'torch'``.
"""

from __future__ import annotations

#: the command that installs each extra, from a checkout of fir-gym (it is not on a package
#: index; PyTorch first for ``rl``: stable-baselines3 would otherwise pull a CUDA build)
INSTALL = {extra: f'{command} (in the fir-gym checkout)' for extra, command in {
    "rl": 'pip install torch==2.13.0 && pip install ".[rl]"',
    "cluster": 'pip install ".[cluster]"',
    "video": 'pip install ".[video]"',
    "bench": 'pip install ".[bench]"',
    "docs": 'pip install ".[docs]"',
    "dataset": 'pip install ".[dataset]"',
    "jax": 'pip install ".[jax]"',
}.items()}

#: top-level module -> (the package's name, the extra that installs it)
MODULES = {
    "torch": ("PyTorch", "rl"),
    "stable_baselines3": ("stable-baselines3", "rl"),
    "sb3_contrib": ("sb3-contrib", "rl"),
    "yaml": ("PyYAML", "rl"),
    "rich": ("rich", "rl"),
    "dask": ("Dask", "cluster"),
    "distributed": ("Dask's distributed", "cluster"),
    "imageio": ("imageio", "video"),
    "imageio_ffmpeg": ("imageio-ffmpeg", "video"),
    "filterpy": ("filterpy", "bench"),
    "mkdocs": ("MkDocs", "docs"),
    "minari": ("Minari", "dataset"),
    "h5py": ("h5py", "dataset"),
    "jax": ("JAX", "jax"),
    "jaxlib": ("jaxlib", "jax"),
    "gymnax": ("gymnax", "jax"),
    "rejax": ("rejax", "jax"),
}


class MissingExtra(ModuleNotFoundError):
    """A package of an optional extra is not installed; the message says how to get it."""


def install_hint(module: str | None) -> str | None:
    """``'PyTorch is missing: pip install ...'`` for a module of an extra, else ``None``.

    ``module`` is a (possibly dotted) module name, as ``ModuleNotFoundError.name``
    gives it; ``tensorboard`` (a plain package, in no extra) gets its own command.
    """
    top = (module or "").split(".")[0]
    if top == "tensorboard":
        return "TensorBoard is missing: pip install tensorboard"
    if top not in MODULES:
        return None
    package, extra = MODULES[top]
    return f"{package} is missing (the {extra} extra): {INSTALL[extra]}"


def require(*modules: str) -> None:
    """Import each module now, so that a missing extra is one clear error before any work
    (:func:`install_hint`'s message) instead of a failure hours into a run."""
    import importlib

    for module in modules:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as err:
            hint = install_hint(err.name or module)
            if hint is None:
                raise
            raise MissingExtra(hint) from None
