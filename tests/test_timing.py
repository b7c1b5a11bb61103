"""A decision clock sums the wall time of the policies it times, and a timed policy acts as the policy."""

import gymnasium as gym
import numpy as np
import pytest

import lawn_env
from agents import make_policy
from agents.timing import DecisionClock, TimedPolicy
from lawn_env.rollouts import rollout


def test_a_timed_policy_acts_as_the_policy_and_counts_its_decisions():
    config = lawn_env.ScenarioConfig(num_slots=8)
    clock = DecisionClock()
    timed = clock.timed(make_policy("rg-mpc", config))
    assert clock.timed(timed) is timed and timed.name == "rg-mpc" and timed.env_id == "lawn/Joint-v1"
    plain = rollout(gym.make("lawn/Joint-v1", config=config), make_policy("rg-mpc", config), 3)
    episode = rollout(gym.make("lawn/Joint-v1", config=config), timed, 3)
    assert episode.metrics["control_cost"] == plain.metrics["control_cost"]
    assert 0 < clock.seconds <= episode.decision_s.sum()  # the rollout times each act around the clock's
    assert timed.last_plan is timed.policy.last_plan is not None
    first = clock.seconds
    other = clock.timed(make_policy("epa", config))  # a second policy on the same clock adds to it
    rollout(gym.make("lawn/Joint-v1", config=config), other, 3)
    assert clock.seconds > first
    with pytest.raises(ValueError, match="shape"):  # the timed policy's checks are the policy's
        timed.act(np.zeros(3, np.float32))
    with pytest.raises(TypeError, match="a built policy"):
        TimedPolicy("rg-mpc", clock)
