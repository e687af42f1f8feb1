"""A run folder of ``fir-gym train --backend jax`` played again: :func:`fir_gym.jax.train.load`,
:func:`fir_gym.jax.benchmark.play_in_numpy_env` and ``fir-gym evaluate --model RUN``.

Tiny runs (two PPO iterations of the shipped 16 x 256 rollout, as tests/jax/test_train.py)
of two seeds on Orbit ``true``, on ``efir`` with an option (``horizon`` 5) and on
``recurrent`` (an LSTM policy whose state the players must carry), on a plant
option (300-step episodes) so that the plant's keywords must travel through the folder too.
The oracle of a loaded run is the run itself in memory: the same policies, bit for bit, and
so the same returns on the same numpy episodes, exactly.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("gymnax")
pytest.importorskip("rejax")
pytest.importorskip("yaml")

import jax
from jax_runs import ORBIT, TINY

from fir_gym.jax import train as jt
from fir_gym.jax.benchmark import play_in_numpy_env

#: a plant option the run must keep: shorter episodes (also quicker to play)
PLANT = {"max_episode_steps": 300}
#: (kind, its options)
KINDS = {"true": {}, "efir": {"horizon": 5}, "recurrent": {}}
#: a kind only the single-env oracle of play_in_numpy_env trains too (its window of 4)
STACK = {"measurement-stack": {"horizon": 4}}


@pytest.fixture(scope="module")
def cache(jax_cache: Path) -> Path:
    return jax_cache


@pytest.fixture(scope="module")
def runs(cache: Path, tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A kind's tiny two-seed run in memory and its saved folder, each trained once."""
    done: dict[str, tuple[jt.JaxTraining, Path]] = {}

    def get(kind: str) -> tuple[jt.JaxTraining, Path]:
        if kind not in done:
            result = jt.train(ORBIT, kind, [0, 1], env_kwargs=PLANT,
                              kind_kwargs={**KINDS, **STACK}[kind],
                              cache=cache, **TINY)
            done[kind] = result, jt.save(result, tmp_path_factory.mktemp(f"run-{kind}"))
        return done[kind]

    return get


@pytest.fixture(scope="module", params=list(KINDS))
def run(request: pytest.FixtureRequest, runs: Any) -> tuple[jt.JaxTraining, Path]:
    return runs(request.param)


@pytest.fixture(scope="module")
def true_run(runs: Any) -> tuple[jt.JaxTraining, Path]:
    """The ``true`` kind's run: where one kind is enough."""
    return runs("true")


@pytest.fixture(scope="module")
def played(run: tuple[jt.JaxTraining, Path]) -> list[list[float]]:
    """The in-memory run's policies played in the numpy env: 2 episodes from seed 10 000."""
    return play_in_numpy_env(run[0], 2)


def played_one_episode_at_a_time(result: jt.JaxTraining, episodes: int, seed: int
                                 ) -> list[list[float]]:
    """The oracle of ``play_in_numpy_env``: every seed's policy in one single env
    (``make_single_env``, as ``fir-gym evaluate`` and the SB3 benchmark build it), one
    observation per call, episode ``i`` from ``reset(seed=seed + i)``."""
    from fir_gym.jax.policy import JaxPolicy
    from fir_gym.training.vec_env import make_single_env

    plant, options = dict(result.env_kwargs), dict(result.kind_kwargs)
    env = (make_single_env(ORBIT, observation="true", **plant) if result.kind == "true"
           else make_single_env(ORBIT, **plant) if result.kind == "recurrent"
           else make_single_env(ORBIT, observation="measurement-stack",
                                stack_horizon=options["horizon"], **plant)
           if result.kind == "measurement-stack"
           else make_single_env(ORBIT, estimator=result.kind, estimator_kwargs=options, **plant))
    out = []
    for policy in JaxPolicy.every_seed(result):
        returns = []
        for episode in range(episodes):
            obs, _ = env.reset(seed=seed + episode)
            total, done, act = 0.0, False, policy.episode()
            while not done:
                obs, reward, terminated, truncated, _ = env.step(act(obs))
                total, done = total + float(reward), terminated or truncated
            returns.append(total)
        out.append(returns)
    env.close()
    return out


@pytest.mark.parametrize("kind", [*KINDS, *STACK])
def test_the_numpy_env_returns_are_the_episodes_played_one_at_a_time(runs: Any,
                                                                     kind: str) -> None:
    """``play_in_numpy_env`` plays a seed's episodes side by side, one single env each, the
    policy acting on their batch row by row: the returns equal, bit for bit, the oracle's
    one env and one observation per call — the LSTM's state carried per episode, the
    window's option and the estimator's passed on, the envs reused from seed to seed."""
    result, _ = runs(kind)
    assert play_in_numpy_env(result, 3, 10_007) == played_one_episode_at_a_time(
        result, 3, 10_007)


@pytest.mark.parametrize("kind", ["efir", "recurrent"])
def test_rowwise_acts_on_each_row_as_on_that_observation_alone(runs: Any, kind: str) -> None:
    """``JaxPolicy(rowwise=True)``: a batch's actions (and LSTM states) are each row's alone,
    bit for bit, whatever the batch; the batched products' agree to float32's round-off."""
    from fir_gym.jax.policy import JaxPolicy

    result, _ = runs(kind)
    rowwise = JaxPolicy.every_seed(result, rowwise=True)[1]
    batched = JaxPolicy.every_seed(result)[1]
    rng = np.random.default_rng(5)
    obs = rng.normal(size=(7, result.train_state.obs_rms_state.mean.shape[-1]))
    start = np.array([True, False, True, True, False, False, True])
    state = None
    for _ in range(3):              # the state carried over three steps
        actions, new_state = rowwise(obs, start, state)
        alone = [rowwise(obs[i], start[i:i + 1], None if state is None else
                         jax.tree.map(lambda leaf, i=i: leaf[i:i + 1], state))
                 for i in range(len(obs))]
        assert np.array_equal(actions, np.stack([a for a, _ in alone]))
        if result.kind == "recurrent":
            for i, (_, carried) in enumerate(alone):
                for leaf, row in zip(jax.tree.leaves(new_state), jax.tree.leaves(carried),
                                     strict=True):
                    assert np.array_equal(np.asarray(leaf)[i:i + 1], np.asarray(row))
        np.testing.assert_allclose(batched(obs, start, state)[0], actions, rtol=1e-5,
                                   atol=1e-6)
        state, obs, start = new_state, obs + 0.1, np.zeros(7, dtype=bool)


def policy_leaves(result: jt.JaxTraining) -> list[np.ndarray]:
    state = result.train_state
    tree = (state.actor_ts.params, state.critic_ts.params, state.obs_rms_state)
    return [np.asarray(leaf) for leaf in jax.tree.leaves(tree)]


def copy_of(folder: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(folder, tmp_path / "copy"))


def as_before_identity(folder: Path) -> None:
    """Take the ``run`` entry out of the folder's policy files: files as saved before it."""
    from flax import serialization

    for path in folder.glob("seed*/policy.msgpack"):
        raw = serialization.msgpack_restore(path.read_bytes())
        del raw["run"]
        path.write_bytes(serialization.msgpack_serialize(raw))


# ---------------------------------------------------------------------------- save and load
def test_results_json_records_the_plant_and_kind_keywords(run: tuple[jt.JaxTraining, Path]
                                                           ) -> None:
    result, folder = run
    assert result.env_kwargs == PLANT and result.kind_kwargs == KINDS[result.kind]
    data = json.loads((folder / "results.json").read_text())
    assert data["env_kwargs"] == PLANT and data["kind_kwargs"] == KINDS[result.kind]


def test_load_gives_the_saved_policies_bit_for_bit(run: tuple[jt.JaxTraining, Path]) -> None:
    result, folder = run
    loaded = jt.load(folder)
    assert (loaded.env_id, loaded.kind, loaded.seeds) == (ORBIT, result.kind, [0, 1])
    assert loaded.recipe == result.recipe
    assert (loaded.env_kwargs, loaded.kind_kwargs) == (PLANT, KINDS[result.kind])
    assert loaded.final_returns == result.final_returns and loaded.curves == result.curves
    assert loaded.checkpoint_steps == result.checkpoint_steps
    assert loaded.iqm == result.iqm and loaded.steps_trained == result.steps_trained
    mine, saved = policy_leaves(loaded), policy_leaves(result)
    assert len(mine) == len(saved)
    for a, b in zip(mine, saved, strict=True):
        assert a.dtype == b.dtype and a.shape == b.shape      # seeds stacked as train()'s
        np.testing.assert_array_equal(a, b)


def test_a_loaded_run_plays_exactly_as_the_trained_one(run: tuple[jt.JaxTraining, Path],
                                                       played: list[list[float]]) -> None:
    result, folder = run
    assert np.shape(played) == (2, 2) and np.all(np.isfinite(played))
    assert played[0] != played[1]                                  # two policies
    assert play_in_numpy_env(jt.load(folder), 2) == played
    # the benchmark's entry point: the same loop on the plant's keywords the run recorded
    assert result.env_kwargs == PLANT and play_in_numpy_env(result, 2) == played


def test_watch_and_record_play_a_jax_run(run: tuple[jt.JaxTraining, Path],
                                         played: list[list[float]]) -> None:
    """``fir-gym watch`` / ``record --policy RUN`` (their shared loader,
    :mod:`fir_gym.episode_policy`): a JAX folder plays its first seed, ``RUN/seed1`` the
    second, on the env its configuration rebuilds — the same episodes, to the last bit, as
    ``play_in_numpy_env``."""
    from fir_gym.episode_policy import run_config, trained_policy
    from fir_gym.training import make_env

    result, folder = run
    for where, index in ((folder, 0), (folder / "seed1", 1)):
        config = run_config(where, None)
        assert (config.env_id, config.observation_kind, config.seed) == (ORBIT, result.kind,
                                                                         index)
        assert config.env_kwargs == PLANT and config.kind_kwargs == KINDS[result.kind]
        env = make_env(config)
        for episode in range(2):
            act = trained_policy(where, config.algo_name, env)       # one episode's policy
            obs, _ = env.reset(seed=10_000 + episode)
            total, done = 0.0, False
            while not done:
                obs, reward, terminated, truncated, _ = env.step(act(obs))
                total, done = total + float(reward), terminated or truncated
            assert total == played[index][episode]
        env.close()
    with pytest.raises(ValueError, match=r"has seeds \[0, 1\], not 7"):
        run_config(folder / "seed7", None)
    with pytest.raises(ValueError, match="was trained on"):
        run_config(folder, "fir_gym/VanDerPol-v0")


def test_a_folder_without_the_keywords_reads_them_as_empty(run: tuple[jt.JaxTraining, Path],
                                                           tmp_path: Path) -> None:
    """Folders saved before ``env_kwargs`` was recorded (and ``kind_kwargs``, and the
    policies' ``run``) still load."""
    folder = copy_of(run[1], tmp_path)
    as_before_identity(folder)
    data = json.loads((folder / "results.json").read_text())
    del data["env_kwargs"], data["kind_kwargs"]
    (folder / "results.json").write_text(json.dumps(data))
    loaded = jt.load(folder)
    assert loaded.env_kwargs == {} and loaded.kind_kwargs == {}
    for a, b in zip(policy_leaves(loaded), policy_leaves(run[0]), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_folder_from_before_network_dtype_loads_with_float64_networks(
        true_run: tuple[jt.JaxTraining, Path], tmp_path: Path) -> None:
    """A folder saved before ``Recipe.network_dtype`` was recorded was trained with float64
    arithmetic on float32 kernels (flax's default): it loads with float64 networks, each saved
    leaf widened exactly, its training state too (it can still be continued); a float64 leaf
    in a float32 run's policy file is refused, naming it."""
    from flax import serialization

    result, saved = true_run
    folder = copy_of(saved, tmp_path)
    data = json.loads((folder / "results.json").read_text())
    del data["recipe"]["network_dtype"]
    (folder / "results.json").write_text(json.dumps(data))
    for path in folder.glob("seed*/policy.msgpack"):
        raw = serialization.msgpack_restore(path.read_bytes())
        raw["run"]["recipe"] = json.dumps(data["recipe"], sort_keys=True)
        path.write_bytes(serialization.msgpack_serialize(raw))
    loaded = jt.load(folder)
    assert loaded.recipe.network_dtype == "float64" and loaded.resumable
    for a, b in zip(policy_leaves(loaded), policy_leaves(result), strict=True):
        assert a.dtype == np.float64
        np.testing.assert_array_equal(a, b.astype(np.float64))
    assert np.all(np.isfinite(play_in_numpy_env(loaded, 1)))

    spoiled = copy_of(saved, tmp_path / "spoiled")
    path = spoiled / "seed0" / "policy.msgpack"
    raw = serialization.msgpack_restore(path.read_bytes())
    kernel = raw["actor"]["params"]["action_mean"]["kernel"]
    raw["actor"]["params"]["action_mean"]["kernel"] = np.asarray(kernel, dtype=np.float64)
    path.write_bytes(serialization.msgpack_serialize(raw))
    with pytest.raises(ValueError, match=r"action_mean/kernel is float64.* has float32"):
        jt.load(spoiled)


# ---------------------------------------------------------------------------- the CLI
def test_evaluate_plays_every_seed_of_a_jax_folder(run: tuple[jt.JaxTraining, Path],
                                                   played: list[list[float]],
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    import statistics

    from fir_gym.cli import main
    from fir_gym.training.stats import iqm

    result, folder = run
    assert main(["evaluate", "--model", str(folder), "--episodes", "2", "--no-progress"]) == 0
    lines = capsys.readouterr().out.splitlines()
    every = [r for seed in played for r in seed]
    assert lines == [
        *(f"seed {s}: return {statistics.fmean(r):.4g} ± {statistics.pstdev(r):.3g} over 2 "
          "episodes" for s, r in zip(result.seeds, played, strict=True)),
        f"{ORBIT} observing {result.kind}: return {statistics.fmean(every):.4g} ± "
        f"{statistics.pstdev(every):.3g} over 2 episodes x 2 seed(s), IQM over seeds "
        f"{iqm([statistics.fmean(r) for r in played]):.4g}"]


def test_evaluate_seed_moves_the_episodes(runs: Any, capsys: pytest.CaptureFixture[str]
                                          ) -> None:
    """``--seed 10001``: the episodes seeded 10 001, 10 002 — the second of the default
    ones first. On ``efir``: Orbit's truth has no process noise and a fixed initial state, so
    a policy of the ``true`` state plays the same episode whatever the seed; the
    measurements' noise makes an ``efir`` policy's episodes differ."""
    from fir_gym.cli import main

    result, folder = runs("efir")
    played = play_in_numpy_env(result, 2)
    assert all(seed[0] != seed[1] for seed in played)
    later = play_in_numpy_env(jt.load(folder), 2, 10_001)
    assert [seed[0] for seed in later] == [seed[1] for seed in played]
    assert all(seed[1] not in seed_played for seed, seed_played in zip(later, played,
                                                                       strict=True))
    assert main(["evaluate", "--model", str(folder), "--episodes", "1", "--seed", "10001",
                 "--no-progress"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first == f"seed 0: return {later[0][0]:.4g} ± 0 over 1 episodes"


# ---------------------------------------------------------------------------- bad folders
def corrupt(kind: str, folder: Path) -> str:
    """Spoil the copied run folder ``folder`` one way; what the error must say."""
    results = folder / "results.json"
    data = json.loads(results.read_text())
    if kind == "missing seed":
        (folder / "seed1" / "policy.msgpack").unlink()
        return "lacks seed1/policy.msgpack"
    if kind == "another plant":
        data["env_id"] = "fir_gym/VanDerPol-v0"
        data["env_kwargs"] = {}
        results.write_text(json.dumps(data))
        return "is not a policy of .*saved by a run of fir_gym/Orbit-v0 true seed 0"
    if kind == "another recipe":
        data["recipe"]["log_std_init"] = 0.5          # the networks' shapes as they were
        results.write_text(json.dumps(data))
        return "is not a policy of .*differing in recipe"
    if kind == "another recipe, files saved before their run was":
        as_before_identity(folder)
        data["recipe"]["hidden_layer_sizes"] = [32, 32]
        results.write_text(json.dumps(data))
        return (r"is not a policy of .*: actor/params/\S+ is float32\[[\d, ]+\] where the "
                r"run's policy has float32\[[\d, ]+\]")
    if kind == "swapped seeds":
        shutil.copy(folder / "seed0" / "policy.msgpack", folder / "seed1" / "policy.msgpack")
        return "is not a policy of .* seed 0 .*differing in seed"
    if kind == "not msgpack":
        (folder / "seed0" / "policy.msgpack").write_bytes(b"\xc1 not msgpack")
        return "is not a flax-serialised policy"
    if kind == "another backend":
        data["backend"] = "sb3"
        results.write_text(json.dumps(data))
        return "backend is 'sb3'"
    if kind == "a kind not trained":
        data["kind"] = "ufir"                   # CarrierMotion-v0's, not Orbit-v0's
        results.write_text(json.dumps(data))
        return "the jax backend trains"
    raise AssertionError(kind)


SPOILED = ["missing seed", "another plant", "another recipe",
           "another recipe, files saved before their run was", "swapped seeds", "not msgpack",
           "another backend", "a kind not trained"]


@pytest.mark.parametrize("how", SPOILED)
def test_a_spoiled_folder_is_one_line_naming_it(how: str,
                                                true_run: tuple[jt.JaxTraining, Path],
                                                tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    from fir_gym.cli import main

    folder = copy_of(true_run[1], tmp_path)
    says = corrupt(how, folder)
    with pytest.raises(ValueError, match=says) as raised:
        jt.load(folder)
    assert str(folder) in str(raised.value) and "\n" not in str(raised.value)
    assert main(["evaluate", "--model", str(folder), "--episodes", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("fir-gym evaluate: error: ")
    assert re.search(says, err) and str(folder) in err


def test_load_refuses_what_is_not_a_jax_run_folder(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"is not a run folder .* does not exist"):
        jt.load(tmp_path / "nowhere")
    with pytest.raises(ValueError, match=r"is not a run folder .* has no results\.json"):
        jt.load(tmp_path)
    (tmp_path / "results.json").write_text("{")
    with pytest.raises(ValueError, match="is not JSON"):
        jt.load(tmp_path)
    (tmp_path / "results.json").write_text(json.dumps({"backend": "jax", "env_id": ORBIT}))
    with pytest.raises(ValueError, match="lacks kind, seeds, recipe"):
        jt.load(tmp_path)


def test_evaluate_refuses_sb3_only_options_on_a_jax_folder(
        true_run: tuple[jt.JaxTraining, Path], capsys: pytest.CaptureFixture[str]) -> None:
    from fir_gym.cli import main

    assert main(["evaluate", "--model", str(true_run[1]), "--best"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--backend jax" in err and "--best" in err


def test_evaluate_without_the_jax_extra_says_which_in_one_line(tmp_path: Path) -> None:
    import subprocess
    import sys

    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "results.json").write_text(json.dumps({"backend": "jax"}))
    code = ("import sys; sys.modules['rejax'] = None\n"
            "from fir_gym.cli import main\n"
            f"sys.exit(main(['evaluate', '--model', {str(tmp_path / 'run')!r}]))\n")
    done = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True,
                          cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and 'pip install ".[jax]"' in done.stderr
    assert "rejax is missing" in done.stderr
