"""Table formatting used by reports and benchmarks."""

import numpy as np
import pytest

from fir_gym.tables import format_table


def test_text_table_aligns_numbers_right_and_text_left():
    text = format_table(["name", "value"], [["a", 1.5], ["long name", np.float64(22.25)]])
    lines = text.splitlines()
    assert lines[0].startswith("name") and set(lines[1]) <= {"-", " "}
    assert lines[2].endswith("  1.5") and lines[3].endswith("22.25")


def test_markdown_table_and_empty_cells():
    text = format_table(["a", "b"], [[1, None], [2, 3.0]], markdown=True)
    lines = text.splitlines()
    assert lines[0] == "| a | b |" and lines[1] == "|--:|--:|"
    assert lines[2] == "| 1 |   |"


def test_row_length_mismatch_raises():
    with pytest.raises(ValueError, match="row 0"):
        format_table(["a", "b"], [[1]])


def test_markdown_cells_escape_pipes():
    text = format_table(["|x|"], [["a | b"]], markdown=True)
    header, _, row = text.splitlines()
    assert header == "| \\|x\\|  |"          # padded to the width of the escaped cell
    assert row == "| a \\| b |"
