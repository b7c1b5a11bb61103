"""The entity layout (``interface={"layout": "entities"}``): a row per AGV padded to MAX_AGVS, a mask,
per-entity actions decoded by the same codec, and the ecosystem's checkers on every central id."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lawn_env
from lawn_env.entities import MAX_AGVS, EntityLayout

IDS = ["lawn/Joint-v1", "lawn/Comm-v1"]


def _make(env_id, k, base="v0", **kwargs):
    return gym.make(env_id, interface={"base": base, "layout": "entities"}, num_agvs=k, **kwargs).unwrapped


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("base", ["v0", "rl"])
@pytest.mark.parametrize("k", [3, 4, 8])
def test_gymnasiums_checker_passes(env_id, base, k):
    env = _make(env_id, k, base)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and obs["mask"].sum() == k
    assert env.observation_space["agvs"].shape == (MAX_AGVS, env.layout.agv_features)


@pytest.mark.parametrize("env_id", IDS)
def test_stable_baselines3s_checker_passes(env_id):
    sb3_env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3_env_checker.check_env(_make(env_id, 3))


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("k", [3, 8])
def test_the_same_episode_as_the_flat_layout_rearranged(env_id, k):
    """Entity actions that carry a flat action's entries replay the flat env's episode: the same
    rewards and infos, and observations whose rows are the flat blocks, padded with zeros."""
    flat, ent = gym.make(env_id, num_agvs=k).unwrapped, _make(env_id, k)
    f = flat.layout.agv_features
    o_flat, _ = flat.reset(seed=5)
    o_ent, _ = ent.reset(seed=5)
    rng = np.random.default_rng(5)
    for _ in range(6):
        np.testing.assert_array_equal(o_ent["agvs"][:k], o_flat[: k * f].reshape(k, f))
        assert not o_ent["agvs"][k:].any() and not o_ent["mask"][k:].any() and o_ent["mask"][:k].all()
        np.testing.assert_array_equal(o_ent["globals"][:3], o_flat[k * f :])
        assert o_ent["globals"][3] == np.float32(k / MAX_AGVS)
        a = rng.uniform(-1, 1, flat.action_space.shape).astype(np.float32)
        o_flat, r_flat, _, _, i_flat = flat.step(a)
        o_ent, r_ent, _, _, i_ent = ent.step(ent.entities.to_entity_actions(a))
        assert r_ent == r_flat
        for key in i_flat:
            np.testing.assert_array_equal(i_ent[key], i_flat[key])


@pytest.mark.parametrize("env_id", IDS)
def test_padded_action_rows_change_nothing(env_id):
    k = 4
    envs = [_make(env_id, k) for _ in range(2)]
    layout = envs[0].entities
    rng = np.random.default_rng(1)
    for env in envs:
        env.reset(seed=2)
    for _ in range(5):
        a = rng.uniform(-1, 1, envs[0].action_space.shape).astype(np.float32)
        b = a.copy()
        present = np.zeros(b.shape, dtype=bool)
        present[layout.gather] = True
        b[~present] = rng.uniform(-1, 1, (~present).sum())  # the padded rows only
        assert not np.array_equal(a, b)
        out_a, out_b = envs[0].step(a), envs[1].step(b)
        assert out_a[1] == out_b[1]
        for key in out_a[0]:
            np.testing.assert_array_equal(out_a[0][key], out_b[0][key])


@pytest.mark.parametrize("role", ["joint", "comm"])
def test_action_round_trips_and_the_codec_decodes_the_present_rows(role):
    cfg = lawn_env.ScenarioConfig(num_agvs=5, reference={"path_set": "random"})
    layout = EntityLayout(cfg, role, 1e6)
    codec = lawn_env.action_codec(cfg, role)
    rng = np.random.default_rng(0)
    flat = rng.uniform(-1, 1, codec.size)
    entity = layout.to_entity_actions(flat)
    np.testing.assert_array_equal(layout.to_flat_actions(entity), flat.astype(np.float32))
    rows = entity[: MAX_AGVS * layout.per_agv].reshape(MAX_AGVS, layout.per_agv)
    decision = codec.decode(layout.to_flat_actions(entity), None, None, np.array([100.0, 100.0]))
    power_row = rows[:5, -1].astype(float)  # each AGV's power weight sits in its own row
    same = codec.decode(flat.astype(np.float32), None, None, np.array([100.0, 100.0]))  # the entity action's float32
    np.testing.assert_array_equal(decision.power_w, same.power_w)
    w = (power_row + 1) / 2
    np.testing.assert_allclose(decision.power_w, cfg.power_budget_w * w / max(1.0, w.sum()), rtol=1e-12)
    if role == "joint":
        np.testing.assert_array_equal(decision.increment.reshape(5, 2) / cfg.control.accel_increment_max_mps2,
                                      rows[:5, :2].astype(float))


def test_the_native_vector_env_takes_the_layout():
    envs = gym.make_vec("lawn/Comm-v1", num_envs=3, vectorization_mode="vector_entry_point",
                        interface={"layout": "entities"}, num_agvs=6, reference={"path_set": "random"})
    obs, _ = envs.reset(seed=0)
    assert envs.observation_space.contains(obs)
    assert obs["agvs"].shape == (3, MAX_AGVS, envs.unwrapped.layout.agv_features)
    for _ in range(3):
        obs, reward, *_ = envs.step(envs.action_space.sample())
        assert envs.observation_space.contains(obs) and reward.shape == (3,)
    with pytest.raises(ValueError, match=r"expected \(3, 66\)"):
        envs.step(np.zeros((3, 8), dtype=np.float32))


def test_bad_layouts_and_fleets_raise_errors_that_name_them():
    with pytest.raises(ValueError, match="layout"):
        gym.make("lawn/Joint-v1", interface={"layout": "graph"})
    with pytest.raises(ValueError, match="MAX_AGVS=64"):
        _make("lawn/Joint-v1", 65, reference={"path_set": "random"})
    with pytest.raises(ValueError, match="layout"):
        lawn_env.parallel_env(interface={"layout": "rows"})
    with pytest.raises(ValueError, match="MAX_AGVS=64"):
        lawn_env.parallel_env(interface={"layout": "entities"}, num_agvs=65, reference={"path_set": "random"})


def test_the_core_and_the_agents_import_without_torch():
    """The fleet network needs torch and SB3 (the rl extra); lawn_env and agents import without them."""
    import subprocess
    import sys

    code = "import sys, lawn_env, agents; print('torch' in sys.modules, 'stable_baselines3' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


def test_mixed_fleets_draw_k_per_episode_deterministically():
    """MixedFleetEnv: Gymnasium's checker passes; the same seed draws the same K and plays the same
    episode; the draws cover the sizes; each episode is the env of its K (identical spaces)."""
    sizes = (3, 5, 8)
    env = lawn_env.MixedFleetEnv("lawn/Comm-v1", fleet_sizes=sizes)
    check_env(env, skip_render_check=True)
    seen, rng = set(), np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (3,) + env.action_space.shape).astype(np.float32)
    for seed in range(12):
        runs = []
        for _ in range(2):
            obs, info = env.reset(seed=seed)
            steps = [env.step(a) for a in actions]
            runs.append((info["num_agvs"], obs["mask"].sum(), [s[1] for s in steps], steps[-1][0]["agvs"]))
        assert runs[0][0] == runs[1][0] == runs[0][1] and runs[0][2] == runs[1][2]
        np.testing.assert_array_equal(runs[0][3], runs[1][3])
        seen.add(runs[0][0])
    assert seen == set(sizes)
    with pytest.raises(ValueError, match="fleet_sizes"):
        lawn_env.MixedFleetEnv(fleet_sizes=(3, 65))
    with pytest.raises(ValueError, match="env_id"):
        lawn_env.MixedFleetEnv("lawn/Parallel-v0")
