"""The fleet policy (agents/fleet.py): permutation-equivariant, blind to padded rows, one network for
every K, saved and loaded like any SB3 model."""

import json

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO

from agents.fleet import FleetPolicy
from lawn_env.entities import (
    MAX_AGVS,
    EntityLayout,
)


def _env(env_id="lawn/Joint-v1", k=5):
    return gym.make(env_id, interface={"base": "rl", "layout": "entities"}, num_agvs=k,
                    reference={"path_set": "random"})


def _model(env, seed=0):
    return PPO(FleetPolicy, env, n_steps=32, batch_size=32, n_epochs=1, seed=seed,
               policy_kwargs=dict(width=32, heads=2, layers=2))


def _rows(action, per_agv):
    return action[..., : MAX_AGVS * per_agv].reshape(action.shape[:-1] + (MAX_AGVS, per_agv)), action[..., -2:]


@pytest.mark.parametrize("env_id, per_agv", [("lawn/Joint-v1", 3), ("lawn/Comm-v1", 1)])
def test_permuting_the_agvs_permutes_their_actions(env_id, per_agv):
    k = 5
    env = _env(env_id, k)
    model = _model(env)
    obs, _ = env.reset(seed=1)
    perm = np.array([3, 0, 4, 1, 2])
    shuffled = {key: value.copy() for key, value in obs.items()}
    shuffled["agvs"][:k] = obs["agvs"][perm]
    a, _ = model.predict(obs, deterministic=True)
    b, _ = model.predict(shuffled, deterministic=True)
    rows_a, drone_a = _rows(a, per_agv)
    rows_b, drone_b = _rows(b, per_agv)
    np.testing.assert_allclose(rows_b[:k], rows_a[perm], atol=1e-5)
    np.testing.assert_allclose(drone_b, drone_a, atol=1e-5)
    assert not np.allclose(rows_a[0], rows_a[1])  # the rows differ: the check above has teeth


def test_padded_rows_change_no_action():
    k = 4
    env = _env(k=k)
    model = _model(env)
    obs, _ = env.reset(seed=2)
    noisy = {key: value.copy() for key, value in obs.items()}
    noisy["agvs"][k:] = np.random.default_rng(0).uniform(-1, 1, noisy["agvs"][k:].shape)
    a, _ = model.predict(obs, deterministic=True)
    b, _ = model.predict(noisy, deterministic=True)
    np.testing.assert_allclose(b, a, atol=1e-6)
    assert np.all(_rows(a, 3)[0][k:] == 0.0)  # padded rows' means are zero


def test_a_network_trained_at_k4_runs_at_k3_and_k8_and_reloads(tmp_path):
    model = _model(_env(k=4))
    model.learn(64)
    for k in (3, 8):
        env = _env(k=k)
        obs, _ = env.reset(seed=k)
        for _ in range(3):
            action, _ = model.predict(obs, deterministic=True)
            assert env.action_space.contains(np.clip(action, -1, 1))
            obs, *_ = env.step(np.clip(action, -1, 1))
    model.save(tmp_path / "fleet")
    again = PPO.load(tmp_path / "fleet")
    assert again.policy.fleet == {"width": 32, "heads": 2, "layers": 2}
    obs, _ = _env(k=8).reset(seed=0)
    np.testing.assert_array_equal(again.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])


def test_the_compiled_inference_gives_the_torch_networks_actions():
    """FleetInference (what SB3Policy acts with) against the torch module it copies, every weight
    perturbed (the layer norms' gains and biases included), on fleets of 1 to 64 and on a mask with
    holes; and a non-fleet policy is refused."""
    import torch

    from agents.fleet import FleetInference

    model = _model(_env(k=4))
    rng = np.random.default_rng(0)
    with torch.no_grad():
        for param in model.policy.parameters():
            param.add_(torch.as_tensor(rng.normal(0, 0.3, tuple(param.shape)), dtype=param.dtype))
    fast = FleetInference(model.policy)
    space = model.policy.observation_space
    for k in (1, 3, 17, MAX_AGVS, "holes"):
        obs = {key: rng.uniform(-2, 2, space[key].shape).astype(np.float32) for key in ("agvs", "globals")}
        mask = (rng.random(MAX_AGVS) < 0.3) if k == "holes" else (np.arange(MAX_AGVS) < k)
        obs["mask"] = mask.astype(np.float32)
        with torch.no_grad():
            expected = model.policy.get_distribution({key: torch.as_tensor(v)[None] for key, v in obs.items()})
            expected = expected.mode().numpy()[0]
        got = fast(obs)
        np.testing.assert_allclose(got, expected, atol=2e-5)
        assert np.all(_rows(expected, 3)[0][~mask] == 0.0) and np.abs(expected).max() > 0.1  # torch: zero padding
    with pytest.raises(TypeError, match="FleetPolicy"):
        FleetInference(PPO("MlpPolicy", gym.make("lawn/JointRL-v1"), n_steps=32, batch_size=32).policy)


def test_the_flat_layout_is_refused_with_a_clear_error():
    with pytest.raises(ValueError, match="entity layout"):
        PPO(FleetPolicy, gym.make("lawn/JointRL-v1"))


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_a_fleet_network_acts_on_the_unmodified_v0_envs_of_any_k(env_id):
    """SB3Policy carries an entity-layout network to the flat v0 env of any K: the v0 action it
    hands the env is the network's entity action gathered and decoded as in training."""
    from agents.learned import SB3Policy
    from lawn_env import action_codec, presets

    iface = {"base": "rl", "layout": "entities"}
    model = _model(gym.make(env_id, interface=iface, num_agvs=4, reference={"path_set": "random"}))
    for k in (3, 8):
        config = presets.get("default").override(num_agvs=k, reference={"path_set": "random"})
        policy = SB3Policy(model, config, env_id, interface=iface)
        v0 = gym.make(env_id, config=config).unwrapped
        twin = gym.make(env_id, config=config, interface=iface).unwrapped
        obs, _ = v0.reset(seed=k)
        twin_obs, _ = twin.reset(seed=k)
        policy.reset(seed=k)
        scheme = action_codec(config, "joint" if env_id == "lawn/Joint-v1" else "comm", iface)
        for _ in range(3):
            action = policy.act(obs)
            assert v0.action_space.contains(action)
            entity, _ = model.predict(twin_obs, deterministic=True)
            snap = v0.snapshot()
            expected = scheme.decode(policy.entities.to_flat_actions(np.clip(entity, -1, 1)), snap.x_aug,
                                     snap.reference, snap.drone_position, snap.slot)
            decided = policy.v0.decode(action, snap.x_aug, snap.reference, snap.drone_position, snap.slot)
            np.testing.assert_allclose(decided.power_w, expected.power_w, rtol=1e-5, atol=1e-9)
            obs, *_ = v0.step(action)
            twin_obs, *_ = twin.step(np.clip(entity, -1, 1))
    with pytest.raises(ValueError, match=r"evaluate it on the scenario it was trained for \(agents.trained_config\)"):
        SB3Policy(model, presets.get("default").override(control={"horizon": 5}), env_id, interface=iface)


def test_dagger_labels_the_expert_and_fitting_lowers_the_loss():
    """The fleet data set's labels are the expert's decisions (decoded they give its powers), the
    padded entries carry none, and a DAgger round on two fleet sizes trains the network."""
    from agents import make_policy
    from lawn_env import action_codec, presets
    from training.fleet import dagger_round, fit_fleet, fleet_pairs

    iface = {"base": "rl", "layout": "entities"}
    configs = [presets.get("default").override(num_agvs=k, num_slots=12) for k in (3, 4)]
    obs, actions, present = fleet_pairs("lawn/Comm-v1", configs[0], 6, 0, iface)
    assert obs["agvs"].shape[0] == 6 and present.sum(axis=1).tolist() == [3 + 2] * 6
    assert not actions[~present].any()
    env = gym.make("lawn/Comm-v1", config=configs[0])
    o, _ = env.reset(seed=0)
    expert = make_policy("rg-mpc", configs[0], env_id="lawn/Comm-v1")
    expert.reset(seed=0)
    snap = env.unwrapped.snapshot()
    want = expert.actions.decode(expert.act(o), snap.x_aug, snap.reference, snap.drone_position, snap.slot)
    layout = EntityLayout(configs[0], "comm", 10.0)
    scheme = action_codec(configs[0], "comm", iface)
    got = scheme.decode(layout.to_flat_actions(actions[0]).astype(float), snap.x_aug, snap.reference,
                        snap.drone_position, snap.slot)
    np.testing.assert_allclose(got.power_w, want.power_w, rtol=1e-4)

    model = _model(_env("lawn/Comm-v1", 4))
    data = dagger_round(None, "lawn/Comm-v1", configs, 12, 0, iface)
    losses = fit_fleet(model, *data, epochs=5, batch_size=8, learning_rate=3e-3, seed=0)
    assert losses[-1] < 0.5 * losses[0]
    more = dagger_round(model, "lawn/Comm-v1", configs, 6, 50, iface)
    assert more[0]["agvs"].shape[0] == 12 and set(more[0]["mask"].sum(axis=1).tolist()) == {3.0, 4.0}


def test_lawn_train_fleet_runs_dagger_and_its_network_drives_any_k(tmp_path):
    """``train("fleet", ...)``: a tiny DAgger run on K = 3 and 4 writes a run that ``sb3:DIR`` loads
    and that drives the unmodified v0 env at K = 8; a bad hyperparameter is named."""
    from agents import make_policy, rollout
    from lawn_env import presets
    from training.spec import TrainSpec
    from training.train import train

    config = presets.get("default").override(num_agvs=4, num_slots=8)
    hp = {"fleet_sizes": [3, 4], "epochs": 2, "dagger_iterations": 1, "dagger_timesteps": 8, "width": 16, "heads": 2}
    summary = train(TrainSpec(algo="fleet", env_id="lawn/Comm-v1", config=config, timesteps=16, seed=0, out_dir=tmp_path / "run", hp_overrides=hp, eval_episodes=1, progress=False))
    assert summary.bc_loss_last < summary.bc_loss_first
    assert 0 < summary.expert_share < 1  # rg-mpc labels every state of every round
    wide = config.override(num_agvs=8)
    policy = make_policy(f"sb3:{tmp_path / 'run'}", wide, env_id="lawn/Comm-v1")
    run = rollout(gym.make("lawn/Comm-v1", config=wide), policy, seed=3)
    assert run.metrics["slots"] == 8 and np.isfinite(run.metrics["control_cost"])
    with pytest.raises(ValueError, match="unknown fleet hyperparameters"):
        train(TrainSpec(algo="fleet", env_id="lawn/Comm-v1", config=config, timesteps=16, seed=0, out_dir=tmp_path / "bad", hp_overrides={"width_": 8}, progress=False))
    assert not (tmp_path / "bad").exists()  # nothing written


def test_each_agent_of_the_multi_agent_env_gets_its_own_row_of_one_network():
    """In the multi-agent entity layout the shared network gives each agent its own row of the
    fleet network's action (the drone its move, padded) and its own token's value; permuting the
    AGVs permutes the agents' actions; the compiled copy gives every row at once."""
    import torch

    import lawn_env
    from agents.fleet import FleetInference
    from training.sb3 import make_marl_vec_env

    k = 4
    venv = make_marl_vec_env(lawn_env.ScenarioConfig(num_agvs=k), 1, 0, interface={"base": "rl", "layout": "entities"})
    model = PPO(FleetPolicy, venv, n_steps=16, batch_size=16, policy_kwargs=dict(width=16, heads=2, layers=1))
    obs = venv.reset()
    rng = np.random.default_rng(0)
    with torch.no_grad():
        for param in model.policy.parameters():
            param.add_(torch.as_tensor(rng.normal(0, 0.3, tuple(param.shape)), dtype=param.dtype))
    actions, _ = model.predict(obs, deterministic=True)  # (K + 1, 3): the drone, then agv_0..agv_3
    full = FleetInference(model.policy)({key: value[0] for key, value in obs.items()})
    rows, drone = _rows(np.clip(full, -1, 1), 3)  # predict clips to the action space
    np.testing.assert_allclose(actions[0, :2], drone, atol=1e-5)
    assert actions[0, 2] == 0.0
    np.testing.assert_allclose(actions[1:], rows[:k], atol=1e-5)
    perm = np.array([2, 0, 3, 1])
    shuffled = {key: value.copy() for key, value in obs.items()}
    shuffled["agvs"][:, :k] = obs["agvs"][:, perm]
    again, _ = model.predict(shuffled, deterministic=True)
    np.testing.assert_allclose(again[1:], actions[1:][perm], atol=1e-5)
    values = model.policy.predict_values(model.policy.obs_to_tensor(obs)[0]).detach().numpy()[:, 0]
    assert len(set(np.round(values, 6))) == k + 1  # each agent's own token
    from training.sb3 import start_at_anchor

    start_at_anchor(model, "ppo")  # the heads zeroed: every agent's action is its anchor's (zero)
    assert not model.predict(obs, deterministic=True)[0].any()
    venv.close()


def test_multi_agent_ppo_trains_the_fleet_network_and_drives_any_k(tmp_path):
    """``lawn train --algo ppo --env lawn/Parallel-v0`` with ``policy: FleetPolicy`` in the entity
    layout: started at the anchor (its heads zeroed), it trains at K = 3 and its network drives
    the unmodified ``lawn/Joint-v1`` at K = 6 (``marl:DIR``)."""
    from agents import make_policy, rollout
    from lawn_env import presets
    from training.spec import TrainSpec
    from training.train import train

    config = presets.get("default").override(num_agvs=3, num_slots=8)
    hp = {"interface": {"base": "rl", "layout": "entities"}, "policy": "FleetPolicy", "normalize": False,
          "start_at_anchor": True, "n_envs": 1, "n_steps": 16, "batch_size": 32,
          "policy_kwargs": {"width": 16, "heads": 2, "layers": 1}}
    train(TrainSpec(algo="ppo", env_id="lawn/Parallel-v0", config=config, timesteps=64, seed=0, out_dir=tmp_path / "run", hp_overrides=hp, eval_episodes=1, progress=False))
    wide = config.override(num_agvs=6)
    policy = make_policy(f"marl:{tmp_path / 'run'}", wide, env_id="lawn/Joint-v1")
    run = rollout(gym.make("lawn/Joint-v1", config=wide), policy, seed=3)
    assert run.metrics["slots"] == 8 and np.isfinite(run.metrics["control_cost"])
    with pytest.raises(ValueError, match="ppo or a2c"):
        train(TrainSpec(algo="sac", env_id="lawn/Comm-v1", config=config, timesteps=64, seed=0, out_dir=tmp_path / "bad", hp_overrides={"policy": "FleetPolicy"}, progress=False))
    assert not (tmp_path / "bad").exists()


def test_the_zoo_builds_the_fleet_section_alone_and_the_table_over_fleet_sizes(tmp_path, monkeypatch):
    """``lawn zoo build --only fleet-comm``: the fleet section's block is rebuilt, the rest of the
    page and the other runs' recorded episodes are kept, the agent is exported (a fleet network:
    agent.json says so and zoo:NAME loads it); the table over fleet sizes runs it beside rg-mpc
    and the noise floor at every size."""
    import dataclasses

    import training.recipes as recipes_module
    from agents import learned, make_policy
    from evaluation.episode import Play, read_csv
    from evaluation.protocols import execute, fleet_agents, fleet_protocol
    from lawn_env import ScenarioConfig, presets
    from paper import learned as learned_page
    from training.spec import TrainSpec
    from training.train import train

    tiny = dataclasses.replace(recipes_module.RECIPES["fleet-comm"], timesteps=16)
    monkeypatch.setitem(recipes_module.RECIPES, "fleet-comm", tiny)
    runs, docs = tmp_path / "runs", tmp_path / "docs"
    hp = {"fleet_sizes": [3, 4], "epochs": 1, "dagger_iterations": 0, "width": 16, "heads": 2}
    train(TrainSpec(algo="fleet", env_id="lawn/Comm-v1", config=ScenarioConfig(), timesteps=16, seed=0, out_dir=runs / "fleet-comm" / "seed-0", hp_overrides=hp, eval_episodes=1, progress=False))
    (docs / "learned").mkdir(parents=True)
    page = "# Learned\n\nkept\n\n<!-- zoo-fleet:begin -->\nold\n<!-- zoo-fleet:end -->\n\nkept too\n"
    (docs / "LEARNED.md").write_text(page)
    other = {"policy": "bc:runs/agents/bc-comm/seed-0", "env": "lawn/Comm-v1", "seed": "0", "control_cost": "1.0"}
    (docs / "learned" / "episodes.csv").write_text(",".join(other) + "\n" + ",".join(other.values()) + "\n")
    table = learned_page.build_zoo(runs, docs / "LEARNED.md", workers=1, progress=False, episodes=2, target=tmp_path / "zoo",
                          only=["fleet-comm"])
    text = (docs / "LEARNED.md").read_text()
    assert text.startswith("# Learned\n\nkept\n") and text.endswith("<!-- zoo-fleet:end -->\n\nkept too\n")
    assert "old" not in text and "`zoo:fleet-comm`, seed 0" in text and "lawn zoo build --only fleet-comm" in text
    assert "`zoo:fleet-comm`" in table
    rows = read_csv(docs / "learned" / "episodes.csv")
    assert rows[0]["policy"] == other["policy"] and any("/fleet-comm/seed-0" in r["policy"] for r in rows)
    record = json.loads((tmp_path / "zoo" / "fleet-comm" / "agent.json").read_text())
    assert record["algo"] == "fleet" and record["interface"]["layout"] == "entities"
    assert record["selected_at_steps"] == int(read_csv(runs / "fleet-comm" / "seed-0" / "learning_curve.csv")[-1]
                                              ["timesteps"])  # a clone: its one validation, after the fit
    with pytest.raises(ValueError, match="unknown recipe 'nope'"):
        learned_page.build_zoo(runs, docs / "LEARNED.md", only=["nope"])

    monkeypatch.setattr(learned, "ZOO_DIR", tmp_path / "zoo")
    assert fleet_agents() == ["zoo:fleet-comm"]
    policy = make_policy("zoo:fleet-comm", ScenarioConfig(num_agvs=7), env_id="lawn/Comm-v1")
    assert policy.entities.num_agvs == 7
    sizes = {3: 2, 5: 2}
    outcome = execute(fleet_protocol(fleet_agents(), sizes, base=presets.get("default").override(num_slots=6)),
                      Play(1, False))
    rows = outcome.results
    assert {(r.policy, r.task) for r in rows} == {(p, f"k{k}") for p in ("dv-mpc", "noise:dv-mpc", "zoo:fleet-comm")
                                                  for k in sizes}
    text = outcome.tables["fleet_sizes.md"]
    assert text.startswith("Test seeds S..S+n-1 of each range S = 0, 100000, n per fleet size (K = 3: 2, K = 5: 2)")
    lines = [line for line in text.splitlines() if line.startswith("| zoo:fleet-comm")]
    assert [line.split(" | ")[2] for line in lines] == ["3", "5"] and all("×" in line for line in lines)
    assert [line.split(" | ")[3] for line in lines] == ["4", "4"]  # two seeds of each of the two test ranges
    assert "reported" in lines[1] and (": met" in lines[0] or ": missed" in lines[0])  # K = 5 has no target
    assert sum(line.startswith("| noise:dv-mpc") for line in text.splitlines()) == 2


def test_a_multi_agent_fleet_run_ships_to_the_zoo_and_a_flat_policy_is_refused(tmp_path, monkeypatch):
    """The zoo exports a multi-agent fleet network as a fleet network (its own class loads it) and
    ``zoo:NAME`` drives lawn/Joint-v1 with it at another K; the multi-agent entity layout refuses a
    policy other than FleetPolicy before anything is written."""
    from agents import learned, make_policy
    from lawn_env import presets
    from training.spec import TrainSpec
    from training.train import train

    config = presets.get("default").override(num_agvs=3, num_slots=6)
    hp = {"interface": {"base": "rl", "layout": "entities"}, "policy": "FleetPolicy", "normalize": False,
          "n_envs": 1, "n_steps": 16, "batch_size": 32, "policy_kwargs": {"width": 16, "heads": 2, "layers": 1}}
    train(TrainSpec(algo="ppo", env_id="lawn/Parallel-v0", config=config, timesteps=32, seed=0, out_dir=tmp_path / "run", hp_overrides=hp, eval_episodes=1, progress=False))
    monkeypatch.setattr(learned, "ZOO_DIR", tmp_path / "zoo")
    learned.export_agent(tmp_path / "run", tmp_path / "zoo" / "marl-fleet", {"label": "tiny", "name": "marl-fleet",
                                                                              "evaluated_on": "lawn/Joint-v1"})
    record = json.loads((tmp_path / "zoo" / "marl-fleet" / "agent.json").read_text())
    assert record["algo"] == "fleet" and record["trainer"] == "ppo"  # a fleet network, trained by PPO
    wide = config.override(num_agvs=5)
    policy = make_policy("zoo:marl-fleet", wide, env_id="lawn/Joint-v1")
    obs, _ = gym.make("lawn/Joint-v1", config=wide).reset(seed=0)
    assert policy.entities.num_agvs == 5 and policy.act(obs).shape == (17,)
    with pytest.raises(ValueError, match="policy=FleetPolicy"):
        train(TrainSpec(algo="ppo", env_id="lawn/Parallel-v0", config=config, timesteps=32, seed=0, out_dir=tmp_path / "flat", progress=False, hp_overrides={**hp, "policy": "MultiInputPolicy"}))
    assert not (tmp_path / "flat").exists()


def test_the_suite_writes_the_table_over_fleet_sizes_for_the_shipped_fleet_networks(tmp_path):
    """``lawn benchmark --suite`` with a fleet network among the policies: every fleet size of the
    table (``--episodes`` caps its seeds), written beside the suite's files; with ``--docs`` a page
    without the block is refused before anything runs."""
    from evaluation.episode import Play, read_csv
    from evaluation.protocols import FLEET_SIZES, execute, fleet_protocol
    from evaluation.seeds import TEST_RANGES
    from lawn_cli import main

    sizes = dict.fromkeys(FLEET_SIZES, 1)  # what --episodes 1 caps them to
    block = execute(fleet_protocol(["zoo:fleet-comm"], sizes), Play(1, False), tmp_path).tables["fleet_sizes.md"]
    rows = read_csv(tmp_path / "fleet_sizes.csv")
    assert {r["task"] for r in rows if r["policy"] == "zoo:fleet-comm"} == {f"k{k}" for k in FLEET_SIZES}
    assert {r["seed"] for r in rows} == {str(base) for base in TEST_RANGES}  # the first seed of each test range
    assert block.count("| zoo:fleet-comm |") == len(FLEET_SIZES) and (tmp_path / "fleet_sizes.md").exists()
    (tmp_path / "docs").mkdir()
    assert main(["benchmark", "--suite", "--docs", str(tmp_path / "docs"), "--policies", "zoo:fleet-comm",
                 "--episodes", "1", "--out", str(tmp_path / "suite"), "--quiet"]) == 2
    assert not any((tmp_path / "suite").iterdir())  # the checked, empty --out folder: nothing was run


def test_the_zoo_builds_the_distil_section_on_two_test_ranges(tmp_path, monkeypatch):
    """``lawn zoo build --only dv-joint``: a network cloned from dv-mpc on two tasks is compared on
    each against dv-mpc and rg-mpc on seeds of both test ranges, exported with those figures, and
    acts at each task's K; a Comm agent refuses a scenario with another control law."""
    import dataclasses

    import training.recipes as recipes_module
    from agents import learned, make_policy
    from agents.runs import AgentRecord
    from evaluation.episode import read_csv
    from evaluation.seeds import TEST_RANGES
    from lawn_env import presets
    from paper import learned as learned_page
    from training import zoo
    from training.spec import TrainSpec
    from training.train import train

    hp = {"expert": "dv-mpc", "tasks": ["steady", "wide-k8"], "epochs": 1, "dagger_iterations": 0, "width": 16,
          "heads": 2, "interface": recipes_module.RECIPES["dv-joint"].hp["interface"],
          "task_settings": {"control.law": "delivery-certainty-equivalent"}}
    tiny = dataclasses.replace(recipes_module.RECIPES["dv-joint"], timesteps=16, hp=hp)
    monkeypatch.setitem(recipes_module.RECIPES, "dv-joint", tiny)
    runs, docs = tmp_path / "runs", tmp_path / "docs"
    train(TrainSpec(algo="fleet", env_id="lawn/Joint-v1", config=tiny.config, timesteps=16, seed=0,
                    out_dir=runs / "dv-joint" / "seed-0", hp_overrides=hp, eval_episodes=1, progress=False))
    docs.mkdir()
    (docs / "LEARNED.md").write_text("# Learned\n\n<!-- zoo-distil:begin -->\nold\n<!-- zoo-distil:end -->\n")
    residual = recipes_module.RECIPES["ppo-dv-residual"]  # an RL run of the section: its curve beside the table
    rl_hp = {**residual.hp, "n_envs": 1, "n_steps": 64, "batch_size": 64, "n_epochs": 1}
    small_rl = dataclasses.replace(residual, timesteps=64, seeds=(0,), hp=rl_hp)
    monkeypatch.setitem(recipes_module.RECIPES, "ppo-dv-residual", small_rl)
    train(TrainSpec(algo="ppo", env_id="lawn/Joint-v1", config=small_rl.config, timesteps=64, seed=0, eval_every=64,
                    out_dir=runs / "ppo-dv-residual" / "seed-0", hp_overrides=rl_hp, eval_episodes=1, progress=False))
    table = learned_page.build_zoo(runs, docs / "LEARNED.md", workers=1, progress=False, episodes=1, target=tmp_path / "zoo",
                          only=["dv-joint", "ppo-dv-residual"])
    rl = [line for line in table.splitlines() if line.startswith("| `zoo:ppo-dv-residual`")]
    assert len(rl) == 1 and rl[0].split(" | ")[2] == "steady" and rl[0].endswith("| – |")  # no clone target
    assert "`ppo-dv-residual` (seed-0, shipped;" in table and "| 64 |" in table  # the learning curve
    record = json.loads((tmp_path / "zoo" / "ppo-dv-residual" / "agent.json").read_text())
    assert record["residual"]["anchor"] == "dv-mpc"
    assert record["selected_at_steps"] == 0  # one validation episode: no interval, so no step beats the start
    monkeypatch.setattr(zoo, "zoo_agents", lambda: {"ppo-dv-residual": AgentRecord.model_validate(record)})
    assert "ships its start: no validation beat the policy it started from" in zoo.format_zoo_list()
    lines = [line for line in table.splitlines() if line.startswith("| `zoo:dv-joint`")]
    assert [line.split(" | ")[2] for line in lines] == ["steady", "wide-k8"]
    assert all(line.split(" | ")[3] == "2" and line.endswith(("| met |", "| missed |")) for line in lines)
    assert "old" not in (docs / "LEARNED.md").read_text()
    rows = read_csv(docs / "learned" / "distil.csv")
    assert {int(r["seed"]) for r in rows} == set(TEST_RANGES)
    assert {r["policy"] for r in rows} == {"dv-mpc", "rg-mpc", f"sb3:{runs / 'dv-joint' / 'seed-0'}",
                                           f"sb3:{runs / 'ppo-dv-residual' / 'seed-0'}"}
    record = json.loads((tmp_path / "zoo" / "dv-joint" / "agent.json").read_text())
    assert set(record["benchmark"]["tasks"]) == {"steady", "wide-k8"}
    assert all(len(v) == 2 for per in record["benchmark"]["tasks"].values() for v in per.values())  # per range
    monkeypatch.setattr(learned, "ZOO_DIR", tmp_path / "zoo")
    delivery = {"control.law": "delivery-certainty-equivalent"}
    assert make_policy("zoo:dv-joint", presets.get("wide-k8").override(delivery)).entities.num_agvs == 8
    with pytest.raises(ValueError, match="zoo:dv-joint was trained on lawn/Joint-v1 with "
                                         "control.law='delivery-certainty-equivalent'"):
        make_policy("zoo:dv-joint", presets.get("wide-k8"))  # its MPC increment anchor plans by the law
    from evaluation.protocols import fleet_agents

    assert "zoo:dv-joint" not in fleet_agents()  # the fleet-size table is for the default-scenario networks
    with pytest.raises(ValueError, match="control.law='delivery'.*control.law='paper'"):
        learned.check_scenario("zoo:x", "lawn/Comm-v1", presets.get("steady").override({"control.law": "delivery"}),
                               presets.get("steady"))


def test_lawn_benchmark_protocol_fleet_plays_named_networks_on_chosen_sizes(tmp_path, capsys):
    """``lawn benchmark --protocol fleet``: the named networks beside dv-mpc and its noise floor at each
    of --sizes, --episodes seeds of each test range; a network that cannot act at a size, sizes without
    the protocol and two protocols at once are refused before any episode."""
    pytest.importorskip("stable_baselines3")
    from evaluation.episode import read_results
    from lawn_cli import main

    out = tmp_path / "fleet"
    assert main(["benchmark", "--protocol", "fleet", "--policies", "zoo:fleet-comm", "--sizes", "3", "--episodes", "1",
                 "--workers", "1", "--quiet", "--out", str(out)]) == 0
    rows = read_results(out / "fleet_sizes.csv")
    assert {(r.policy, r.task) for r in rows} == {(p, "k3") for p in ("dv-mpc", "noise:dv-mpc", "zoo:fleet-comm")}
    assert sorted({r.seed for r in rows}) == [0, 100_000]
    assert "| zoo:fleet-comm | lawn/Comm-v1 | 3 | 2 |" in (out / "fleet_sizes.md").read_text()
    capsys.readouterr()
    cases = [(["--protocol", "fleet", "--policies", "zoo:ppo-comm", "--sizes", "3"], "zoo:ppo-comm cannot act with 3 AGVs"),
             (["--sizes", "3"], "--sizes 3: fleet sizes belong to --protocol fleet"),
             (["--suite", "--protocol", "fleet"], "--suite and --protocol fleet are two protocols")]
    for flags, message in cases:
        assert main(["benchmark", *flags, "--quiet", "--out", str(tmp_path / "refused")]) == 2, flags
        assert message in capsys.readouterr().err, flags
    assert not (tmp_path / "refused").exists() or not any((tmp_path / "refused").iterdir())
