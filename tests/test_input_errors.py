"""Bad input from Python gets a clear error: an exception that names the field or argument, the
value given and what is allowed (no library's raw error, no pydantic documentation link)."""

import gymnasium as gym
import numpy as np
import pytest

import lawn_env
from agents import make_policy
from lawn_env import ConfigError, MixedFleetEnv, ScenarioConfig, UnknownConfigKeyError
from lawn_env.config import ChannelConfig, ControlConfig
from lawn_env.spaces import SHOWN_BAD_ENTRIES, check_action


def _message(call) -> tuple[BaseException, str]:
    with pytest.raises(ValueError) as err:
        call()
    return err.value, str(err.value)


# ---------------------------------------------------------------------- 1. config values
@pytest.mark.parametrize("call, needles", [
    (lambda: gym.make("lawn/Joint-v1", num_agvs=0),
     ["num_agvs=0", "greater than or equal to 1", "allowed: an integer in [1, 256]"]),
    (lambda: ScenarioConfig(num_agvs="x"), ["num_agvs='x'", "valid integer", "allowed: an integer in [1, 256]"]),
    (lambda: ScenarioConfig(channel={"blocklength": -1}), ["channel.blocklength=-1", "allowed: an integer >= 1"]),
    (lambda: ScenarioConfig().override({"channel.bler": 0.7}), ["channel.bler=0.7", "allowed: a number in (0, 0.5)"]),
    (lambda: ScenarioConfig(reference={"path_set": "x"}), ["reference.path_set='x'", "'auto', 'paper' or 'random'"]),
    (lambda: ScenarioConfig(reference={"envelope_fraction": 2}),
     ["reference.envelope_fraction=2", "allowed: a number in (0, 1] or None"]),
    (lambda: ScenarioConfig(control={"q1_diag": (1, 2)}),
     ["control.q1_diag=(1, 2)", "has 2 entries", "allowed: a sequence of 6 numbers"]),
    (lambda: ScenarioConfig(channel={"infinite_blocklength": "maybe"}),
     ["channel.infinite_blocklength='maybe'", "allowed: true or false"]),
    (lambda: ScenarioConfig(power_budget_dbw=float("inf")),
     ["power_budget_dbw=inf", "finite", "allowed: a number in [-100, 60]"]),
    (lambda: ChannelConfig(blocklength=0), ["channel.blocklength=0", "allowed: an integer >= 1"]),
    (lambda: ScenarioConfig(area_m=(10, 0, 0, 10)), ["area_m=(10.0, 0.0, 0.0, 10.0)", "need x_min < x_max"]),
    (lambda: ControlConfig(q2_diag=(1.0, 0.0)), ["control.q2_diag=(1.0, 0.0)", "[1e-6, 1e6]"]),
    (lambda: gym.make("lawn/Joint-v1", interface={"cost_clip": -1}),
     ["interface.cost_clip=-1", "allowed: a number > 0"]),
    (lambda: make_policy("ao-mpc", max_iterations=0), ["AOSettings", "max_iterations=0", "allowed: an integer >= 1"]),
])
def test_bad_config_values_raise_a_config_error_naming_field_value_and_allowed(call, needles):
    exc, text = _message(call)
    assert isinstance(exc, ConfigError) and isinstance(exc, ValueError), type(exc)
    assert all(n in text for n in needles), text
    # one readable line, none of pydantic's text around it
    assert "\n" not in text and "pydantic" not in text and "errors.pydantic.dev" not in text
    assert "type=" not in text and "input_value" not in text, text


def test_every_bad_field_is_named_once_with_its_dotted_path():
    exc, text = _message(lambda: ScenarioConfig(num_agvs=0, channel={"blocklength": -1, "bler": 0.7}))
    assert set(exc.fields) == {"num_agvs", "channel.blocklength", "channel.bler"}
    assert text.startswith("invalid ScenarioConfig: ") and text.count("; ") == 2, text
    for needle in ("num_agvs=0", "channel.blocklength=-1", "channel.bler=0.7"):
        assert text.count(needle) == 1, text
    # a tuple with several missing entries is one problem of its field, not one per entry
    exc, text = _message(lambda: ScenarioConfig(control={"q1_diag": (1,)}))
    assert exc.fields == ("control.q1_diag",) and text.count("control.q1_diag") == 1, text


def test_unknown_keys_of_a_direct_constructor_are_unknown_config_key_errors():
    """ScenarioConfig(foo=1) and a nested unknown key name the key and the valid keys there, and stay
    both a TypeError (an unexpected keyword) and a ValueError."""
    with pytest.raises(UnknownConfigKeyError) as err:
        ScenarioConfig(channel={"blocklenght": 3})
    text = str(err.value)
    assert isinstance(err.value, TypeError) and isinstance(err.value, ConfigError)
    assert "unknown config key 'channel.blocklenght'" in text and "channel.blocklength" in text, text
    assert err.value.fields == ("channel.blocklenght",)
    with pytest.raises(TypeError, match="unknown config key 'foo'.*valid config keys: num_agvs"):
        ScenarioConfig(foo=1)
    with pytest.raises(TypeError, match="unknown setting 'bogus'.*valid settings: drone_spacing_m.*psi_points"):
        make_policy("rg-mpc", bogus=1)


def test_valid_configs_still_build_and_the_signature_is_kept():
    import inspect

    cfg = ScenarioConfig(num_agvs=3, channel={"blocklength": 256})
    assert cfg.num_agvs == 3 and cfg.channel.blocklength == 256
    assert list(inspect.signature(ScenarioConfig).parameters)[:2] == ["num_agvs", "num_slots"]


def test_the_cli_prints_the_config_error_on_one_line(tmp_path, capsys):
    from lawn_cli import main

    assert main(["demo", "--out", str(tmp_path), "--set", "num_agvs=0", "--set", "channel.bler=0.7"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "errors.pydantic.dev" not in err, err
    assert "num_agvs=0" in err and "allowed: an integer in [1, 256]" in err and "channel.bler=0.7" in err, err


# ---------------------------------------------------------------------- 2, 3. observation shapes
def test_planners_and_anchors_reject_another_observation_shape_alike():
    for name in ("rg-mpc", "heuristic", "anchor:hover", "anchor:stake"):
        policy = make_policy(name)
        policy.reset(seed=0)
        with pytest.raises(ValueError, match=r"^observation has shape \(10,\); expected \(335,\)$"):
            policy.act(np.zeros(10, np.float32))


def test_learned_policies_check_the_observation_shape_like_the_planners():
    pytest.importorskip("stable_baselines3")
    for name in ("zoo:bc-joint", "zoo:ppo-marl", "zoo:fleet-joint"):
        policy = make_policy(name)
        policy.reset(seed=0)
        with pytest.raises(ValueError, match=r"^observation has shape \(10,\); expected \(335,\)$"):
            policy.act(np.zeros(10, np.float32))
    # an observation of another fleet size says which K the agent was trained at
    env = gym.make("lawn/Joint-v1", num_agvs=3)
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match=r"^observation has shape \(252,\); expected \(335,\): zoo:bc-joint was built "
                                         r"for K = 4 and this observation is of K = 3"):
        make_policy("zoo:bc-joint").act(obs)


def test_a_fleet_agent_acts_at_the_env_k_given_its_config_and_says_how_otherwise():
    """zoo:ppo-marl-fleet-k16 (trained at K = 16) on lawn/Joint-v1 (K = 4): with the env's config (or
    none: the default scenario) it acts there; built on its training scenario it raises naming K = 16
    and the keyword to pass."""
    pytest.importorskip("stable_baselines3")
    from agents import trained_config

    env = gym.make("lawn/Joint-v1")
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError) as err:
        make_policy("zoo:ppo-marl-fleet-k16", trained_config("zoo:ppo-marl-fleet-k16")).act(obs)
    text = str(err.value)
    assert text.startswith("observation has shape (335,); expected (1331,): "), text
    assert "built for K = 16" in text and "this observation is of K = 4" in text, text
    assert "make_policy('zoo:ppo-marl-fleet-k16', config=env.unwrapped.config)" in text, text
    policy = make_policy("zoo:ppo-marl-fleet-k16", config=env.unwrapped.config)
    policy.reset(seed=0)
    for _ in range(3):
        action = policy.act(obs)
        assert env.action_space.contains(action)
        obs, *_ = env.step(action)


# ---------------------------------------------------------------------- 4. MixedFleetEnv's arguments
@pytest.mark.parametrize("kwargs, needles", [
    (dict(fleet_sizes=["a"]), ["fleet_sizes=['a']", "the entry 'a' is not allowed", "integers in [1, 64]"]),
    (dict(fleet_sizes=[]), ["fleet_sizes=[] is empty", "integers in [1, 64]"]),
    (dict(fleet_sizes="34"), ["fleet_sizes='34'", "integers in [1, 64]"]),
    (dict(fleet_sizes=5), ["fleet_sizes=5", "integers in [1, 64]"]),
    (dict(fleet_sizes=[3, 4.0, True, 0, 65]), ["the entries [4.0, True, 0, 65] are not allowed"]),
    (dict(fleet_sizes=np.array([3, 65])), ["fleet_sizes=[3, 65]", "the entry 65"]),
    (dict(fleet_sizes=[3], num_agvs=5), ["num_agvs=5", "fleet_sizes=[...]"]),
    (dict(env_id="lawn/Parallel-v0"), ["env_id='lawn/Parallel-v0'", "'lawn/Joint-v1', 'lawn/Comm-v1'"]),
    (dict(fleet_sizes=[3], channel={"blocklength": 0}), ["channel.blocklength=0", "allowed: an integer >= 1"]),
])
def test_mixed_fleet_env_validates_its_arguments(kwargs, needles):
    _, text = _message(lambda: MixedFleetEnv(**kwargs))
    assert all(n in text for n in needles), text


def test_mixed_fleet_env_takes_numpy_sizes():
    env = MixedFleetEnv("lawn/Comm-v1", fleet_sizes=np.array([4, 3, 4]))
    assert env.fleet_sizes == (3, 4) and all(type(k) is int for k in env.fleet_sizes)


# ---------------------------------------------------------------------- 5. out-of-range actions
def test_an_action_error_counts_the_bad_entries_and_says_the_list_is_cut():
    env = gym.make("lawn/Joint-v1")
    env.reset(seed=0)
    _, text = _message(lambda: env.step(np.full(14, 2.0, np.float32)))
    assert f"14 action entries are outside [-1, 1] or not finite; the first {SHOWN_BAD_ENTRIES}: entries " \
           f"{list(range(SHOWN_BAD_ENTRIES))}" in text, text
    action = np.zeros(14, np.float32)
    action[[3, 12]] = [np.nan, 1.5]
    _, text = _message(lambda: env.step(action))
    assert "2 action entries are outside [-1, 1] or not finite: entries [3, 12] = [nan, 1.5]" in text, text
    assert "the first" not in text
    action = np.zeros(14, np.float32)
    action[13] = 5
    _, text = _message(lambda: env.step(action))
    assert text.startswith("1 action entry is outside [-1, 1] or not finite: entries [13] = [5.0]"), text


def test_a_batched_action_error_counts_the_bad_entries_across_envs():
    batch = np.zeros((4, 14))
    batch[2, 5] = np.nan
    _, text = _message(lambda: check_action(batch, 14, num_envs=4))
    assert text.startswith("env 2: action entry 5 = nan is outside [-1, 1]"), text
    batch = np.full((4, 14), 3.0)
    _, text = _message(lambda: check_action(batch, 14, num_envs=4))
    assert text.startswith(f"56 action entries (in 4 envs) are outside [-1, 1] or not finite; the first "
                           f"{SHOWN_BAD_ENTRIES}: env 0: action entry 0 = 3.0"), text
    assert text.count("env 0: action entry") == SHOWN_BAD_ENTRIES and "env 1:" not in text, text


def test_config_error_is_exported():
    assert lawn_env.ConfigError is ConfigError and issubclass(UnknownConfigKeyError, ConfigError)


# ---------------------------------------------------------------------- 5. agents trained elsewhere
@pytest.mark.parametrize(("agent", "env_id", "settings", "needle"), [
    ("zoo:dv-comm", "lawn/Comm-v1", {}, "with control.law='delivery-certainty-equivalent' and acts only there; "
                                        "this scenario has control.law='paper'"),
    ("zoo:fleet-joint", "lawn/Joint-v1", {"control.actuator": "buffer"},
     "with control.actuator='hold' and acts only there; this scenario has control.actuator='buffer'"),
    ("zoo:bc-joint", "lawn/Joint-v1", {"control.horizon": 6},
     "with control.horizon=10 and acts only there; this scenario has control.horizon=6"),
    ("zoo:bc-joint", "lawn/Joint-v1", {"num_agvs": 3}, "with num_agvs=4 and acts only there; this scenario has num_agvs=3"),
])
def test_make_policy_compare_and_the_cli_refuse_an_agent_trained_elsewhere_alike(agent, env_id, settings, needle,
                                                                                 tmp_path, capsys):
    """The guard of agents.learned.check_scenario, whatever the entry point: the same message naming the
    setting, the value the agent was trained with and the scenario's; make_policy without a config is
    the default scenario, as for every policy (gym.make(env_id)'s)."""
    pytest.importorskip("stable_baselines3")
    from agents import trained_config
    from evaluation.api import compare
    from lawn_cli import main
    from lawn_env import ScenarioConfig

    config = ScenarioConfig().override(settings) if settings else None
    with pytest.raises(ValueError) as made:
        make_policy(agent, config, env_id=env_id)
    message = str(made.value)
    assert message.startswith(f"{agent} was trained on {env_id} ") and needle in message, message
    with pytest.raises(ValueError) as compared:
        compare([agent], config, seeds=[0], env=env_id)
    assert str(compared.value) == message
    argv = ["evaluate", "--policy", agent, "--env", env_id, "--episodes", "1", "--quiet", "--out",
            str(tmp_path / "r.csv"), *[w for k, v in settings.items() for w in ("--set", f"{k}={v}")]]
    assert main(argv) == 2  # bad input
    assert capsys.readouterr().err.strip() == f"lawn evaluate: error: {message}"
    assert not (tmp_path / "r.csv").exists()
    make_policy(agent, trained_config(agent), env_id=env_id)  # on its own scenario it is made
