"""docs/getting-started.md's "A filter on its own" runs as written (its Python blocks, in
order, in a namespace of their own: the section defines everything it uses)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

PAGE = Path(__file__).resolve().parents[1] / "docs" / "getting-started.md"


def section_blocks(title: str) -> list[str]:
    """The ```python blocks of the page's section ``## title``."""
    text = PAGE.read_text(encoding="utf-8")
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text,
                      re.MULTILINE | re.DOTALL)
    assert match, f"{PAGE.name} has no section {title!r}"
    return re.findall(r"^```python\n(.*?)^```", match.group(1), re.MULTILINE | re.DOTALL)


def test_a_filter_on_its_own_runs_as_written(capsys):
    blocks = section_blocks("A filter on its own")
    assert blocks
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(PAGE), "exec"), namespace)
    capsys.readouterr()
    x_hat, state = namespace["x_hat"], namespace["info"]["state"]
    assert x_hat.shape == (2,) and np.all(np.isfinite(x_hat))
    assert namespace["efir"].time_step == 2                 # two steps: y[0]; u[0], y[1]
    assert np.all(np.abs(x_hat - state) < 1.0)               # near the truth (r ≈ 8, v ≈ 2)
