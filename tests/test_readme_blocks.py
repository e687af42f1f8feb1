"""Every Python block of README.md runs as a script, prints what it computes, and warns of
nothing (issue 26, item 8).

Each block runs in a fresh interpreter from an empty folder, exactly as a reader pasting it
into a file would run it: exit status 0, something on stdout, no warning on stderr (a
progress bar may draw there).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"),
                    re.MULTILINE | re.DOTALL)
NEEDS = {"stable_baselines3": "stable_baselines3", "filterpy": "filterpy"}


def test_the_readme_has_python_blocks() -> None:
    assert len(BLOCKS) >= 5


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=lambda i: f"block{i + 1}")
def test_a_readme_block_runs_as_a_script(index: int, tmp_path: Path) -> None:
    block = BLOCKS[index]
    for needle, module in NEEDS.items():
        if needle in block:
            pytest.importorskip(module)
    result = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True,
                            text=True, timeout=900, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip(), "the block prints nothing"
    assert "Warning" not in result.stderr, result.stderr[-2000:]
