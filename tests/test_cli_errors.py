"""The CLI helps: each mistake of issue 17 is one line on stderr and exit status 2.

The missing-extra cases run in a fresh interpreter in which the extra's package is
blocked (``sys.modules[name] = None`` makes ``import name`` fail as if it were absent).
"""

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from fir_gym.cli import build_parser, main

PACKAGE = Path(__import__("fir_gym").__file__).parent


def one_line(capsys, argv, *needles):
    """Run ``fir-gym argv`` in process: exit 2 (returned or raised) and one stderr line."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2, captured.err
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    assert lines[0].startswith("fir-gym"), lines[0]
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def run_blocked(blocked, argv):
    """``fir-gym argv`` in a fresh interpreter with the ``blocked`` modules absent."""
    code = ("import sys\n"
            f"for name in {list(blocked)!r}: sys.modules[name] = None\n"
            "from fir_gym.cli import main\n"
            f"raise SystemExit(main({list(argv)!r}))\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd="/", timeout=300)


@pytest.mark.parametrize(("blocked", "argv", "install"), [
    (["stable_baselines3"], ["train", "--env", "fir_gym/Orbit-v0", "--out", "RUN"],
     'pip install torch==2.13.0 && pip install ".[rl]"'),
    (["stable_baselines3"], ["evaluate", "--env", "fir_gym/Orbit-v0", "--kind", "lqg"],
     'pip install ".[rl]"'),
    (["dask", "distributed"], ["reproduce", "--backend", "dask", "--quick"],
     'pip install ".[cluster]"'),
    (["imageio"], ["watch", "--env", "fir_gym/Orbit-v0", "--estimator", "ekf", "--out",
                   "x.gif"], 'pip install ".[video]"'),
    (["jax", "gymnax", "rejax"], ["benchmark-controllers", "--backend", "jax", "--quick",
                                  "--out", "RUN"], 'pip install ".[jax]"'),
])
def test_a_missing_extra_names_the_pip_install_that_fixes_it(tmp_path, blocked, argv, install):
    argv = [str(tmp_path / a) if a in ("RUN", "x.gif") else a for a in argv]
    result = run_blocked(blocked, argv)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert install in lines[0]
    assert not list(tmp_path.iterdir())                    # nothing was run or written


def test_debug_shows_the_traceback_as_well(tmp_path):
    result = run_blocked(["imageio"], ["watch", "--env", "fir_gym/Orbit-v0", "--estimator",
                                       "ekf", "--out", str(tmp_path / "x.gif"), "--debug"])
    assert result.returncode == 2
    assert "Traceback" in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("fir-gym watch: error:")


def test_evaluate_on_a_folder_that_is_not_a_run(tmp_path, capsys):
    one_line(capsys, ["evaluate", "--model", str(tmp_path)], "not a run folder", "run.json")
    one_line(capsys, ["evaluate", "--model", str(tmp_path / "nope")], "does not exist")
    one_line(capsys, ["evaluate"], "give --model")


def test_estimator_kwargs_mistakes(tmp_path, capsys):
    gif = str(tmp_path / "x.gif")
    base = ["watch", "--env", "fir_gym/VanDerPol-v0", "--out", gif]
    line = one_line(capsys, [*base, "--estimator", "ekf", "--estimator-kwargs", '{"x_0": 1}'],
                    "ekf (ExtendedKalmanFilter)", "'x_0'", "did you mean 'x0'")
    for key in ("x0", "P0", "nan_policy", "max_covariance_trace"):
        assert key in line                                  # the accepted keys are listed
    assert "raised from the environment creator" not in line
    one_line(capsys, [*base, "--estimator", "ekf", "--estimator-kwargs", '{"Q": 0.1}'],
             "'Q'", "nominal=")
    one_line(capsys, [*base, "--estimator", "ekf", "--estimator-kwargs", '{"R": 0.1}'],
             "'R'", "nominal=")
    for name in ("fir", "ufir", "rfir"):
        one_line(capsys, [*base, "--estimator", name], "nonlinear", "'efir'")
    one_line(capsys, [*base, "--estimator", "nope"], "unknown estimator", "ekf")
    assert not Path(gif).exists()


def test_estimator_options_of_train_evaluate_and_compare(tmp_path, capsys):
    """The same message for a kind's estimator options, before any training starts."""
    one_line(capsys, ["train", "--env", "fir_gym/Orbit-v0", "--kind", "ekf", "--kind-kwargs",
                      '{"ekf": {"Q": 1}}', "--out", str(tmp_path / "r")],
             "ekf (ExtendedKalmanFilter)", "'Q'", "nominal")
    one_line(capsys, ["evaluate", "--env", "fir_gym/Orbit-v0", "--kind", "lqg",
                      "--kind-kwargs", '{"lqg": {"estimator": "ukf", "alpah": 1}}'],
             "UnscentedKalmanFilter", "did you mean 'alpha'")
    one_line(capsys, ["compare-controllers", "--env", "fir_gym/Orbit-v0", "--observations",
                      "efir", "--kind-kwargs", '{"efir": {"horizn": 5}}', "--out",
                      str(tmp_path / "c")], "efir (ExtendedFIRFilter)", "'horizon'")
    assert not list(tmp_path.iterdir())


def test_parse_mistakes_are_one_line(capsys):
    one_line(capsys, ["nonsense"], "invalid choice")
    one_line(capsys, ["reproduce", "--paper", "007"], "--paper", "000,001")
    one_line(capsys, ["train", "--env", "fir_gym/Orbit-v0"], "--out")
    one_line(capsys, ["watch", "--estimator-kwargs", "{bad", "--out", "x.gif"], "JSON")
    one_line(capsys, ["speed", "nonsense"], "invalid choice")


def test_an_unknown_env_id_is_one_line(tmp_path, capsys):
    one_line(capsys, ["watch", "--env", "fir_gym/Nope-v0", "--estimator", "ekf",
                      "--out", str(tmp_path / "x.gif")], "Nope")


def _subcommands():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return parser, sub.choices


def test_every_option_has_help_and_shows_its_default():
    parser, choices = _subcommands()
    for name, p in [("fir-gym", parser), *choices.items()]:
        if name in ("speed", "bench"):
            from fir_gym.benchmarks import speed_parser

            p = speed_parser()
        formatter = p._get_formatter()
        for action in p._actions:
            if not action.option_strings or action.dest in ("help", "version"):
                continue
            assert action.help, f"{name} {action.option_strings[0]} has no help"
            text = formatter._get_help_string(action) or ""
            if action.nargs != 0:                           # not a flag
                assert "default" in text or action.required, (name, action.option_strings)
                if action.required:
                    assert "required" in text, (name, action.option_strings)


HEAVY = ("torch", "numba", "mujoco", "stable_baselines3", "sb3_contrib", "scipy", "dask",
         "fir_gym.estimators", "fir_gym.envs", "fir_gym.training")


@pytest.mark.parametrize("argv", [[], ["list"], ["reproduce"], ["train"], ["evaluate"],
                                  ["compare-controllers"], ["benchmark-controllers"],
                                  ["watch"], ["speed"], ["bench"], ["bench", "kalman"]])
def test_help_imports_nothing_heavy(argv):
    """``--help`` is instant because it imports none of the heavy packages (the test
    looks at sys.modules after it, not at a clock)."""
    code = ("import sys, contextlib, io, json\n"
            "from fir_gym.cli import main\n"
            "code = None\n"
            "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
            "    try:\n"
            f"        main({[*argv, '--help']!r})\n"
            "    except SystemExit as e:\n"
            "        code = e.code\n"
            f"heavy = [m for m in {HEAVY!r} if m in sys.modules]\n"
            "print(json.dumps([code, heavy, out.getvalue()]))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            cwd="/", timeout=120)
    assert result.returncode == 0, result.stderr
    code, heavy, text = json.loads(result.stdout)
    assert code in (0, None)
    assert heavy == []                                      # no heavy module was imported
    assert "usage: fir-gym" in text and len(text) > 200     # a real help text was printed


def test_bench_is_the_old_name_of_speed(monkeypatch):
    import fir_gym.benchmarks.speed as speed

    seen = []
    monkeypatch.setattr(speed, "main", lambda argv: seen.append(argv) or 0)
    assert main(["bench", "kalman", "--quick"]) == 0
    assert seen == [["kalman", "--quick"]]
    with pytest.raises(SystemExit) as exc:
        main(["bench", "kalman", "--help"])
    assert exc.value.code == 0


INTERNAL = re.compile(r"\bissues? ?#?\d+|issue's|acceptance criterion|criterion ratio|"
                      r"the project's", re.IGNORECASE)


def test_no_internal_wording_in_the_package():
    """Output, docstrings and comments of the installed package name no issue of the
    tracker and no acceptance criterion (users never saw them)."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if INTERNAL.search(line):
                found.append(f"{path.relative_to(PACKAGE)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)


def test_watch_lqg_policy_is_listed_in_help(capsys):
    with pytest.raises(SystemExit):
        main(["watch", "--help"])
    assert "zero|lqg|RUN" in capsys.readouterr().out


def test_json_of_speed_is_untouched_by_the_cli_parser(tmp_path, monkeypatch):
    import fir_gym.benchmarks.speed as speed

    monkeypatch.setitem(speed.RUNNERS, "fir", (lambda quick: {"x": 1}, lambda res: None))
    monkeypatch.setattr(speed, "targets", lambda results: [])
    out = tmp_path / "s.json"
    assert main(["speed", "fir", "--quick", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["fir"] == {"x": 1}


def test_benchmark_options_of_the_other_backend_are_refused_in_one_line(capsys, tmp_path):
    one_line(capsys, ["benchmark-controllers", "--compare-with", str(tmp_path), "--out",
                      str(tmp_path / "b")], "--compare-with", "--backend jax")
    assert not (tmp_path / "b").exists()


def test_benchmark_kinds_are_checked_before_any_work(capsys, tmp_path):
    one_line(capsys, ["benchmark-controllers", "--kinds", "recurent", "--out",
                      str(tmp_path / "b")], "kinds must be among", "recurent")
    one_line(capsys, ["benchmark-controllers", "--kinds", "kf", "--plants",
                      "fir_gym/Orbit-v0", "--out", str(tmp_path / "b")], "kf", "no row")
    assert not (tmp_path / "b").exists()
