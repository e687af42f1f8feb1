"""The version of the code a result was computed with: part of every reusable job's key.

``benchmark-controllers``, ``compare-controllers --resume`` and ``benchmark-robustness``
reuse a finished job's ``result.json`` only when its configuration *and* its
:func:`code_version` equal this run's, so a change anywhere in the package — a plant, a
filter, a wrapper, the training recipe — invalidates every result computed before it. The
version is the SHA-256 of every source and data file of the installed package
(``fir_gym``, ``fir_gym.envs``, ``fir_gym.estimators`` and their sub-packages: ``.py``,
``.yml``, ``.xml``), path by path in sorted order, and the package's version string;
documentation, tests and scripts are not part of it, nor are the modules that only
present finished results or run other commands (:data:`PRESENTATION`: the report, the
tables, the figures, the command line, the paper scenarios, the speed benchmarks), which
cannot change a job's numbers. It is computed once per process.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

#: the files that make up the code
SUFFIXES = (".py", ".yml", ".yaml", ".xml")
#: files and folders of ``fir_gym`` that only present results or run other commands
PRESENTATION = ("_cli_parser.py", "_commands.py", "_extras.py", "cli.py", "tables.py",
                "video.py", "episode_policy.py", "machine.py", "benchmarks", "plotting",
                "scenarios", "robustness/benchmark.py",
                "robustness/report.py", "robustness/tables.py", "robustness/answers.py",
                "robustness/readme.py", "robustness/formatting.py",
                "training/benchmark.py", "training/curves.py")


def code_files() -> list[tuple[str, Path]]:
    """``(name, path)`` of every file :func:`code_version` hashes, in its order: the name is
    the file's path inside the installed package (``fir_gym/...``, ``fir_gym.envs/...``)."""
    import fir_gym
    import fir_gym.envs
    import fir_gym.estimators

    files = []
    for package, module in (("fir_gym", fir_gym), ("fir_gym.envs", fir_gym.envs),
                            ("fir_gym.estimators", fir_gym.estimators)):
        for root in sorted(set(module.__path__)):
            base = Path(root)
            for path in sorted(base.rglob("*")):
                relative = path.relative_to(base)
                if (path.suffix not in SUFFIXES or "__pycache__" in relative.parts
                        or not path.is_file()):
                    continue
                if package == "fir_gym" and (
                        relative.parts[0] in ("envs", "estimators")   # their own packages
                        or relative.parts[0] in PRESENTATION
                        or relative.as_posix() in PRESENTATION):
                    continue
                files.append((f"{package}/{relative.as_posix()}", path))
    return files


@functools.cache
def code_version() -> str:
    """The first 16 hex digits of the SHA-256 of the package's files (module docstring)."""
    import fir_gym

    digest = hashlib.sha256(fir_gym.__version__.encode())
    for name, path in code_files():
        digest.update(f"{name}\0".encode())
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()[:16]
