"""The paired reward (training.paired): the anchor's copy shares the agent's randomness slot by slot,
and what it subtracts over an episode does not depend on the agent's actions."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import lawn_env
from agents import make_policy
from training.paired import PairedReward

SHORT = {"num_slots": 12}


def _play(env, actor, seed):
    """One episode of ``actor(obs)`` on ``env``; the rewards and infos of its steps."""
    obs, _ = env.reset(seed=seed)
    rewards, infos, done = [], [], False
    while not done:
        obs, reward, terminated, truncated, info = env.step(actor(obs))
        rewards.append(reward)
        infos.append(info)
        done = terminated or truncated
    return np.array(rewards), infos


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_an_agent_playing_the_anchor_earns_zero_every_slot(env_id):
    # the same decisions on the same draws: the two copies stay equal slot by slot
    env = PairedReward(gym.make(env_id, **SHORT), anchor="epa")
    agent = make_policy("epa", env.unwrapped.config, env_id=env_id)
    agent.reset()
    rewards, infos = _play(env, agent.act, seed=3)
    assert len(rewards) == SHORT["num_slots"]
    assert np.array_equal(rewards, np.zeros_like(rewards))
    assert all(i["anchor_stage_cost"] == i["stage_cost"] for i in infos)


def _subtracted_total(env, actor, seed):
    """What the wrapper subtracted over an episode: the env's rewards (its slot rewards, and the
    terminal penalty, the reward floor of every unplayed slot) minus the paired rewards."""
    rewards, infos = _play(env, actor, seed)
    iface, slots = env.unwrapped.interface, env.unwrapped.config.num_slots
    env_rewards = [float(iface.rewards_from_costs(np.array(i["stage_cost"]))) for i in infos]
    penalty = iface.reward_floor * (slots - len(infos)) if len(infos) < slots else 0.0
    return sum(env_rewards) + penalty - float(np.sum(rewards)), len(infos)


def test_the_subtracted_total_is_the_anchors_episode_whatever_the_agent_does():
    # the RL interface terminates bad episodes early; the anchor's unplayed slots are subtracted too
    interface = dataclasses.replace(lawn_env.RL_INTERFACE, termination_distance_m=2.0)
    env = PairedReward(gym.make("lawn/Joint-v1", **SHORT, interface=interface), anchor="epa")
    low, high = env.action_space.low, env.action_space.high
    zero, _ = _subtracted_total(env, lambda obs: np.zeros_like(low), seed=5)
    rng = np.random.default_rng(0)
    wild, played = _subtracted_total(env, lambda obs: rng.choice([low, high], axis=0).astype(low.dtype), seed=5)
    assert played < SHORT["num_slots"]  # the wild agent's episode ended early
    anchor = make_policy("epa", env.unwrapped.config)
    anchor.reset()
    _, anchor_infos = _play(gym.make("lawn/Joint-v1", **SHORT), anchor.act,
                            seed=int(np.random.default_rng(5).integers(2**31)))  # the wrapper's episode seed
    iface = env.unwrapped.interface
    expected = sum(float(iface.rewards_from_costs(np.array(i["stage_cost"]))) for i in anchor_infos)
    assert zero == pytest.approx(expected, rel=1e-12)
    assert wild == pytest.approx(expected, rel=1e-12)


def test_episodes_are_seeded_by_the_wrapper_and_repeat():
    env = PairedReward(gym.make("lawn/CommRL-v1", **SHORT), anchor="epa")
    zero = lambda obs: np.zeros(env.action_space.shape, env.action_space.dtype)  # noqa: E731
    first, _ = _play(env, zero, seed=11)
    second, _ = _play(env, zero, seed=11)
    assert np.array_equal(first, second)
    env.reset(seed=11)
    third, _ = _play(env, zero, seed=None)  # the next episode of the wrapper's own seed stream
    assert not np.array_equal(first, third)


def test_bad_arguments_name_the_argument():
    with pytest.raises(ValueError, match="gamma=0"):
        PairedReward(gym.make("lawn/Joint-v1"), gamma=0)
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        PairedReward(gym.make("lawn/Joint-v1"), anchor="nope")
    with pytest.raises(ValueError, match=r"anchor=.*lawn/Comm-v1"):
        PairedReward(gym.make("lawn/Comm-v1"), anchor=make_policy("epa"))
    with pytest.raises(TypeError, match="CartPoleEnv"):
        PairedReward(gym.make("CartPole-v1"))
