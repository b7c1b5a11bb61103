import math

import pytest

from lawn_env import ScenarioConfig, presets
from lawn_env.config import ChannelConfig, ControlConfig, DroneConfig


def test_defaults_match_model_md():
    cfg = ScenarioConfig()
    assert cfg.num_agvs == 4 and cfg.num_slots == 120 and cfg.slot_s == 0.5
    assert cfg.area_m == (0.0, 200.0, 0.0, 200.0)
    assert cfg.drone.altitude_m == 50.0 and cfg.drone.start_m == (0.0, 100.0) and cfg.drone.max_speed_mps == 15.0
    ch = cfg.channel
    assert ch.nakagami_m == 2 and ch.blocklength == 1024 and ch.bler == 1e-6 and ch.rate_threshold_bps_hz == 10.0
    assert math.isclose(ch.alpha0, 1e-5) and math.isclose(ch.noise_power_w, 1e-13)
    assert math.isclose(cfg.power_budget_w, 1.0)
    ctl = cfg.control
    assert ctl.horizon == 10 and ctl.q1_diag == (1.0,) * 6 and ctl.q2_diag == (1.0, 1.0)
    assert ctl.accel_max_mps2 == 2.0 and ctl.accel_increment_max_mps2 == 1.0
    assert cfg.reference.initial_offset_std_m == 3.0


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(num_agvs=0), "num_agvs"),
        (dict(num_slots=-3), "num_slots"),
        (dict(slot_s=0.0), "slot_s"),
        (dict(channel=dict(nakagami_m=0)), "channel.nakagami_m"),
        (dict(channel=dict(nakagami_m=2.5)), "channel.nakagami_m"),
        (dict(channel=dict(bler=1.0)), "channel.bler"),
        (dict(channel=dict(bler=float("nan"))), "channel.bler"),
        (dict(channel=dict(ce_error_var=1.0)), "channel.ce_error_var"),
        (dict(channel=dict(rate_threshold_bps_hz=-1)), "channel.rate_threshold_bps_hz"),
        (dict(drone=dict(altitude_m=-5)), "drone.altitude_m"),
        (dict(drone=dict(max_speed_mps=0)), "drone.max_speed_mps"),
        (dict(control=dict(horizon=0)), "control.horizon"),
        (dict(control=dict(accel_max_mps2=-1)), "control.accel_max_mps2"),
        (dict(power_budget_dbw=float("inf")), "power_budget_dbw"),
    ],
)
def test_bad_values_name_the_field(kwargs, field):
    with pytest.raises(ValueError) as err:
        ScenarioConfig.from_dict(kwargs)
    assert field in str(err.value)


def test_cross_field_checks():
    with pytest.raises(ValueError, match=r"drone.start_m=\(500.0, 100.0\) must lie inside area_m"):
        ScenarioConfig(drone=DroneConfig(start_m=(500.0, 100.0)))
    with pytest.raises(ValueError, match="area_m"):
        ScenarioConfig(area_m=(10, 0, 0, 10))
    with pytest.raises(ValueError, match="path_set='paper'"):
        ScenarioConfig(num_agvs=5, reference=dict(path_set="paper"))
    with pytest.raises(ValueError, match="q2_diag"):
        ControlConfig(q2_diag=(1.0, 0.0))
    with pytest.raises(ValueError, match="unknown"):
        ScenarioConfig(reference=dict(families=("lemniscate", "zigzag")))


def test_unknown_keys_rejected_by_name():
    with pytest.raises(ValueError, match="num_agv"):
        ScenarioConfig.from_dict({"num_agv": 3})
    with pytest.raises(ValueError, match="channel.blocklenght"):
        ScenarioConfig.from_dict({"channel": {"blocklenght": 3}})
    with pytest.raises(ValueError, match="unknown config key 'channel.foo'"):
        ScenarioConfig().override({"channel.foo": 1})
    with pytest.raises(ValueError, match="unknown config key 'bogus'"):
        ScenarioConfig().override(bogus=1)


def test_round_trip_and_override():
    cfg = ScenarioConfig().override({"channel.blocklength": 256, "num_agvs": 3}, drone={"altitude_m": 80.0})
    assert cfg.channel.blocklength == 256 and cfg.num_agvs == 3 and cfg.drone.altitude_m == 80.0
    assert ScenarioConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="blocklength"):
        ScenarioConfig().override({"channel.blocklength": 0})


def test_config_is_frozen():
    cfg = ScenarioConfig()
    with pytest.raises(Exception):
        cfg.num_agvs = 3


def test_presets():
    assert presets.get("default") == ScenarioConfig()
    assert presets.get("paper-nominal").channel.rate_threshold_bps_hz == 1.0
    assert {"default", "paper-nominal", "k3", "k32"} <= set(presets.names())
    with pytest.raises(ValueError, match="valid presets: .*default"):
        presets.get("nope")
    with pytest.raises(ValueError, match="already registered"):
        presets.register("default", ScenarioConfig())


def test_channel_config_linear_values():
    ch = ChannelConfig(alpha0_db=-60.0, noise_power_dbm=-90.0)
    assert math.isclose(ch.alpha0, 1e-6) and math.isclose(ch.noise_power_w, 1e-12)


@pytest.mark.parametrize("overrides, field", [
    ({"control": {"q1_diag": (0, 0, 1, 1, 1, 1)}}, "control.q1_diag"),
    ({"control": {"q2_diag": (1e20, 1.0)}}, "control.q2_diag"),
    ({"channel": {"bler": 0.6, "blocklength": 1, "rate_threshold_bps_hz": 0.1}}, "channel.bler"),
    ({"channel": {"rate_threshold_bps_hz": 2000}}, "channel.rate_threshold_bps_hz"),
    ({"power_budget_dbw": 5000}, "power_budget_dbw"),
    ({"power_budget_dbw": -3300}, "power_budget_dbw"),
    ({"disturbance": {"measurement_noise_position_m": 1e40}}, "disturbance.measurement_noise_position_m"),
])
def test_configs_the_code_cannot_run_are_rejected_naming_the_field(overrides, field):
    """Each of these validated before and crashed later (Riccati, root finding, overflow,
    inf observations); now the config names the field and the allowed range."""
    with pytest.raises(ValueError) as err:
        ScenarioConfig(**overrides)
    text = str(err.value).replace("\n", " ")
    assert field.split(".")[-1] in text and (field.split(".")[0] in text or "." not in field)


def test_accepted_edge_configs_run():
    """The bounds are not too tight: the extremes they allow still run reset and a few steps."""
    import gymnasium as gym
    import numpy as np

    from lawn_env.dynamics import PredictionModel

    for cfg in (ScenarioConfig(channel={"blocklength": 1, "rate_threshold_bps_hz": 0.1}, num_slots=5),
                ScenarioConfig(power_budget_dbw=-100, num_slots=5), ScenarioConfig(power_budget_dbw=60, num_slots=5),
                ScenarioConfig(control={"q1_diag": (1, 1, 0, 0, 0, 0), "q2_diag": (1e6, 1e6)}, num_slots=5)):
        PredictionModel.from_config(cfg)
        env = gym.make("lawn/Joint-v1", config=cfg)
        obs, _ = env.reset(seed=0)
        env.action_space.seed(0)
        for _ in range(5):
            obs, reward, *_ = env.step(env.action_space.sample())
        assert np.all(np.isfinite(obs)) and np.isfinite(reward)
