"""Run tests against one hand-written mutant, applied in memory: the check that a new test
kills the survivor it was written for, without editing any file.

    python scripts/apply_mutant.py MODULE OLD NEW [PYTEST ARGS ...]

``MODULE`` is an import name (``fir_gym.estimators.efir``); ``OLD`` must occur exactly once
in its source and is replaced by ``NEW``. Only the top-level function or class holding it
is re-executed in the module's namespace; a class is patched in place (the methods'
zero-argument ``super`` cells pointed at it), so subclasses, registries and earlier
imports see the mutant too, and a function replaces every module's name for it (a
package's re-export included). The tests then run in this process (``pytest.main``).
``OLD`` = ``NEW`` is the control: the tests must pass.

numba's cache goes to a fresh temporary folder: a mutated kernel compiled into the
checkout's cache would be found there, under the unchanged file's stamp, by every later run.
Unlike ``scripts/mutation.py`` this touches no file, so it may run beside other tests.
"""

from __future__ import annotations

import ast
import importlib
import os
import sys
import tempfile
from typing import Any


class Mutant:
    """A pytest plugin applying ``old`` → ``new`` in ``module`` before collection."""

    def __init__(self, module: str, old: str, new: str) -> None:
        self.module, self.old, self.new = module, old, new

    def pytest_configure(self, config: Any) -> None:
        mod = importlib.import_module(self.module)
        assert mod.__file__ is not None
        with open(mod.__file__, encoding="utf-8") as f:
            src = f.read()
        if src.count(self.old) != 1:
            raise SystemExit(f"OLD occurs {src.count(self.old)} times in {mod.__file__}; "
                             "it must occur once")
        at = src.index(self.old)
        offsets = [0]
        for line in src.splitlines(keepends=True):
            offsets.append(offsets[-1] + len(line))
        for node in ast.parse(src).body:
            decorators = getattr(node, "decorator_list", None)
            first = decorators[0].lineno if decorators else node.lineno
            start, end = offsets[first - 1], offsets[node.end_lineno or node.lineno]
            if start <= at < end:
                break
        else:
            raise SystemExit("OLD is not inside a top-level statement")
        segment = "\n" * src[:start].count("\n") + src[start:end].replace(self.old, self.new)
        before = mod.__dict__.get(getattr(node, "name", ""))
        exec(compile(segment, mod.__file__, "exec"), mod.__dict__)
        if isinstance(node, ast.ClassDef) and isinstance(before, type):
            for key, value in vars(mod.__dict__[node.name]).items():
                if key in ("__dict__", "__weakref__"):
                    continue
                for fn in (value, getattr(value, "__func__", None), getattr(value, "fget", None)):
                    code = getattr(fn, "__code__", None)
                    if code is not None and "__class__" in code.co_freevars:
                        fn.__closure__[code.co_freevars.index("__class__")].cell_contents = before
                setattr(before, key, value)
            mod.__dict__[node.name] = before
        elif before is not None:
            # a function: every module that imported it by name gets the mutant too
            after = mod.__dict__[node.name]
            for other in list(sys.modules.values()):
                for key, value in list(getattr(other, "__dict__", {}).items()):
                    if value is before:
                        setattr(other, key, after)
        print(f"mutant applied in {self.module}: {self.old!r} -> {self.new!r}", file=sys.stderr)


def main(argv: list[str]) -> int:
    if len(argv) < 3:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    module, old, new, *pytest_args = argv
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="fir-gym-mutant-numba-")
    import pytest
    return int(pytest.main(["-p", "no:cacheprovider", *pytest_args],
                           plugins=[Mutant(module, old, new)]))


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
