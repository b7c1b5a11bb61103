import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

import lawn_env


def test_pettingzoo_api():
    parallel_api_test(lawn_env.parallel_env(), num_cycles=150)


def test_pettingzoo_seed():
    parallel_seed_test(lambda: lawn_env.parallel_env(num_agvs=3))


def test_spaces_are_stable_objects():
    env = lawn_env.parallel_env()
    for agent in env.possible_agents:
        assert env.observation_space(agent) is env.observation_space(agent)
        assert env.action_space(agent) is env.action_space(agent)
    with pytest.raises(ValueError, match="unknown agent"):
        env.action_space("agv_99")


def test_lockstep_with_joint_env():
    """Two views of one core: the same seed and decisions give bit for bit the same observations,
    drone reward and drone infos as ``lawn/Joint-v1``, and AGV rewards that sum to it."""
    par = lawn_env.parallel_env()
    joint = gym.make("lawn/Joint-v1").unwrapped
    obs, infos = par.reset(seed=21)
    jobs, jinfo = joint.reset(seed=21)
    assert np.array_equal(obs["drone"], jobs)
    assert infos["drone"].keys() == jinfo.keys()
    assert all(np.array_equal(infos["drone"][key], jinfo[key]) for key in jinfo)
    rng = np.random.default_rng(0)
    k = 4
    while par.agents:
        a = rng.uniform(-1, 1, 3 * k + 2).astype(np.float32)
        actions = {"drone": a[2 * k :], **{f"agv_{i}": a[2 * i : 2 * i + 2] for i in range(k)}}
        obs, rewards, terms, truncs, infos = par.step(actions)
        jobs, jr, _, jtrunc, jinfo = joint.step(a)
        assert np.array_equal(obs["drone"], jobs)
        assert rewards["drone"] == jr
        # the same keys, but episode_metrics: the parallel env's infos keep fixed keys (TorchRL's wrapper)
        assert infos["drone"].keys() == jinfo.keys() - {"episode_metrics"}
        assert all(np.array_equal(infos["drone"][key], jinfo[key]) for key in infos["drone"])
        assert sum(rewards[f"agv_{i}"] for i in range(k)) == pytest.approx(jr)
        blocks = joint.layout.agv_blocks(jobs)
        for i in range(k):
            assert np.array_equal(obs[f"agv_{i}"][: blocks.shape[1]], blocks[i])
        assert all(truncs.values()) == jtrunc
    assert par.agents == []
    assert par.episode_metrics() == jinfo["episode_metrics"]


def test_missing_and_bad_actions():
    env = lawn_env.parallel_env()
    env.reset(seed=0)
    acts = {a: env.action_space(a).sample() for a in env.agents}
    partial = dict(acts)
    partial.pop("agv_1")
    with pytest.raises(ValueError, match="missing agents \\['agv_1'\\]"):
        env.step(partial)
    bad = dict(acts)
    bad["agv_0"] = np.array([np.nan, 0.0])
    with pytest.raises(ValueError, match="agv_0"):
        env.step(bad)
    with pytest.raises(ValueError, match="unknown agents \\['pilot'\\]"):
        env.step({**acts, "pilot": np.zeros(2)})


def test_state_and_render():
    env = lawn_env.parallel_env(render_mode="rgb_array")
    env.reset(seed=0)
    assert env.state().shape == env.observation_space("drone").shape
    frame = env.render()
    assert frame.shape[2] == 3
    env.close()


def test_parallel_step_rejects_what_is_not_a_dict_of_actions():
    par = lawn_env.parallel_env(num_agvs=2)
    par.reset(seed=0)
    for bad in (None, [par.action_space(a).sample() for a in par.agents]):
        with pytest.raises(TypeError, match="actions must be a dict from agent name to action"):
            par.step(bad)
    actions = {a: par.action_space(a).sample() for a in par.agents}
    actions["agv_1"] = np.zeros((1, 2))
    with pytest.raises(ValueError, match=r"actions\['agv_1'\] has shape \(1, 2\); expected \(2,\)"):
        par.step(actions)


@pytest.mark.parametrize("k", [3, 4, 8])
def test_the_entity_layout_passes_pettingzoos_checker(k):
    env = lawn_env.parallel_env(interface={"base": "rl", "layout": "entities"}, num_agvs=k, num_slots=12)
    parallel_api_test(env, num_cycles=15)
    assert env.observation_space("drone") is env.observation_space(f"agv_{k - 1}")  # one space for all agents
    assert env.action_space("drone").shape == (2,) and env.action_space("agv_0").shape == (3,)


def test_entity_agents_in_lockstep_with_the_central_entity_env():
    """The multi-agent entity layout is the central one split by entity: every agent sees the
    central entity observation and its own one-hot; the agents' rows and the drone's move,
    assembled, give bit for bit the central env's step."""
    k, iface = 5, {"base": "rl", "layout": "entities"}
    par = lawn_env.parallel_env(interface=iface, num_agvs=k, reference={"path_set": "random"})
    joint = gym.make("lawn/Joint-v1", interface=iface, num_agvs=k, reference={"path_set": "random"}).unwrapped
    obs, _ = par.reset(seed=4)
    jobs, _ = joint.reset(seed=4)
    rng = np.random.default_rng(2)
    for _ in range(6):
        for j, agent in enumerate(par.possible_agents):
            assert all(np.array_equal(obs[agent][key], jobs[key]) for key in jobs)
            assert obs[agent]["me"].argmax() == j and obs[agent]["me"].sum() == 1.0
        a = np.zeros(joint.action_space.shape, dtype=np.float32)
        a[: 3 * k] = rng.uniform(-1, 1, 3 * k)
        a[-2:] = rng.uniform(-1, 1, 2)
        actions = {"drone": a[-2:], **{f"agv_{i}": a[3 * i : 3 * i + 3] for i in range(k)}}
        obs, rewards, *_ = par.step(actions)
        jobs, jr, *_ = joint.step(a)
        assert rewards["drone"] == jr
    with pytest.raises(ValueError, match=r"actions\['agv_0'\]"):
        par.step({**actions, "agv_0": np.zeros(2, dtype=np.float32)})
