"""The residual action scheme (agents.residual): the zero action plays the anchor, the learner's
action moves it by its scale, and a trained agent acts at evaluation exactly as it did in training."""

import gymnasium as gym
import numpy as np
import pytest

import lawn_env
from agents import make_policy
from agents.residual import AnchorResidual, ResidualActions, check_residual
from lawn_env.rollouts import rollout

SHORT = {"num_slots": 12}
#: The fleet networks' interface: no MPC in the decode, dv-mpc's decisions inside its range.
NO_MPC = {"base": "rl", "power_anchor": "distance", "increment_anchor": "lqr", "residual_scale": 2.0,
          "power_log_range": 4.0}


def _episode(env, actor, seed):
    obs, _ = env.reset(seed=seed)
    done, actions = False, []
    while not done:
        actions.append(actor(obs))
        obs, _, terminated, truncated, info = env.step(actions[-1])
        done = terminated or truncated
    return info["episode_metrics"]["control_cost"], np.array(actions)


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_the_zero_action_plays_the_anchor(env_id):
    config = lawn_env.presets.get("steady").override(SHORT)
    expert = rollout(gym.make(env_id, config=config), make_policy("dv-mpc", config, env_id=env_id), 0)
    env = AnchorResidual(gym.make(env_id, config=config, interface=NO_MPC), make_policy("dv-mpc", config, env_id=env_id),
                         scale=0.3)
    cost, _ = _episode(env, lambda obs: np.zeros(env.action_space.shape, np.float32), seed=0)
    assert cost == pytest.approx(expert.metrics["control_cost"], rel=1e-6)


def test_the_action_moves_the_anchors_by_the_scale():
    config = lawn_env.ScenarioConfig(**SHORT)
    env = AnchorResidual(gym.make("lawn/Joint-v1", config=config, interface=NO_MPC), make_policy("epa", config),
                         scale=0.5)
    env.reset(seed=1)
    probe = ResidualActions(make_policy("epa", config), config, "lawn/Joint-v1", NO_MPC, 0.5)
    probe.reset(1)
    anchor = probe.anchor_action(env.unwrapped.benchmark_observation())
    a = np.linspace(-1, 1, env.action_space.shape[0]).astype(np.float32)
    moved = env.action(a)
    assert np.allclose(moved, np.clip(anchor + 0.5 * a, -1, 1), atol=1e-6)
    assert not np.allclose(moved, anchor, atol=1e-3)  # the learner's action reaches the env


def test_bad_settings_and_actions_are_named():
    env = gym.make("lawn/Joint-v1", interface=NO_MPC, **SHORT)
    epa = make_policy("epa", env.unwrapped.config)
    for bad, match in ((0.0, "scale=0.0"), (3, "scale=3"), (True, "scale=True")):
        with pytest.raises(ValueError, match=match):
            AnchorResidual(env, epa, scale=bad)
    with pytest.raises(TypeError, match="a built policy"):
        AnchorResidual(env, "epa")
    with pytest.raises(ValueError, match="drives lawn/Comm-v1, not lawn/Joint-v1"):
        AnchorResidual(env, make_policy("epa", env.unwrapped.config, env_id="lawn/Comm-v1"))
    with pytest.raises(ValueError, match="'anchor'"):
        check_residual({"scale": 0.2})
    with pytest.raises(ValueError, match="action_scheme='direct'"):
        AnchorResidual(gym.make("lawn/Joint-v1", **SHORT), epa)  # the v0 interface has no anchored actions
    with pytest.raises(TypeError, match="wraps a lawn env"):
        AnchorResidual(gym.make("CartPole-v1"), epa)
    wrapped = AnchorResidual(env, epa)
    wrapped.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        wrapped.step(np.zeros(3, np.float32))
    with pytest.raises(ValueError, match="action"):
        wrapped.step(np.full(wrapped.action_space.shape, np.nan, np.float32))


def test_a_residual_agent_acts_at_evaluation_as_in_training(tmp_path):
    # the learned policy recomputes the anchor's action and adds its own: the same episode as training's env
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from agents.learned import SB3Policy

    config = lawn_env.ScenarioConfig(**SHORT)
    residual = {"anchor": "epa", "scale": 0.4}
    env = AnchorResidual(gym.make("lawn/Joint-v1", config=config, interface=NO_MPC), make_policy("epa", config), 0.4)
    model = PPO("MlpPolicy", env, seed=0, device="cpu", n_steps=32, batch_size=32)
    import torch

    with torch.no_grad():  # an untrained network's actions are tiny: make them move the anchor's
        model.policy.action_net.weight.mul_(50.0)
    trained, actions = _episode(env, lambda obs: model.predict(obs, deterministic=True)[0], seed=4)
    assert np.abs(actions).max() > 0.2
    from agents.policies import attach_residual

    policy = attach_residual(SB3Policy(model, config, "lawn/Joint-v1", NO_MPC), residual)
    evaluated = rollout(gym.make("lawn/Joint-v1", config=config), policy, 4).metrics["control_cost"]
    assert evaluated == pytest.approx(trained, rel=1e-5)
    plain = rollout(gym.make("lawn/Joint-v1", config=config), SB3Policy(model, config, "lawn/Joint-v1", NO_MPC), 4)
    assert plain.metrics["control_cost"] != pytest.approx(trained, rel=1e-3)  # without the residual: another agent


def test_a_residual_of_some_parts_moves_only_those():
    # moves=("power", "drone"): the learner's action is the K powers and the drone's offsets; the increments
    # stay the anchor's, and the zero action still plays it
    config = lawn_env.ScenarioConfig(**SHORT)
    k = config.num_agvs
    env = AnchorResidual(gym.make("lawn/Joint-v1", config=config, interface=NO_MPC), make_policy("epa", config),
                         scale=0.5, moves=["drone", "power"])
    assert env.action_space.shape == (k + 2,)
    assert env.residual.moved.tolist() == list(range(2 * k, 3 * k + 2))  # the action's order, whatever the list's
    env.reset(seed=1)
    probe = ResidualActions(make_policy("epa", config), config, "lawn/Joint-v1", NO_MPC, 0.5)
    probe.reset(1)
    anchor = probe.anchor_action(env.unwrapped.benchmark_observation())
    a = np.linspace(-1, 1, k + 2).astype(np.float32)
    moved = env.action(a)
    assert np.allclose(moved[: 2 * k], anchor[: 2 * k], atol=1e-6)  # the increments: the anchor's
    assert np.allclose(moved[2 * k :], np.clip(anchor[2 * k :] + 0.5 * a, -1, 1), atol=1e-6)
    steady = lawn_env.presets.get("steady").override(SHORT)  # dv-mpc's decisions lie inside the interface's range
    expert = rollout(gym.make("lawn/Joint-v1", config=steady), make_policy("dv-mpc", steady), 2)
    env = AnchorResidual(gym.make("lawn/Joint-v1", config=steady, interface=NO_MPC), make_policy("dv-mpc", steady),
                         scale=0.5, moves=["drone", "power"])
    cost, _ = _episode(env, lambda obs: np.zeros(k + 2, np.float32), seed=2)
    assert cost == pytest.approx(expert.metrics["control_cost"], rel=1e-6)
    drone = AnchorResidual(gym.make("lawn/Comm-v1", config=config, interface=NO_MPC),
                           make_policy("epa", config, env_id="lawn/Comm-v1"), moves=["drone"])
    assert drone.action_space.shape == (2,) and drone.residual.moved.tolist() == [k, k + 1]


def test_bad_moves_are_named():
    assert check_residual({"anchor": "dv-mpc", "moves": ["drone", "power", "increment"]}) == \
        {"anchor": "dv-mpc", "scale": 0.25}  # every part: the record stays as before
    assert check_residual({"anchor": "dv-mpc", "moves": ("drone", "power")})["moves"] == ["power", "drone"]
    for bad in ([], "drone", ["wing"], ["drone", "drone"], 3):
        with pytest.raises(ValueError, match="residual moves="):
            check_residual({"anchor": "dv-mpc", "moves": bad})
    config = lawn_env.ScenarioConfig(**SHORT)
    for moves in (["increment"], ["increment", "power"]):  # Comm's AGVs plan their own increments: no part dropped
        with pytest.raises(ValueError, match=r"lawn/Comm-v1 has no \['increment'\]"):
            ResidualActions(make_policy("epa", config, env_id="lawn/Comm-v1"), config, "lawn/Comm-v1", NO_MPC,
                            moves=moves)
