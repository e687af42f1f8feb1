"""The fir-gym command."""

import re

import pytest

import fir_gym
from fir_gym.cli import main


def test_reproduce_with_out_prints_the_verdict_counts_the_path_and_its_time(capsys, tmp_path):
    """With --out the report goes to the file (one block per environment, the paper's
    section); the terminal gets the verdict counts per paper, the path, and on stderr the
    command's wall and CPU time, which the report does not carry."""
    from fir_gym.scenarios.summary import COLUMNS

    assert main(["reproduce", "--seed", "3", "--quick", "--paper", "003", "--runs", "2",
                 "--no-progress", "--out", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    report = (tmp_path / "REPORT.md").read_text()
    for env_id in fir_gym.ENV_IDS:
        assert env_id.split("/")[-1] in report
    assert "## Scripted episodes" in report and "## Paper 003" in report
    lines = captured.out.splitlines()
    assert lines[-1] == f"wrote {tmp_path / 'REPORT.md'}"
    assert len(lines) < 12                                  # a summary, not the report
    header = next(line for line in lines if line.startswith("paper"))
    assert header.split()[-1] == "rows" and all(c.split()[0] in header for c in COLUMNS)
    assert any(line.startswith("Paper 003 ") for line in lines) and "Paper 001" not in captured.out
    assert "Setup:" not in captured.out and "| quantity" not in captured.out
    timing = captured.err.strip().splitlines()[-1]
    assert re.fullmatch(r"fir-gym reproduce took [\d.]+ s wall, [\d.]+ s CPU \([\d.]+ s this "
                        r"process, [\d.]+ s worker processes\)", timing), timing
    assert " s wall" not in report and " CPU" not in report


def test_reproduce_without_out_prints_the_whole_report(capsys):
    assert main(["reproduce", "--quick", "--paper", "002", "--runs", "2", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "Verdicts" in out and "Scripted episodes" in out and "Paper 002" in out
    assert "Setup:" in out and out.rstrip().splitlines()[-1].startswith("all ")


def test_reproduce_rejects_unknown_papers():
    with pytest.raises(SystemExit):
        main(["reproduce", "--paper", "007"])


def test_reproduce_paper_selection_includes_the_sweeps():
    from fir_gym.cli import _papers

    assert _papers("000,sweeps") == ["000", "sweeps"]


def test_list_names_every_environment(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert all(env_id in out for env_id in fir_gym.ENV_IDS)


def test_every_subcommand_of_the_parser_runs_a_command():
    """The parser names a subcommand and imports no command; cli.main runs it from
    _commands.COMMANDS (speed and bench hand their raw arguments to cmd_speed)."""
    import argparse

    from fir_gym._commands import COMMANDS
    from fir_gym.cli import SPEED_COMMANDS, build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) - set(SPEED_COMMANDS) == set(COMMANDS)


def test_unknown_subcommand_is_an_argparse_error():
    with pytest.raises(SystemExit) as exc:
        main(["nonsense"])
    assert exc.value.code == 2


def test_version(capsys):
    with pytest.raises(SystemExit):
        main(["--version"])
    assert fir_gym.__version__ in capsys.readouterr().out


def test_speed_and_bench_forward_options_to_the_benchmark(monkeypatch):
    import fir_gym.benchmarks.speed as speed

    seen = []
    monkeypatch.setattr(speed, "main", lambda argv: seen.append(argv) or 0)
    assert main(["speed", "--json", "out.json", "estimators"]) == 0
    assert seen == [["--json", "out.json", "estimators"]]
    with pytest.raises(SystemExit):
        main(["list", "--json", "x"])
