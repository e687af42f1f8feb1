"""Kinds, their one options format, hyperparameter YAML: bad input fails by name, at once."""

import json

import pytest

pytest.importorskip("stable_baselines3")

from fir_gym.training import RunConfig, kind_names, kind_options
from fir_gym.training.hyperparams import hyperparameters, parse_policy_kwargs
from fir_gym.training.kinds import recipe


def test_the_kinds_are_the_plain_ones_every_estimator_and_the_classical_ones():
    names = kind_names()
    for kind in ("true", "measurement", "measurement-stack", "recurrent", "ekf", "ukf", "efir",
                 "lqg", "pid"):
        assert kind in names


def test_kind_options_take_the_nested_form_and_name_what_is_wrong():
    assert kind_options({"efir": {"horizon": 50}}, ["efir", "true"]) == {
        "efir": {"horizon": 50}, "true": {}}
    with pytest.raises(ValueError, match=r"'horizon'.*not among.*efir.*under their kind"):
        kind_options({"horizon": 50}, ["efir"])
    with pytest.raises(ValueError, match=r"'ukf'.*not among"):
        kind_options({"ukf": {}}, ["efir", "ekf"])
    with pytest.raises(ValueError, match="JSON object"):
        kind_options({"efir": 50}, ["efir", "ekf"])


@pytest.mark.parametrize(("kind", "options", "message"), [
    ("efir", {"horizn": 5}, "efir takes no option 'horizn'.*horizon"),
    ("true", {"horizon": 5}, "true takes no option 'horizon'"),
    ("measurement-stack", {"k": 5}, "measurement-stack takes no option 'k'.*horizon"),
    ("lqg", {"estimator": "kalman"}, "lqg: estimator must be"),
    ("lqg", {"alpha": 1e-3}, "lqg \\(ekf\\) takes no option 'alpha'"),
    ("pid", {"gain": 1.0}, "pid takes no option 'gain'.*kp"),
    ("nope", {}, "unknown kind 'nope'; kinds are true, measurement"),
])
def test_bad_kinds_and_options_are_refused(kind, options, message):
    with pytest.raises(ValueError, match=message):
        recipe(kind, options)


def test_run_config_checks_everything_up_front():
    with pytest.raises(ValueError, match="algo"):
        RunConfig(env_id="fir_gym/Orbit-v0", algo="dqn")
    with pytest.raises(ValueError, match="RecurrentPPO"):
        RunConfig(env_id="fir_gym/Orbit-v0", observation_kind="recurrent", algo="sac")
    with pytest.raises(ValueError, match="steps"):
        RunConfig(env_id="fir_gym/Orbit-v0", steps=0)
    config = RunConfig(env_id="fir_gym/Orbit-v0", observation_kind="efir",
                       kind_kwargs={"horizon": 50})
    assert config.env_kwargs_for_sb3()["estimator_kwargs"] == {"horizon": 50}
    assert json.loads(config.to_json())["kind_kwargs"] == {"horizon": 50}


def test_the_shipped_yaml_is_rl_zoo_format_and_fills_the_defaults():
    entry = hyperparameters("ppo", "fir_gym/Orbit-v0")
    assert entry["policy"] == "MlpPolicy" and entry["n_envs"] == 16
    assert entry["policy_kwargs"] == {"log_std_init": -1.0}
    assert hyperparameters("recurrent-ppo", "fir_gym/VanDerPol-v0")["policy"] == "MlpLstmPolicy"
    settings = RunConfig(env_id="fir_gym/Orbit-v0", steps=1000, n_envs=4,
                         algo_kwargs={"learning_rate": 3e-4}).settings()
    assert settings["steps"] == 1000 and settings["n_envs"] == 4
    assert settings["algo_kwargs"]["learning_rate"] == 3e-4
    assert settings["algo_kwargs"]["n_steps"] * 4 >= settings["algo_kwargs"]["batch_size"]


def test_policy_kwargs_strings_are_read_without_eval():
    import torch.nn as nn

    value = parse_policy_kwargs("dict(log_std_init=-2, net_arch=dict(pi=[64], vf=[64]), "
                                "activation_fn=nn.Tanh)")
    assert value == {"log_std_init": -2, "net_arch": {"pi": [64], "vf": [64]},
                     "activation_fn": nn.Tanh}
    for bad in ("__import__('os').system('true')", "dict(a=open('x'))", "[1, 2]"):
        with pytest.raises(ValueError, match="policy_kwargs"):
            parse_policy_kwargs(bad)


def test_the_lqg_kind_takes_the_input_weight_and_checks_it_before_any_job():
    from fir_gym.training.compare import validate
    from fir_gym.training.evaluation import load_controller, make_eval_env

    for estimator in ("ekf", "true"):
        config = RunConfig(env_id="fir_gym/VanDerPol-v0", observation_kind="lqg",
                           kind_kwargs={"estimator": estimator, "input_weight": 0.5})
        controller, _ = load_controller(config, None, make_eval_env(config))
        assert controller.point.M[2, 2] == 0.5
    bad = RunConfig(env_id="fir_gym/VanDerPol-v0", observation_kind="lqg",
                    kind_kwargs={"input_weight": -1})
    with pytest.raises(ValueError, match="lqg: input_weight must be a positive number"):
        validate([bad])
