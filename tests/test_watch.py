"""``fir-gym watch``: a playable GIF or MP4 of one episode, read back with imageio."""

from __future__ import annotations

import sys

import gymnasium as gym
import numpy as np
import pytest

imageio = pytest.importorskip("imageio.v2")
pytest.importorskip("imageio_ffmpeg")

from fir_gym.cli import main  # noqa: E402


def expected_frames(env_id, estimator, seed, steps, every, **kwargs):
    """The frames ``watch`` should write: the wrapper's renders of the same zero-action run."""
    env = gym.make(env_id, render_mode="rgb_array", estimator=estimator, **kwargs)
    env.reset(seed=seed)
    frames = [env.render()]
    for k in range(1, steps + 1):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        if k % every == 0:
            frames.append(env.render())
    return frames


def mp4_frames(path):
    reader = imageio.get_reader(path)
    try:
        return [np.asarray(f) for f in reader], reader.get_meta_data()
    finally:
        reader.close()


def test_watch_writes_a_playable_gif_of_the_wrappers_frames(tmp_path, capsys):
    out = tmp_path / "orbit.gif"
    assert main(["watch", "--env", "fir_gym/Orbit-v0", "--estimator", "ekf", "--steps", "20",
                 "--seed", "4", "--out", str(out)]) == 0
    assert "21 frames" in capsys.readouterr().out
    frames = imageio.mimread(out)
    assert len(frames) == 21                                     # reset + 20 steps
    expected = expected_frames("fir_gym/Orbit-v0", "ekf", 4, 20, 1)
    for got, want in zip(frames, expected, strict=True):
        # a GIF holds a palette of 256 colours: these frames have fewer, so it is exact
        assert np.array_equal(np.asarray(got)[..., :3], want)


@pytest.mark.parametrize(("env_id", "estimator"), [("fir_gym/CarrierMotion-v0", "kf"),
                                                    ("fir_gym/PendulumSlider-v0", "ukf")])
def test_watch_writes_a_playable_mp4(tmp_path, env_id, estimator):
    out = tmp_path / "episode.mp4"
    assert main(["watch", "--env", env_id, "--estimator", estimator, "--steps", "20",
                 "--every", "5", "--fps", "12", "--out", str(out)]) == 0
    frames, meta = mp4_frames(out)
    expected = expected_frames(env_id, estimator, 0, 20, 5)
    assert len(frames) == len(expected) == 5                     # steps 0, 5, 10, 15, 20
    assert meta["fps"] == 12 and frames[0].shape == expected[0].shape
    for got, want in zip(frames, expected, strict=True):         # H.264 is lossy, not far off
        assert np.mean(np.abs(got.astype(float) - want)) < 4.0


def test_watch_stops_at_the_end_of_the_episode(tmp_path):
    out = tmp_path / "short.gif"
    assert main(["watch", "--env", "fir_gym/VanDerPol-v0", "--estimator", "bpf-kf",
                 "--env-kwargs", '{"max_episode_steps": 6}', "--out", str(out)]) == 0
    assert len(imageio.mimread(out)) == 7


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two tiny trained runs on CarrierMotion-v0: one sees the true state, one a KF's."""
    pytest.importorskip("stable_baselines3")
    from fir_gym.training import RunConfig, train

    root = tmp_path_factory.mktemp("runs")
    out = {}
    for kind in ("true", "kf"):
        config = RunConfig(env_id="fir_gym/CarrierMotion-v0", observation_kind=kind,
                           steps=256, seed=0, n_envs=1, env_kwargs={"max_episode_steps": 30})
        out[kind] = train(config, root / kind)
    return out


@pytest.mark.parametrize(("kind", "estimator"), [("true", ["--estimator", "kf"]),
                                                 ("kf", [])])
def test_watch_a_trained_run_plays_the_episode_its_evaluation_plays(tmp_path, runs, capsys,
                                                                    kind, estimator):
    """The oracle is fir_gym.training.evaluate: on the same seed, the watched episode's
    return is its first episode's (the same policy, normalisation and env)."""
    from fir_gym.training import evaluate

    out = tmp_path / "run.gif"
    assert main(["watch", "--policy", str(runs[kind]), *estimator, "--seed", "7",
                 "--every", "10", "--out", str(out)]) == 0
    printed = float(capsys.readouterr().out.rsplit("return ", 1)[1])
    reference = evaluate(runs[kind], episodes=1, seed=7).returns[0]
    assert printed == float(f"{reference:.4g}")                    # printed to 4 digits
    assert len(imageio.mimread(out)) == 4                          # steps 0, 10, 20, 30


def test_watch_a_run_returns_exactly_its_evaluation_return(runs, tmp_path):
    from fir_gym.training import evaluate
    from fir_gym.video import watch

    rec = watch(None, tmp_path / "x.gif", policy=runs["kf"], seed=3, every=30)
    reference = evaluate(runs["kf"], episodes=1, seed=3).returns[0]
    assert rec.episode_return == pytest.approx(reference, abs=5e-7)   # SB3's Monitor rounds
    assert rec.episode_return != pytest.approx(                       # to 6 decimals
        evaluate(runs["kf"], episodes=1, seed=4).returns[0], abs=1e-3)  # (another seed)
    assert rec.steps == 30 and rec.frames == 2


def one_line_error(capsys, argv, *needles):
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    for needle in needles:
        assert needle in lines[0]


def test_watch_mistakes_print_one_line_and_exit_2(tmp_path, capsys, runs):
    gif = str(tmp_path / "x.gif")
    base = ["watch", "--env", "fir_gym/Orbit-v0"]
    one_line_error(capsys, [*base, "--estimator", "nope", "--out", gif], "unknown estimator")
    one_line_error(capsys, [*base, "--estimator", "ekf", "--out", "x.avi"], ".gif or .mp4")
    one_line_error(capsys, [*base, "--out", gif], "estimator is needed")
    one_line_error(capsys, [*base, "--estimator", "ekf", "--steps", "0", "--out", gif], "steps")
    one_line_error(capsys, [*base, "--estimator", "ekf", "--policy", str(tmp_path),
                            "--out", gif], "run folder")
    one_line_error(capsys, ["watch", "--env", "fir_gym/Nope-v0", "--estimator", "ekf",
                            "--out", gif], "Nope")
    one_line_error(capsys, [*base, "--policy", str(runs["kf"]), "--out", gif],
                   "trained on 'fir_gym/CarrierMotion-v0'")
    one_line_error(capsys, ["watch", "--policy", str(runs["kf"]), "--estimator", "ukf",
                            "--out", gif], "observes 'kf'")
    one_line_error(capsys, ["watch", "--policy", str(runs["true"]), "--out", gif],
                   "estimator is needed")
    assert not (tmp_path / "x.gif").exists()


def test_a_missing_extra_names_the_install_that_fixes_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)       # as if not installed
    one_line_error(capsys, ["watch", "--env", "fir_gym/Orbit-v0", "--estimator", "ekf",
                            "--out", str(tmp_path / "x.mp4")], 'pip install "fir-gym[video]"')
    monkeypatch.setitem(sys.modules, "imageio", None)
    one_line_error(capsys, ["watch", "--env", "fir_gym/Orbit-v0", "--estimator", "ekf",
                            "--out", str(tmp_path / "x.gif")], 'pip install "fir-gym[video]"')


def test_watch_lqg_plays_the_classical_controller_evaluate_plays(tmp_path, capsys):
    """``--policy lqg`` is fir_gym.controllers.LQGController on the estimate drawn; the
    oracle is fir_gym.training.evaluate of the ``lqg`` kind with the same estimator, seed
    and episode length (its Monitor rounds returns to 6 decimals)."""
    pytest.importorskip("stable_baselines3")
    from fir_gym.training import RunConfig, evaluate
    from fir_gym.video import watch

    env_kwargs = {"max_episode_steps": 30}
    rec = watch("fir_gym/CarrierMotion-v0", tmp_path / "lqg.gif", estimator="kf",
                policy="lqg", seed=5, every=10, env_kwargs=env_kwargs)
    config = RunConfig(env_id="fir_gym/CarrierMotion-v0", observation_kind="lqg",
                       kind_kwargs={"estimator": "kf"}, env_kwargs=env_kwargs)
    reference = evaluate(config, episodes=1, seed=5).returns[0]
    assert rec.episode_return == pytest.approx(reference, abs=5e-7)
    assert rec.steps == 30 and rec.frames == 4 and len(imageio.mimread(rec.path)) == 4
    zero = watch("fir_gym/CarrierMotion-v0", tmp_path / "zero.gif", estimator="kf",
                 policy="zero", seed=5, every=30, env_kwargs=env_kwargs)
    assert zero.episode_return != pytest.approx(rec.episode_return, abs=1e-3)  # it acts
    assert main(["watch", "--env", "fir_gym/CarrierMotion-v0", "--estimator", "kf",
                 "--policy", "lqg", "--steps", "3", "--out", str(tmp_path / "c.gif")]) == 0
    assert "4 frames" in capsys.readouterr().out
