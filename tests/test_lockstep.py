"""Seeds played in lockstep (:func:`evaluation.run.play_together`) give each seed the record it gets alone; the
batched policy interface (``Policy.reset_scenarios``, ``Policy.act_scenarios``) and its checks."""

import math

import gymnasium as gym
import numpy as np
import pytest

import lawn_env  # noqa: F401
from agents import make_policy
from agents.base import Policy
from evaluation.episode import EpisodeSpec
from evaluation.run import _chunks, evaluate, play_together, run_episode
from lawn_env import ScenarioConfig, presets

#: Fields that time the decisions: a batch's share is not one decision's clock.
TIMING = {"decision_time_median_s", "decision_time_p95_s"}
SHORT = {"num_slots": 24}


def _same(a, b):
    """Two records equal field by field (a NaN equals a NaN), their decision times aside."""
    ra, rb = a.as_row(), b.as_row()
    assert ra.keys() == rb.keys()
    for key in ra.keys() - TIMING:
        x, y = ra[key], rb[key]
        assert x == y or (isinstance(x, float) and math.isnan(x) and isinstance(y, float) and math.isnan(y)), key


@pytest.mark.parametrize("config", [ScenarioConfig(**SHORT), presets.get("disturbed").override(SHORT),
                                    ScenarioConfig(control={"actuator": "buffer"}, **SHORT),
                                    ScenarioConfig(num_agvs=1, **SHORT)],
                         ids=["default", "disturbed", "buffer", "k1"])
def test_lockstep_records_equal_the_seeds_played_alone(config):
    seeds = [4, 9, 2]
    together = play_together(make_policy("dv-mpc", config), "lawn/Joint-v1", config, seeds)
    for seed, row in zip(seeds, together):
        _same(row, run_episode("dv-mpc", "lawn/Joint-v1", config, seed))


def test_the_comm_env_plays_in_lockstep_too():
    config = ScenarioConfig(control={"law": "delivery"}, **SHORT)
    together = play_together(make_policy("dv-mpc", config, env_id="lawn/Comm-v1"), "lawn/Comm-v1", config, [1, 2])
    for seed, row in zip([1, 2], together):
        _same(row, run_episode("dv-mpc", "lawn/Comm-v1", config, seed))


def test_evaluate_chunks_batched_policies_and_plays_the_rest_alone():
    config = ScenarioConfig(**SHORT)
    specs = [EpisodeSpec("dv-mpc", "lawn/Joint-v1", config, s) for s in range(5)]
    specs += [EpisodeSpec("pid", "lawn/Joint-v1", config, s) for s in range(3)]
    chunks = _chunks(specs, workers=2)
    assert [len(c) for c in chunks] == [3, 2, 1, 1, 1]
    legacy = [EpisodeSpec("dv-mpc", "lawn/Joint-v0", config, s) for s in range(3)]  # no native vector env
    assert [len(c) for c in _chunks(legacy, workers=1)] == [1, 1, 1]
    rows = evaluate(specs, progress=False)
    assert [(r.policy, r.seed) for r in rows] == [(s.policy, s.seed) for s in specs]
    for spec, row in zip(specs, rows):
        _same(row, run_episode(spec.policy, spec.env, spec.config, spec.seed))


def test_independent_draws_make_each_vector_scenario_its_single_env():
    config = ScenarioConfig(**SHORT)
    vec = gym.make_vec("lawn/Joint-v1", num_envs=3, vectorization_mode="vector_entry_point", config=config)
    vec.reset(seed=[7, 3, 5], options={"independent_draws": True})
    singles = [gym.make("lawn/Joint-v1", config=config) for _ in range(3)]
    for env, seed in zip(singles, [7, 3, 5]):
        env.reset(seed=seed)
    rng = np.random.default_rng(0)
    for _ in range(10):
        actions = rng.uniform(-1, 1, (3, *vec.single_action_space.shape)).astype(np.float32)
        obs, reward, *_ = vec.step(actions)
        for i, env in enumerate(singles):
            single_obs, single_reward, *_ = env.step(actions[i])
            assert np.array_equal(obs[i], single_obs) and reward[i] == single_reward
    with pytest.raises(ValueError, match=r"options\['independent_draws'\]='yes': must be True or False"):
        vec.reset(seed=0, options={"independent_draws": "yes"})
    assert vec.unwrapped.independent_draws  # the failed reset changed nothing


class Hold(Policy):
    """A user's own policy: no batched act, per-episode state (it counts its steps)."""

    name = "hold"
    stateful = True

    def _on_reset(self, rng):
        self.steps = 0

    def act(self, obs):
        self.steps += 1
        return np.zeros(self.actions.space.shape, dtype=np.float32) + min(self.steps, 3) * 0.1


def test_a_policy_without_a_batched_act_plays_a_batch_scenario_by_scenario():
    config = ScenarioConfig(**SHORT)
    policy = Hold(config)
    policy.reset_scenarios([0, 1])
    env = gym.make_vec("lawn/Joint-v1", num_envs=2, vectorization_mode="vector_entry_point", config=config)
    obs, _ = env.reset(seed=[0, 1], options={"independent_draws": True})
    first = policy.act_scenarios(obs)
    second = policy.act_scenarios(obs)
    assert np.allclose(first, 0.1) and np.allclose(second, 0.2) and not policy.batched
    assert policy.last_plans == [None, None]


def test_a_bad_batch_is_refused_with_what_is_wrong():
    config = ScenarioConfig()
    policy = make_policy("dv-mpc", config)
    obs = np.zeros((2, policy.layout.size), dtype=np.float32)
    with pytest.raises(ValueError, match="act_scenarios before reset_scenarios"):
        policy.act_scenarios(obs)
    policy.reset_scenarios([0, 1])
    with pytest.raises(ValueError, match=r"this batch has 2 scenarios: expected \(2, "):
        policy.act_scenarios(obs[:1])
    bad = obs.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"scenarios \[1\] hold NaN"):
        policy.act_scenarios(bad)
    with pytest.raises(ValueError, match="seeds is empty"):
        policy.reset_scenarios([])
    other = make_policy("dv-mpc", presets.get("k8"))
    with pytest.raises(ValueError, match="observation"):
        other.reset_scenarios([0, 1])
        other.act_scenarios(obs)


class Jitter(Policy):
    """A user's own policy that draws its action's offset at each reset."""

    name = "jitter"

    def _on_reset(self, rng):
        self.offset = float(rng.uniform(-1, 1))

    def act(self, obs):
        return np.full(self.actions.space.shape, self.offset, dtype=np.float32)


def test_unseeded_scenarios_draw_their_own_randomness_and_seeded_ones_their_seeds():
    config = ScenarioConfig(**SHORT)
    policy = Jitter(config, seed=0)
    obs = np.zeros((3, policy.layout.size), dtype=np.float32)
    policy.reset_scenarios([None, None, 7])
    actions = policy.act_scenarios(obs)
    alone = Jitter(config)
    alone.reset(7)
    assert actions[0, 0] != actions[1, 0] and actions[2, 0] == alone.act(obs[2])[0]


def test_a_partial_reset_is_refused_with_why():
    vec = gym.make_vec("lawn/Joint-v1", num_envs=2, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match=r"options\['reset_mask'\]: partial resets are not supported"):
        vec.reset(seed=0, options={"reset_mask": np.array([True, False])})
