"""fir_gym.jax.train: rejax's PPO on the gymnax Orbit, every seed in one compiled program.

Tiny runs (two PPO iterations of the shipped 16 x 256 rollout) except the oracle, which
trains the ``true`` kind long enough for PPO to beat the zero-action and random policies
by a wide margin. The compilation cache is the test session's (tests/jax/conftest.py).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("gymnax")
pytest.importorskip("rejax")
pytest.importorskip("yaml")

import jax
import jax.numpy as jnp
from jax_runs import ORBIT, TINY

from fir_gym.jax import Orbit
from fir_gym.jax import train as jt


@pytest.fixture(scope="module")
def cache(jax_cache: Path) -> Path:
    return jax_cache


@pytest.fixture(scope="module")
def two_seeds(cache: Path) -> jt.JaxTraining:
    return jt.train(ORBIT, "measurement", [0, 1], cache=cache, **TINY)


def params_of(result: jt.JaxTraining, index: int) -> list[np.ndarray]:
    state = result.train_state
    tree = (state.actor_ts.params, state.critic_ts.params, state.obs_rms_state)
    return [np.asarray(leaf)[index] for leaf in jax.tree.leaves(tree)]


# ---------------------------------------------------------------------------- a tiny run
def test_a_tiny_run_returns_curves_and_final_returns_per_seed(two_seeds: jt.JaxTraining
                                                                ) -> None:
    r = two_seeds
    assert r.seeds == [0, 1] and r.steps_trained == 8192
    assert r.checkpoint_steps == [4096, 8192]
    assert np.shape(r.curves) == (2, 2) and np.shape(r.final_returns) == (2, 2)
    assert np.all(np.isfinite(r.curves)) and np.all(np.isfinite(r.final_returns))
    # the last checkpoint is the end of training: its episodes are the final ones' first
    # (the same evaluation keys), so with as many episodes the numbers agree
    np.testing.assert_array_equal(np.asarray(r.curves)[:, -1],
                                  np.mean(r.final_returns, axis=1))
    assert r.iqm == pytest.approx(float(np.mean(r.per_seed)))   # two seeds: the mean
    assert r.compile_seconds > 0 and r.train_seconds > 0
    data = r.to_dict()
    assert data["backend"] == "jax" and data["unmatched"] == list(jt.UNMATCHED)


def test_the_same_seeds_train_bit_for_bit_the_same(two_seeds: jt.JaxTraining, cache: Path
                                                   ) -> None:
    again = jt.train(ORBIT, "measurement", [0, 1], cache=cache, **TINY)
    assert again.curves == two_seeds.curves
    assert again.final_returns == two_seeds.final_returns
    for i in (0, 1):
        for a, b in zip(params_of(again, i), params_of(two_seeds, i), strict=True):
            np.testing.assert_array_equal(a, b)
    assert two_seeds.final_returns[0] != two_seeds.final_returns[1]   # seeds differ


def test_vmapped_seeds_match_the_same_seed_trained_alone(two_seeds: jt.JaxTraining,
                                                         cache: Path) -> None:
    """Not bit for bit: XLA compiles the seeds' batched matrix products and reductions with
    another summation order than a single seed's, so the float32 network weights differ
    in their last bits (about 1e-8 after two iterations) and the float64 returns in their
    seventh digit. Equal to that rounding, in weights and returns."""
    alone = jt.train(ORBIT, "measurement", [1], cache=cache, **TINY)
    for a, b in zip(params_of(alone, 0), params_of(two_seeds, 1), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(alone.final_returns[0], two_seeds.final_returns[1], rtol=1e-5)
    np.testing.assert_allclose(alone.curves[0], two_seeds.curves[1], rtol=1e-5)


def test_save_writes_a_run_folder(two_seeds: jt.JaxTraining, tmp_path: Path) -> None:
    import json

    from flax import serialization

    out = jt.save(two_seeds, tmp_path / "run")
    data = json.loads((out / "results.json").read_text())
    assert data["per_seed"] == two_seeds.per_seed and data["recipe"]["num_envs"] == 16
    assert (out / "code_version.txt").is_file()
    blob = serialization.msgpack_restore((out / "seed1" / "policy.msgpack").read_bytes())
    saved = jax.tree.leaves(blob["actor"])
    actor = jax.tree.leaves(two_seeds.train_state.actor_ts.params)
    for a, b in zip(saved, actor, strict=True):
        np.testing.assert_array_equal(a, np.asarray(b)[1])


# ---------------------------------------------------------------------------- continuing
def whole_state(result: jt.JaxTraining) -> list[np.ndarray]:
    return [np.asarray(leaf) for leaf in jax.tree.leaves(result.train_state)]


@pytest.mark.parametrize("kind", ["measurement", "recurrent"])
def test_a_continued_run_is_the_run_trained_straight_bit_for_bit(kind: str, cache: Path,
                                                                 tmp_path: Path) -> None:
    """Two iterations, saved, loaded and continued to four equal four iterations straight:
    every leaf of the training state (weights, Adam's moments, statistics, envs, keys), the
    curves and the final returns — for the feed-forward and the recurrent PPO."""
    settings = {k: v for k, v in TINY.items() if k != "steps"}
    straight = jt.train(ORBIT, kind, [0, 1], cache=cache, **{**settings, "checkpoints": 4},
                        steps=16384)
    first = jt.train(ORBIT, kind, [0, 1], cache=cache, **TINY)
    loaded = jt.load(jt.save(first, tmp_path / "run"))
    assert loaded.resumable and (tmp_path / "run" / jt.STATE_FILE).is_file()
    for a, b in zip(whole_state(loaded), whole_state(first), strict=True):
        np.testing.assert_array_equal(a, b)
    on = jt.continue_training(loaded, 16384, checkpoints=2, cache=cache)
    assert on.steps_trained == straight.steps_trained == 16384
    assert on.checkpoint_steps == straight.checkpoint_steps == [4096, 8192, 12288, 16384]
    mine, theirs = whole_state(on), whole_state(straight)
    assert len(mine) == len(theirs)
    for a, b in zip(mine, theirs, strict=True):
        np.testing.assert_array_equal(a, b)
    assert on.curves == straight.curves and on.final_returns == straight.final_returns
    assert on.settings["checkpoints"] == 4 and on.recipe == straight.recipe


@pytest.mark.parametrize("kind", ["measurement", "recurrent"])
def test_the_program_is_its_iterations_one_call_at_a_time(kind: str, cache: Path) -> None:
    """The one loop of :func:`fir_gym.jax.train.training_program` (the curve's evaluations
    a ``lax.cond`` inside it) against the run driven from Python: five iterations, each
    one call of ``train_iteration``, the curve's episodes evaluated after the second and
    the fourth (two checkpoints every two iterations, then a tail of one), the final ones
    after the fifth — every leaf of the state, the curve and the final returns, bit for
    bit; for the feed-forward and the recurrent PPO, one seed (unbatched) and two
    (vmapped)."""
    settings = {"checkpoints": 2, "curve_episodes": 2, "episodes": 3, "eval_seed": 10_000}
    rec = jt.recipe(ORBIT, steps=5 * 4096, kind=kind)
    assert rec.iterations == 5 and jt._segments(5, 2) == (2, 2, 1)
    env, params = jt.make_env(ORBIT, kind)
    algo = jt.make_algorithm(env, params, rec)
    curve_keys = jax.random.split(jax.random.PRNGKey(10_000), 2)
    final_keys = jax.random.split(jax.random.PRNGKey(10_000), 3)
    program = jax.jit(jt.over_seeds(jt.training_program(algo, rec, **settings)))
    # the oracle's pieces over the seeds as the program's are (unbatched for one seed)
    step = jax.jit(jt.over_seeds(algo.train_iteration))
    play_curve, play_final = (
        jax.jit(jt.over_seeds(lambda ts, keys=keys: jt.evaluate_policy(algo, ts, keys)))
        for keys in (curve_keys, final_keys))
    for seeds in ([3], [0, 1]):
        initial = jt.initial_states(algo, seeds)
        ts, curve, final = program(initial)
        state, points = initial, []
        for i in range(5):
            state = step(state)
            if i in (1, 3):
                points.append(play_curve(state))
        for a, b in zip(jax.tree.leaves(ts), jax.tree.leaves(state), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        np.testing.assert_array_equal(np.asarray(curve), np.stack(points, axis=1))
        np.testing.assert_array_equal(np.asarray(final), np.asarray(play_final(state)))


def test_a_run_without_its_state_is_played_not_continued(two_seeds: jt.JaxTraining,
                                                         tmp_path: Path) -> None:
    out = jt.save(two_seeds, tmp_path / "run")
    (out / jt.STATE_FILE).unlink()                      # a folder of before the state file
    loaded = jt.load(out)
    assert not loaded.resumable
    with pytest.raises(ValueError, match="can be played, not trained further"):
        jt.continue_training(loaded, 16384)
    with pytest.raises(ValueError, match="more than the 8192 steps"):
        jt.continue_training(two_seeds, 8192)
    (out / jt.STATE_FILE).write_bytes(b"\xc1 not msgpack")
    with pytest.raises(ValueError, match="is not this run's training state"):
        jt.load(out)


# ---------------------------------------------------------------------------- the recipe
def test_the_recipe_is_ppo_yml_translated() -> None:
    from fir_gym.training import hyperparams

    entry = hyperparams.hyperparameters("ppo", ORBIT)
    rec = jt.recipe(ORBIT)
    assert rec.steps == entry["n_timesteps"] and rec.num_envs == entry["n_envs"]
    assert rec.num_steps == entry["n_steps"] and rec.num_epochs == entry["n_epochs"]
    assert rec.num_minibatches == entry["n_steps"] * entry["n_envs"] // entry["batch_size"]
    assert rec.rollout // rec.num_minibatches == entry["batch_size"]
    for ours, theirs in (("learning_rate", "learning_rate"), ("gamma", "gamma"),
                         ("gae_lambda", "gae_lambda"), ("clip_eps", "clip_range"),
                         ("ent_coef", "ent_coef")):
        assert getattr(rec, ours) == entry[theirs], ours
    assert rec.log_std_init == entry["policy_kwargs"]["log_std_init"]
    # what the YAML leaves out: stable-baselines3's PPO defaults
    assert (rec.vf_coef, rec.max_grad_norm) == (0.5, 0.5)
    assert rec.hidden_layer_sizes == (64, 64) and rec.activation == "tanh"
    # normalize: true is VecNormalize's defaults
    assert entry["normalize"] is True
    assert rec.normalize_observations and rec.normalize_rewards
    assert (rec.clip_obs, rec.clip_reward) == (10.0, 10.0)
    assert rec.iterations == math.ceil(entry["n_timesteps"] / (entry["n_steps"]
                                                               * entry["n_envs"]))


def test_the_recipe_takes_overrides_and_policy_kwargs_as_sb3_does() -> None:
    rec = jt.recipe(ORBIT, steps=8192, n_envs=8, algo_kwargs={
        "batch_size": 512, "policy_kwargs": "dict(net_arch=dict(pi=[32], vf=[32]), "
                                            "activation_fn=nn.ReLU, log_std_init=-0.5)"})
    assert (rec.num_envs, rec.num_steps, rec.num_minibatches) == (8, 256, 4)
    assert rec.hidden_layer_sizes == (32,) and rec.activation == "relu"
    assert rec.log_std_init == -0.5


def test_the_recurrent_recipe_is_ppo_lstm_yml_translated() -> None:
    from fir_gym.training import hyperparams

    entry = hyperparams.hyperparameters("recurrent-ppo", ORBIT)
    rec = jt.recipe(ORBIT, kind="recurrent")
    assert entry["policy"] == "MlpLstmPolicy"
    assert rec.lstm_hidden_size == entry["policy_kwargs"]["lstm_hidden_size"] == 64
    assert rec.num_epochs == entry["n_epochs"] == 5
    assert rec.num_minibatches == entry["n_steps"] * entry["n_envs"] // entry["batch_size"]
    assert rec.num_envs % rec.num_minibatches == 0              # whole envs per minibatch
    assert rec.log_std_init == entry["policy_kwargs"]["log_std_init"]
    assert jt.recipe(ORBIT).lstm_hidden_size == 0                # every other kind: no LSTM
    assert jt.recipe(ORBIT, kind="recurrent", algo_kwargs={
        "policy_kwargs": {"lstm_hidden_size": 16}}).lstm_hidden_size == 16


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"policy_kwargs": {"shared_lstm": True, "enable_critic_lstm": False}}, "shared_lstm=False"),
    ({"policy_kwargs": {"n_lstm_layers": 2}}, "n_lstm_layers=1"),
    ({"batch_size": 384}, "multiple of n_steps"),         # 6 envs of 256 steps, 4 minibatches
])
def test_the_recurrent_recipe_refuses_another_lstm_arrangement(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        jt.recipe(ORBIT, kind="recurrent", algo_kwargs=kwargs, n_envs=6)
    with pytest.raises(ValueError, match="lstm_hidden_size"):     # not for other kinds
        jt.recipe(ORBIT, algo_kwargs={"policy_kwargs": {"lstm_hidden_size": 8}})


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"use_sde": True}, "does not translate PPO setting"),
    ({"batch_size": 1000}, "divide the rollout"),
    ({"clip_range_vf": 0.2}, "clip_range_vf=None"),
    ({"policy_kwargs": {"net_arch": {"pi": [64], "vf": [32]}}}, "same hidden layers"),
])
def test_the_recipe_refuses_what_it_cannot_translate(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        jt.recipe(ORBIT, algo_kwargs=kwargs)


# ---------------------------------------------------------------------------- the CLI
@pytest.mark.parametrize("argv", [
    ["--env", "fir_gym/VanDerPol-v0", "--kind", "kf"],
    ["--env", ORBIT, "--kind", "fir"],
    ["--env", ORBIT, "--kind", "ekf", "--observation", "estimate+covariance"],
])
def test_the_cli_refuses_what_the_jax_backend_does_not_train(
        argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from fir_gym.cli import main

    assert main(["train", "--backend", "jax", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("fir-gym train: error: the jax backend")
    assert "fir_gym/Orbit-v0" in err
    if "--observation" not in argv:
        assert f"with kind {', '.join(jt.SUPPORTED[ORBIT])}" in err
        assert jt.SUPPORTED[ORBIT][-1] == "recurrent"
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("missing", ["jax", "rejax"])
def test_the_cli_without_the_jax_extra_says_which_in_one_line(missing: str, tmp_path: Path
                                                              ) -> None:
    import subprocess
    import sys

    code = (f"import sys; sys.modules[{missing!r}] = None\n"
            "from fir_gym.cli import main\n"
            f"sys.exit(main(['train', '--backend', 'jax', '--env', {ORBIT!r}, "
            f"'--out', {str(tmp_path / 'run')!r}]))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and 'pip install ".[jax]"' in done.stderr
    assert ("rejax is missing" if missing == "rejax" else "JAX is missing") in done.stderr


def test_the_cli_trains_and_writes_the_run_folder(tmp_path: Path, cache: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from fir_gym.cli import main

    monkeypatch.setenv(jt.CACHE_ENV, str(cache))
    out = tmp_path / "run"
    assert main(["train", "--backend", "jax", "--env", ORBIT, "--kind", "measurement",
                 "--steps", "8192", "--seeds", "2", "--episodes", "2", "--eval-freq", "4096",
                 "--no-progress", "--out", str(out)]) == 0
    assert "over 2 episodes x 2 seed(s)" in capsys.readouterr().out
    assert {p.name for p in out.iterdir()} == {"results.json", "code_version.txt", "seed0",
                                               "seed1", jt.STATE_FILE}
    assert main(["evaluate", "--model", str(out), "--episodes", "2", "--no-progress"]) == 0
    assert "over 2 episodes x 2 seed(s)" in capsys.readouterr().out   # the folder plays
    # --resume: the same call and code reuse the finished run (nothing trained, nothing
    # written); another call on the folder is refused in one line, the folder untouched
    before = (out / "results.json").read_text()
    args = ["train", "--backend", "jax", "--env", ORBIT, "--kind", "measurement", "--steps",
            "8192", "--seeds", "2", "--episodes", "2", "--eval-freq", "4096", "--no-progress",
            "--resume", "--out", str(out)]
    assert main(args) == 0
    assert "reused the finished run" in capsys.readouterr().out
    assert (out / "results.json").read_text() == before
    assert main([*args[:-3], "--seeds", "3", "--resume", "--out", str(out)]) == 2
    assert "holds another run (its seeds differ" in capsys.readouterr().err
    assert (out / "results.json").read_text() == before
    # --resume with more steps continues the run from its saved state; fewer is refused
    assert main([*args[:7], "--steps", "12288", *args[9:]]) == 0
    assert "continued from 8192 steps (--resume)" in capsys.readouterr().out
    data = json.loads((out / "results.json").read_text())
    assert data["steps_trained"] == 12288 and data["checkpoint_steps"][-1] == 12288
    assert main(args) == 2
    assert "its steps (12288 > 8192) differ" in capsys.readouterr().err
    (out / "code_version.txt").write_text("older code\n")    # the same run at other code
    assert jt.finished_run(out, ORBIT, "measurement", [0, 1], steps=12288, episodes=2,
                           checkpoints=2) is None


def test_the_cache_folder_is_overridable(monkeypatch: pytest.MonkeyPatch, tmp_path: Path
                                         ) -> None:
    monkeypatch.setenv(jt.CACHE_ENV, str(tmp_path / "c"))
    assert jt.cache_dir() == tmp_path / "c"
    monkeypatch.delenv(jt.CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert jt.cache_dir() == tmp_path / "x" / "fir-gym" / "jax"


def test_the_compilation_cache_moves_to_another_folder(tmp_path: Path, jax_cache: Path
                                                       ) -> None:
    """JAX opens its cache once; a second folder in the same process still gets the
    programs compiled after it (and the session's cache is put back afterwards)."""
    try:
        for i, name in enumerate(("a", "b")):
            jt.enable_compilation_cache(tmp_path / name)
            jax.jit(lambda x, i=i: x * (i + 7.25) + 1.0)(jnp.ones(3)).block_until_ready()
            assert any((tmp_path / name).iterdir()), name
    finally:
        jt.enable_compilation_cache(jax_cache)


# ---------------------------------------------------------------------------- the oracle
def baseline_return(policy: str, episodes: int = 4) -> float:
    """The mean return of a zero-action or uniformly random policy on Orbit ``true``."""
    env = Orbit("true")
    params = env.default_params

    def episode(key: jax.Array) -> jax.Array:
        obs, state = env.reset(key, params)

        def step(carry: Any, k: jax.Array) -> Any:
            obs, state, total, done = carry
            k_step, k_act = jax.random.split(k)
            action = (jnp.zeros(1) if policy == "zero"
                      else jax.random.uniform(k_act, (1,), minval=-1.0, maxval=1.0))
            obs, state, reward, term, trunc, _ = env.step(k_step, state, action, params)
            return (obs, state, total + jnp.where(done, 0.0, reward), done | term | trunc), None

        keys = jax.random.split(key, params.max_steps_in_episode)
        (_, _, total, _), _ = jax.lax.scan(step, (obs, state, 0.0, False), keys)
        return jnp.asarray(total)

    keys = jax.random.split(jax.random.PRNGKey(7), episodes)
    return float(jnp.mean(jax.jit(jax.vmap(episode))(keys)))


@pytest.mark.slow
def test_ppo_beats_the_zero_action_and_random_policies_on_orbit_true(cache: Path) -> None:
    """An oracle of learning: 14 iterations (57 344 steps) of the shipped recipe take both
    seeds' deterministic return on Orbit ``true`` from about the zero-action policy's
    (-35 000: the orbit leaves the domain and pays the terminal penalty) to less than
    four fifths of it (-17 800 and -11 500 on the machine this was written on). Neither
    backend solves Orbit at this budget (SB3's PPO at 65 536 steps still scores about
    -35 000; the LQG's -512 needs far more), so this checks that PPO learns, not that
    it matches SB3."""
    zero, random = baseline_return("zero"), baseline_return("random")
    assert zero < -30_000 and random < -30_000
    result = jt.train(ORBIT, "true", [0, 1], steps=57_344, checkpoints=1, curve_episodes=1,
                      episodes=2, cache=cache)
    for seed_return in result.per_seed:
        assert seed_return > 0.8 * max(zero, random), (seed_return, zero, random)
