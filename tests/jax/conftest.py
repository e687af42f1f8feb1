"""The JAX tests' compilation cache: one persistent cache (JAX's, on disk) for the whole test
session, shared by pytest-xdist's workers.

Many tests compile the same program again (the same plant, kind and options jitted by
another test, or by another worker): XLA's compile dominates the JAX tests' time on a small
CPU, and a cache hit loads the very executable the first compile made, so the results are
bit for bit those of compiling again. The folder is new for every session (under pytest's
temporary root, which all workers of one run share), so nothing from an earlier run or
another version of the code is ever loaded: each program is compiled once per session.
Measured on 2 cores with three of the compile-heavy files (test_registry, test_kinds,
test_small_linalg): 460 s of CPU without the cache, 268 s with it.

Tests that train use it too: the ``cache`` fixtures of test_train.py and test_run_folder.py
return :func:`jax_cache`, and ``$FIR_GYM_JAX_CACHE`` (:data:`fir_gym.jax.train.CACHE_ENV`) points
at it, so a training with the default cache does not write to the user's home.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

#: :data:`fir_gym.jax.train.CACHE_ENV` (not imported: this file loads without the extra)
CACHE_ENV = "FIR_GYM_JAX_CACHE"


@pytest.fixture(scope="session")
def jax_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The session's compilation-cache folder, the same for every xdist worker of a run."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):          # .../pytest-N/popen-gwK: share N
        root = root.parent
    folder = root / "jax-compilation-cache"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


@pytest.fixture(scope="session", autouse=True)
def _session_compilation_cache(jax_cache: Path) -> Iterator[None]:
    """JAX's persistent cache in :func:`jax_cache` for every program, before the first
    compile (no minimum compile time or size; nothing without JAX installed)."""
    try:
        import jax
    except ImportError:
        yield
        return
    before = os.environ.get(CACHE_ENV)
    os.environ[CACHE_ENV] = str(jax_cache)
    jax.config.update("jax_compilation_cache_dir", str(jax_cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    yield
    if before is None:
        os.environ.pop(CACHE_ENV, None)
    else:
        os.environ[CACHE_ENV] = before
