"""The fir-gym command."""

import pytest

import fir_gym
from fir_gym.cli import main


def test_reproduce_prints_one_block_per_environment(capsys, tmp_path):
    assert main(["reproduce", "--seed", "3", "--quick", "--paper", "003", "--runs", "2",
                 "--no-progress", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    for env_id in fir_gym.ENV_IDS:
        assert env_id.split("/")[-1] in out
    report = (tmp_path / "REPORT.md").read_text()
    assert "## Scripted episodes" in report and "## Paper 003" in report
    assert "Paper 001" not in out


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
