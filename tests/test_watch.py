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
                 "--seed", "4", "--every", "1", "--out", str(out)]) == 0
    assert "21 frames" in capsys.readouterr().out
    frames = imageio.mimread(out)
    assert len(frames) == 21                                     # reset + 20 steps
    expected = expected_frames("fir_gym/Orbit-v0", "ekf", 4, 20, 1)
    for got, want in zip(frames, expected, strict=True):
        # a GIF holds a palette of 256 colours: these frames have fewer, so it is exact
        # (each frame after the first stored as the rectangle that changed, read back whole)
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


@pytest.fixture
def runs(tiny_runs):
    """The session's two tiny trained runs (tests/conftest.py)."""
    return tiny_runs


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


def test_watch_a_recurrent_run_carries_its_lstm_state(tmp_path):
    """A RecurrentPPO run (the ``recurrent`` kind): watch loads it as RecurrentPPO and
    carries the LSTM state through the episode, so its return is the evaluation's (which
    plays it with its state) — a policy reset at every step would return another."""
    pytest.importorskip("sb3_contrib")
    from fir_gym.training import RunConfig, evaluate, train
    from fir_gym.video import watch

    config = RunConfig(env_id="fir_gym/CarrierMotion-v0", observation_kind="recurrent",
                       steps=256, seed=0, n_envs=1, env_kwargs={"max_episode_steps": 30})
    run = train(config, tmp_path / "recurrent")
    rec = watch(None, tmp_path / "x.gif", policy=run, seed=3, every=30)
    reference = evaluate(run, episodes=1, seed=3).returns[0]
    assert rec.episode_return == pytest.approx(reference, abs=5e-7)   # SB3's Monitor rounds


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
                            "--out", str(tmp_path / "x.mp4")], 'pip install ".[video]"')
    monkeypatch.setitem(sys.modules, "imageio", None)
    one_line_error(capsys, ["watch", "--env", "fir_gym/Orbit-v0", "--estimator", "ekf",
                            "--out", str(tmp_path / "x.gif")], 'pip install ".[video]"')


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


# ---------------------------------------------------------------------- frames drawn by default
def test_the_default_every_plays_in_real_time_within_20_seconds():
    """The rule of watch's docstring and --help: the steps of one frame in real time,
    round(1 / (fps dt)), raised to the fewest that keep 1 + ceil(steps / every) frames
    within 20 s at fps."""
    from fir_gym.video import CLIP_SECONDS, default_every

    assert default_every(50, 0.001, 5000) == 20          # PendulumSlider-v0, GIF: real time
    assert default_every(100, 0.001, 5000) == 10         # its MP4 at render_fps
    assert default_every(50, 0.01, 1000) == 2            # Orbit-v0
    assert default_every(10, 0.1, 100) == 1              # VanDerPol-v0
    assert default_every(10, 0.1, 1000) == 6             # CarrierMotion-v0: 100 s, sped up
    assert default_every(30, None, None) == 1
    rng = np.random.default_rng(0)
    for _ in range(500):
        fps, dt = rng.uniform(1, 120), 10 ** rng.uniform(-4, 0)
        steps = int(rng.integers(1, 20_000))
        every = default_every(fps, dt, steps)
        real_time = max(1, round(1 / (fps * dt)))
        def seconds(e, steps=steps, fps=fps):
            return (1 + -(-steps // e)) / fps           # 1 + ceil(steps / e) frames at fps

        assert every >= real_time and seconds(every) <= CLIP_SECONDS
        assert every == real_time or seconds(every - 1) > CLIP_SECONDS   # the fewest


@pytest.mark.parametrize(("suffix", "fps", "every"), [(".gif", 50, 20), (".mp4", 100, 10)])
def test_watch_draws_the_pendulum_in_real_time_by_default(tmp_path, suffix, fps, every):
    """PendulumSlider-v0 steps 1 ms and renders at 100 fps; a GIF plays at most 50 fps
    (browsers play shorter delays as 100 ms). A frame every 1/fps s of the plant's time."""
    from fir_gym.video import watch

    rec = watch("fir_gym/PendulumSlider-v0", tmp_path / f"p{suffix}", estimator="ukf",
                steps=100, progress=False)
    assert (rec.fps, rec.every, rec.frames) == (fps, every, 1 + 100 // every)
    assert rec.seconds == pytest.approx(rec.frames / fps)
    if suffix == ".gif":
        from PIL import Image

        with Image.open(rec.path) as gif:
            delays = []
            for i in range(gif.n_frames):
                gif.seek(i)
                delays.append(gif.info["duration"])
        assert delays == [20] * rec.frames


def test_gif_delays_are_whole_centiseconds_that_keep_time(tmp_path):
    """At 30 fps, frame k starts at k/30 s to the nearest centisecond: 30, 40, 30, 30, ..."""
    from PIL import Image

    from fir_gym._gif import GifStream

    frame = np.zeros((20, 30, 3), dtype=np.uint8)
    with GifStream(tmp_path / "t.gif", 30) as gif:
        for k in range(31):
            frame[k % 20, k % 30] = (k * 8, 255 - k * 8, 7)
            gif.append(frame)
    with Image.open(tmp_path / "t.gif") as im:
        delays = []
        for i in range(im.n_frames):
            im.seek(i)
            delays.append(im.info["duration"])
    assert len(delays) == 31 and set(delays) == {30, 40}
    starts = np.cumsum([0, *delays[:-1]])
    assert np.all(np.abs(starts - 1000 * np.arange(31) / 30) <= 5)


def test_watch_holds_one_frame_not_the_episode(tmp_path):
    """The frames go to the file as they are drawn: the peak of memory (numpy's and
    Python's, traced) does not grow with the number of frames. imageio's GIF writer held
    every frame: 250 more Orbit-v0 frames are 90 MB."""
    import tracemalloc

    from fir_gym.video import watch

    run = lambda n: watch("fir_gym/Orbit-v0", tmp_path / "o.gif", estimator="ekf",  # noqa: E731
                          steps=n, every=1, progress=False)
    run(5)                                                    # imports, caches
    frame_bytes = 300 * 400 * 3
    tracemalloc.start()
    try:
        peaks = []
        for n in (50, 300):
            tracemalloc.reset_peak()
            assert run(n).frames == n + 1
            peaks.append(tracemalloc.get_traced_memory()[1])
    finally:
        tracemalloc.stop()
    assert peaks[1] - peaks[0] < 10 * frame_bytes, peaks


def test_watch_shows_a_progress_bar_of_the_steps_unless_told_not_to(tmp_path, monkeypatch):
    """A tqdm bar of the episode's steps (checked through a stand-in for tqdm, not the
    terminal); none with progress=False."""
    tqdm_auto = pytest.importorskip("tqdm.auto")
    from fir_gym.video import watch

    bars = []

    class Bar:
        def __init__(self, total=None, **kwargs):
            self.total, self.n, self.closed = total, 0, False
            bars.append(self)

        def update(self, n=1):
            self.n += n

        def close(self):
            self.closed = True

    monkeypatch.setattr(tqdm_auto, "tqdm", Bar)
    watch("fir_gym/VanDerPol-v0", tmp_path / "v.gif", estimator="bpf-kf", steps=12)
    assert [(b.total, b.n, b.closed) for b in bars] == [(12, 12, True)]
    watch("fir_gym/VanDerPol-v0", tmp_path / "v.gif", estimator="bpf-kf", steps=12,
          progress=False)
    assert len(bars) == 1


def test_watch_help_states_the_default_and_what_a_clip_costs(capsys):
    with pytest.raises(SystemExit):
        main(["watch", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for needle in ("real time", "20 s", "--no-progress", "takes about", "inset"):
        assert needle in text, needle
