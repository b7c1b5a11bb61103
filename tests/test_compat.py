"""What other RL libraries rely on: copies, keyword errors, info schemas, PettingZoo's
AEC form and tests, the registry's episode length. The clients themselves run in
``tests/test_clients.py`` (slow, skipped when they are not installed)."""

import copy
import pickle
import sys

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test
from pettingzoo.test.state_test import test_state as pz_state_test
from pettingzoo.test.state_test import test_state_space as pz_state_space_test

import lawn_env
from lawn_env.config import ScenarioConfig, UnknownConfigKeyError
from lawn_env.envs.base import COMM_INFO_KEYS, INFO_KEYS

ALL_IDS = list(lawn_env.ENV_IDS) + list(lawn_env.RL_ENV_IDS)


def _actions(space, n, seed):
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1, 1, space.shape).astype(np.float32) for _ in range(n)]


def _run(env, actions):
    out = []
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs, reward, info["stage_cost"]))
        if terminated or truncated:
            break
    return out


@pytest.mark.parametrize("env_id", ALL_IDS)
@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_env_continues_like_the_original(env_id, how):
    """A copy made mid-episode continues bitwise like the original for the rest of the episode
    (the MPC's warm starts are plain arrays that the copy carries)."""
    env = gym.make(env_id, num_slots=40).unwrapped
    env.reset(seed=4)
    for a in _actions(env.action_space, 5, 0):
        env.step(a * 0.3)
    clone = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    actions = [a * 0.3 for a in _actions(env.action_space, 40, 1)]
    original, copied = _run(env, actions), _run(clone, actions)
    assert len(original) == len(copied) > 10
    for (o1, r1, c1), (o2, r2, c2) in zip(original, copied):
        np.testing.assert_array_equal(o2, o1)
        assert r2 == r1 and c2 == c1


def test_a_copied_parallel_env_continues_like_the_original():
    par = lawn_env.parallel_env(num_slots=30)
    par.reset(seed=2)
    rng = np.random.default_rng(0)

    def acts():
        return {a: rng.uniform(-1, 1, par.action_space(a).shape).astype(np.float32) * 0.3 for a in par.possible_agents}

    par.step(acts())
    clone = pickle.loads(pickle.dumps(par))
    for _ in range(20):
        a = acts()
        o1, r1, *_ = par.step(a)
        o2, r2, *_ = clone.step(a)
        assert all(np.array_equal(o1[k], o2[k]) for k in o1) and r1 == r2


def test_unknown_keywords_raise_a_type_error_naming_the_key():
    for make in (lambda: gym.make("lawn/Comm-v1", frameskip=4), lambda: lawn_env.parallel_env(frameskip=4)):
        # TorchRL retries without frameskip= on a TypeError saying "unexpected keyword argument 'frameskip'"
        with pytest.raises(TypeError, match="unknown config key 'frameskip' \\(unexpected keyword argument "
                                            "'frameskip'\\); valid keys: num_agvs") as err:
            make()
        assert isinstance(err.value, ValueError)  # callers that catch ValueError keep working
    with pytest.raises(UnknownConfigKeyError, match="'channel.blok'"):
        ScenarioConfig.from_dict({"channel": {"blok": 1}})
    with pytest.raises(UnknownConfigKeyError, match="'drone.speed'"):
        ScenarioConfig().override({"drone.speed": 3})


def _schema(info):
    out = {}
    for key, value in info.items():
        assert isinstance(value, (np.ndarray, np.generic)), (key, type(value))  # flat: no nested dicts
        out[key] = (np.shape(value), np.asarray(value).dtype)
    return out


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1", "lawn/CommRL-v1"])
def test_reset_and_step_infos_share_keys_shapes_and_dtypes(env_id):
    env = gym.make(env_id, num_slots=5)
    _, info0 = env.reset(seed=0)
    expected = set(INFO_KEYS) | (set(COMM_INFO_KEYS) if "Comm" in env_id else set())
    assert set(info0) == expected
    schema = _schema(info0)
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(env.action_space.sample())
        done = terminated or truncated
        metrics = info.pop("episode_metrics", None)
        assert (metrics is not None) == done  # the one key of the last step only
        assert _schema(info) == schema
    assert info["reward_tracking"] + info["reward_effort"] == pytest.approx(-info["stage_cost"])


def test_the_three_envs_share_the_info_schema():
    schemas = []
    for make in (lambda: gym.make("lawn/Joint-v1"), lambda: gym.make("lawn/Comm-v1")):
        _, info = make().reset(seed=0)
        schemas.append({k: v for k, v in _schema(info).items() if k in INFO_KEYS})
    par = lawn_env.parallel_env()
    _, infos = par.reset(seed=0)
    schemas.append(_schema(infos["drone"]))
    assert schemas[0] == schemas[1] == schemas[2]
    agv = _schema(infos["agv_0"])
    assert set(agv) == set(INFO_KEYS)
    _, _, _, _, step_infos = par.step({a: par.action_space(a).sample() for a in par.agents})
    assert _schema(step_infos["drone"]) == schemas[2] and _schema(step_infos["agv_0"]) == agv


def test_pettingzoo_aec_form_max_cycles_and_state():
    max_cycles_test(sys.modules["lawn_env"])
    api_test(lawn_env.env(num_agvs=2, num_slots=30), num_cycles=40)
    aec = lawn_env.env(num_agvs=2, num_slots=30)
    pz_state_space_test(aec)
    pz_state_test(aec, num_cycles=40)
    parallel_api_test(lawn_env.parallel_env(max_cycles=20), num_cycles=30)
    with pytest.raises(ValueError, match="max_cycles=20 and num_slots=30 disagree"):
        lawn_env.parallel_env(max_cycles=20, num_slots=30)


def test_parallel_render_accepts_the_arguments_rllib_passes():
    par = lawn_env.parallel_env(render_mode="rgb_array", num_agvs=2)
    par.reset(seed=0)
    frame = par.render("rgb_array")
    assert frame.ndim == 3 and frame.shape[2] == 3


def test_the_spec_carries_the_episode_length_and_agrees_with_num_slots():
    """The envs end their episodes at num_slots themselves; a made env's spec reports it (no
    registered time limit to disagree with it, and none that would block the native vector env)."""
    for env_id in ALL_IDS:
        assert gym.spec(env_id).max_episode_steps is None and not gym.spec(env_id).additional_wrappers
        assert gym.make(env_id).spec.max_episode_steps == ScenarioConfig().num_slots
    env = gym.make("lawn/Joint-v1", num_slots=150)
    assert env.spec.max_episode_steps == 150
    env.reset(seed=0)
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        steps, done = steps + 1, terminated or truncated
    assert steps == 150
    assert gym.make("lawn/Comm-v1", num_slots=60, max_episode_steps=60).spec.max_episode_steps == 60
    # the module:id form registers the ids in processes that never imported lawn_env
    assert gym.make("lawn_env:lawn/Comm-v1").spec.max_episode_steps == 120
