"""The benchmark protocol: anchors, the normalized score, the learned protocol, the task suite,
Minari datasets and behaviour cloning from them."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil

import gymnasium as gym
import numpy as np
import pytest

from agents import ANCHORS, AnchorPolicy, anchor_name, make_policy
from evaluation.episode import EpisodeResult
from evaluation.run import run_episode
from evaluation.stats import normalized_score, scores_by_policy
from lawn_env import ScenarioConfig, presets
from paper.pages import ROOT, first_table


# ---------------------------------------------------------------------- normalized score
def _rows(policy, costs, env="lawn/Joint-v1", task="default"):
    return [EpisodeResult(policy, env, s, control_cost=c, task=task) for s, c in costs.items()]


def test_score_is_zero_at_epa_and_one_hundred_at_rg_mpc():
    epa = {0: 900.0, 1: 1500.0, 2: 700.0, 3: 1200.0}
    rg = {0: 400.0, 1: 500.0, 2: 450.0, 3: 600.0}
    for version in (2, 3):
        assert normalized_score(epa, epa, rg, version=version)[0] == 0.0
        assert normalized_score(rg, epa, rg, version=version)[0] == pytest.approx(100.0, abs=1e-12)
    # v2, on cost: halfway on every seed is 50; the mean gap (not a per-seed ratio) is the denominator
    half = {s: (epa[s] + rg[s]) / 2 for s in epa}
    assert normalized_score(half, epa, rg, version=2)[0] == pytest.approx(50.0, abs=1e-12)
    better = {s: rg[s] - 0.1 * (epa[s] - rg[s]) for s in epa}
    assert normalized_score(better, epa, rg, version=2)[0] == pytest.approx(110.0, abs=1e-9)
    gap = np.mean([epa[s] - rg[s] for s in epa])
    odd = {0: 650.0, 1: 1500.0, 2: 700.0, 3: 1200.0}  # only seed 0 moves
    assert normalized_score(odd, epa, rg, version=2)[0] == pytest.approx(100 * 250.0 / 4 / gap)
    # v3, on log cost: the geometric midpoint on every seed is 50
    geometric = {s: math.sqrt(epa[s] * rg[s]) for s in epa}
    assert normalized_score(geometric, epa, rg)[0] == pytest.approx(50.0, abs=1e-9)


def test_the_log_score_is_not_squashed_by_a_diverged_reference():
    """One EPA episode at 1e7 (a diverged AGV) leaves v2 with every other policy near 100 whatever it
    costs; v3 on log cost keeps a policy at twice the expert's cost well apart from the expert."""
    epa = {0: 900.0, 1: 1500.0, 2: 1e7, 3: 1200.0}
    expert = {0: 400.0, 1: 500.0, 2: 450.0, 3: 600.0}
    twice = {s: 2 * c for s, c in expert.items()}
    assert normalized_score(twice, epa, expert, version=2)[0] > 99.9
    assert normalized_score(twice, epa, expert)[0] < 80.0
    with pytest.raises(ValueError, match=r"log costs: every cost must be > 0"):
        normalized_score({0: 0.0}, {0: 2.0}, {0: 1.0})


def test_score_interval_brackets_the_mean_and_is_seeded():
    rng = np.random.default_rng(3)
    epa = {s: float(v) for s, v in enumerate(rng.uniform(800, 2000, 30))}
    rg = {s: float(v) for s, v in enumerate(rng.uniform(300, 600, 30))}
    x = {s: rg[s] * float(rng.uniform(0.9, 1.4)) for s in rg}
    score, lo, hi, n = normalized_score(x, epa, rg)
    assert n == 30 and lo < score < hi
    assert normalized_score(x, epa, rg) == (score, lo, hi, n)
    assert math.isnan(normalized_score({0: 1.0, 1: 2.0}, {0: 3.0, 1: 4.0}, {0: 1.0, 1: 1.0})[1])


def test_score_needs_references_that_separate_and_shared_seeds():
    with pytest.raises(ValueError, match="do not separate"):
        normalized_score({0: 5.0, 1: 5.0}, {0: 1.0, 1: 2.0}, {0: 3.0, 1: 3.0})
    with pytest.raises(ValueError, match="no seed holds"):
        normalized_score({7: 5.0}, {0: 1.0}, {0: 0.5})


def test_scores_by_policy_pairs_within_task_and_env():
    rows = (_rows("epa", {0: 100.0, 1: 400.0}) + _rows("dv-mpc", {0: 1.0, 1: 4.0}) + _rows("x", {0: 10.0, 1: 40.0})
            + _rows("epa", {0: 100.0, 1: 100.0}, task="k8") + _rows("dv-mpc", {0: 50.0, 1: 50.0}, task="k8")
            + _rows("x", {0: 50.0, 1: 50.0}, task="k8") + _rows("y", {0: 1.0}, env="lawn/Comm-v1"))
    scores = scores_by_policy(rows)
    assert scores[("default", "lawn/Joint-v1", "x")][0] == pytest.approx(50.0)
    assert scores[("k8", "lawn/Joint-v1", "x")][0] == pytest.approx(100.0)
    assert ("default", "lawn/Comm-v1", "y") not in scores  # no references on that env
    # references that do not separate give no score instead of an error mid-table
    rows = _rows("epa", {0: 1.0, 1: 1.0}, task="t") + _rows("dv-mpc", {0: 2.0, 1: 2.0}, task="t")
    assert scores_by_policy(rows) == {}


def test_earlier_scores_stay_computable_beside_v3():
    """v3 puts 100 at dv-mpc on log cost; v2 (100 at dv-mpc-ce, dv-mpc before its loss-aware tail) and
    v1 (at rg-mpc), both on cost, are computed from the same rows when they hold their references."""
    from evaluation.stats import SCORE_REFERENCES, SCORE_SCALES, SCORE_VERSION

    assert SCORE_VERSION == 3 and SCORE_REFERENCES == {1: ("epa", "rg-mpc"), 2: ("epa", "dv-mpc-ce"),
                                                        3: ("epa", "dv-mpc")}
    assert SCORE_SCALES == {1: "cost", 2: "cost", 3: "log cost"}
    rows = (_rows("epa", {0: 10.0, 1: 12.0}) + _rows("rg-mpc", {0: 6.0, 1: 8.0}) + _rows("dv-mpc-ce", {0: 4.0, 1: 6.0})
            + _rows("dv-mpc", {0: 4.0, 1: 6.0}) + _rows("x", {0: 7.0, 1: 9.0}))
    v1, v2, v3 = (scores_by_policy(rows, version=v) for v in (1, 2, 3))
    assert v1[("default", "lawn/Joint-v1", "x")][0] == pytest.approx(75.0)
    assert v2[("default", "lawn/Joint-v1", "x")][0] == pytest.approx(50.0)
    logs = {p: np.log([c for c in costs]) for p, costs in
            {"epa": (10.0, 12.0), "dv-mpc": (4.0, 6.0), "x": (7.0, 9.0)}.items()}
    expected = 100 * (logs["epa"] - logs["x"]).mean() / (logs["epa"] - logs["dv-mpc"]).mean()
    assert v3[("default", "lawn/Joint-v1", "x")][0] == pytest.approx(expected)
    assert v1[("default", "lawn/Joint-v1", "dv-mpc")][0] == pytest.approx(150.0)
    with pytest.raises(ValueError, match=r"score version=4; valid: 1, 2, 3"):
        scores_by_policy(rows, version=4)
    with pytest.raises(ValueError, match=r"run epa and rg-mpc on the same seeds"):
        normalized_score({5: 1.0}, {0: 1.0}, {0: 0.5}, references=SCORE_REFERENCES[1])


# ---------------------------------------------------------------------- anchors
def _zero_action_cost(env_id, interface, seed):
    """The zero action stepped directly through the interface (no policy, no v0 carry), full episode."""
    iface = None if interface is None else {**interface, "reward": "cost", "termination_distance_m": None}
    env = gym.make(env_id, interface=iface)
    env.reset(seed=seed)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(zero)
        done = terminated or truncated
    return info["episode_metrics"]["control_cost"]


@pytest.mark.parametrize("env_id", ["lawn/Comm-v1", "lawn/Joint-v1"])
@pytest.mark.parametrize("name", list(ANCHORS))
def test_anchor_rows_equal_a_direct_rollout_of_the_zero_action(env_id, name):
    seed = 4
    direct = _zero_action_cost(env_id, ANCHORS[name], seed)
    row = run_episode(f"anchor:{name}", env_id, ScenarioConfig(), seed)
    # the policy hands the env the float32 v0 action that carries out the zero action
    assert row.control_cost == pytest.approx(direct, rel=1e-6)
    assert row.policy == f"anchor:{name}"


def test_anchor_names_and_errors():
    assert anchor_name(None) == "anchor:hover"
    assert anchor_name("rl") == "anchor:stake"
    assert anchor_name({"base": "rl", "power_anchor": "distance", "drone_offset_m": 10.0}) == "anchor:distance"
    assert anchor_name({"base": "rl", "power_anchor": "distance", "increment_anchor": "lqr"}) == "anchor:distance-lqr"
    assert isinstance(make_policy("anchor:stake", env_id="lawn/Comm-v1"), AnchorPolicy)
    with pytest.raises(ValueError, match="unknown anchor 'nope'; valid: hover, distance, stake"):
        make_policy("anchor:nope")
    with pytest.raises(ValueError, match="takes no settings"):
        make_policy("anchor:stake", tolerance=1.0)


# ---------------------------------------------------------------------- the learned protocol
def test_learned_protocol_has_the_anchor_rows_and_columns(tmp_path):
    pytest.importorskip("stable_baselines3")
    from evaluation.cells import fmt_geometric, fmt_paired
    from evaluation.episode import Entry, Play, read_results
    from evaluation.protocols import execute, learned_protocol
    from evaluation.run import learned_entries, own_anchor
    from evaluation.stats import costs_of, paired_difference, paired_geometric

    agents = ["zoo:ppo-comm", "zoo:bc-comm", "zoo:ppo-comm"]
    anchors = sorted({own_anchor(a) for a in agents})
    assert all(a.startswith("anchor:") for a in anchors)
    entries = learned_entries(agents)  # a repeated agent is one row
    assert entries == [("dv-mpc", "lawn/Comm-v1", None), ("epa", "lawn/Comm-v1", None),
                       *[(a, "lawn/Comm-v1", None) for a in anchors],
                       Entry("zoo:ppo-comm", "lawn/Comm-v1", own_anchor("zoo:ppo-comm")),
                       Entry("zoo:bc-comm", "lawn/Comm-v1", own_anchor("zoo:bc-comm"))]
    with pytest.raises(ValueError, match="unknown zoo agent 'nope'"):
        learned_protocol(["zoo:nope"], episodes=3)  # a bad name fails before any episode
    protocol = learned_protocol(["zoo:ppo-comm"], episodes=3)
    assert protocol.entries == learned_entries(["zoo:ppo-comm"]) and protocol.tables == {"summary.md": "learned"}
    table = execute(protocol, Play(1, False), tmp_path).tables["summary.md"]
    assert (tmp_path / "summary.md").read_text().strip() == table.strip()
    lines = table.splitlines()
    assert "vs own anchor (paired mean)" in lines[0] and "vs own anchor (geometric" in lines[0] and "score v3" in lines[0]
    agent = next(line for line in lines if line.startswith("| zoo:ppo-comm "))
    anchor = own_anchor("zoo:ppo-comm")
    assert f"| {anchor} |" in agent
    rows = read_results(tmp_path / "episodes.csv")
    diff = paired_difference(costs_of(rows, "zoo:ppo-comm", "lawn/Comm-v1"), costs_of(rows, anchor, "lawn/Comm-v1"))
    assert fmt_paired(*diff[:2]) in agent.split("|")[11]
    geo = paired_geometric(costs_of(rows, "zoo:ppo-comm", "lawn/Comm-v1"), costs_of(rows, anchor, "lawn/Comm-v1"))
    assert agent.split("|")[9].strip() == fmt_geometric(geo)
    split = [r.transient_cost + r.sustained_cost - r.control_cost for r in rows]
    assert max(map(abs, split)) < 1e-6
    assert any(line.startswith("| anchor:stake | lawn/Comm-v1 |") for line in lines)
    assert any(line.startswith("| dv-mpc | lawn/Comm-v1 | – |") and "| 100.0 |" in line for line in lines)
    assert (tmp_path / "episodes.csv").exists() and "3 test seeds" in table


def test_model_selection_is_paired_against_rg_mpc_on_the_validation_seeds():
    from training.validation import selection_key, validation_row

    reference = {1: 100.0, 2: 1000.0}  # rg-mpc on two validation seeds, one of them hard
    a = validation_row({1: 110.0, 2: 1000.0}, reference)  # +10 % on the easy seed: +5 % paired, mean 555
    b = validation_row({1: 100.0, 2: 1080.0}, reference)  # +8 % on the hard seed: +4 % paired, mean 590
    assert a["vs_reference"] == pytest.approx(0.05) and b["vs_reference"] == pytest.approx(0.04)
    assert a["control_cost"] < b["control_cost"] and selection_key(b) < selection_key(a)
    assert selection_key({"timesteps": 0.0, "control_cost": 3.0, "control_cost_ci95": 1.0}) == 3.0  # older runs


def test_selection_keeps_the_start_unless_a_validation_beats_it_significantly():
    from training.validation import selected_validation, validation_row

    reference = {1: 100.0, 2: 100.0, 3: 100.0}
    start_costs = {1: 110.0, 2: 110.0, 3: 110.0}
    start = {"timesteps": 0, **validation_row(start_costs, reference, start_costs)}
    assert start["vs_start"] == 0.0 and start["vs_start_ci95"] == 0.0
    noisy = {"timesteps": 1, **validation_row({1: 90.0, 2: 130.0, 3: 95.0}, reference, start_costs)}
    better = {"timesteps": 2, **validation_row({1: 104.0, 2: 105.0, 3: 106.0}, reference, start_costs)}
    assert noisy["vs_reference"] < better["vs_reference"] < start["vs_reference"]  # noisy looks best on the mean
    assert noisy["vs_start"] + noisy["vs_start_ci95"] > 0 > better["vs_start"] + better["vs_start_ci95"]
    assert selected_validation([start, noisy]) is start  # the winner's curse is refused
    assert selected_validation([start, noisy, better]) is better
    bc_rows = [{"timesteps": 5, **validation_row({1: 120.0}, {1: 100.0})}, {"timesteps": 9, "control_cost": 101.0,
                                                                           "vs_reference": 0.01}]
    assert selected_validation(bc_rows) is bc_rows[1]  # no start to beat: the plain minimum
    assert selected_validation([]) is None


def test_the_geometric_rule_sees_a_gain_on_a_heavy_tailed_start_that_the_relative_mean_does_not():
    from training.validation import selected_validation, selection_key, validation_row

    reference = dict.fromkeys(range(20), 100.0)
    start_costs = {s: 10_000.0 if s < 5 else 100.0 for s in range(20)}  # five seeds where an AGV is lost
    learned = {s: 150.0 if s < 5 else 110.0 for s in range(20)}  # saves them, 10 % dearer on the others
    start = {"timesteps": 0, **validation_row(start_costs, reference, start_costs)}
    row = {"timesteps": 1, **validation_row(learned, reference, start_costs)}
    assert row["vs_start"] + row["vs_start_ci95"] > 0  # the relative mean's interval reaches past no change
    assert row["vs_start_geometric_high"] < 0 < row["vs_start_geometric_high"] + 1  # the geometric one does not
    assert row["vs_start_geometric"] == pytest.approx(np.exp(np.mean(np.log([150 / 1e4] * 5 + [1.1] * 15))) - 1)
    assert selected_validation([start, row]) is start
    assert selected_validation([start, row], "geometric") is row
    assert selection_key(row, "geometric") == row["vs_reference_geometric"] != selection_key(row)
    with pytest.raises(ValueError, match=r"'median'.*relative, geometric"):
        selected_validation([start], "median")


# ---------------------------------------------------------------------- the task suite
def test_suite_tasks_are_presets_with_their_own_scenarios():
    for suite in (presets.SUITE, presets.SUITE_V2, presets.SUITE_V1):
        configs = [presets.get(task) for task in suite]
        assert suite[0] == "default" and len(set(map(repr, configs))) == len(configs)
    assert presets.get("k8").num_agvs == 8 and presets.get("k3").num_agvs == 3
    assert presets.get("imperfect-csi").channel.ce_error_var > 0
    assert presets.get("short-blocklength").channel.blocklength < ScenarioConfig().channel.blocklength
    assert presets.get("low-power").power_budget_dbw < ScenarioConfig().power_budget_dbw
    env = gym.make("lawn/Comm-v1", config="k8")
    assert env.unwrapped.config.num_agvs == 8 and env.spec.kwargs == {"config": "k8"}


def test_every_suite_task_runs_and_learned_agents_report_where_they_cannot_act(tmp_path):
    pytest.importorskip("stable_baselines3")
    from evaluation.episode import Play
    from evaluation.protocols import execute, suite_protocol

    policies = ["anchor:stake", "zoo:ppo-comm"]
    tasks = ["default", "wide-k8"]
    protocol = suite_protocol(policies, tasks, 1)
    outcome = execute(protocol, Play(1, False), tmp_path)
    rows, skipped = outcome.results, protocol.skipped
    assert {r.task for r in rows} == set(tasks)
    assert {r.policy for r in rows} >= {"dv-mpc", "epa", "noise:dv-mpc", "limit:fast-drone", "limit:perfect-links"}
    assert set(skipped) == {("wide-k8", "zoo:ppo-comm")}
    assert skipped[("wide-k8", "zoo:ppo-comm")].startswith(
        "zoo:ppo-comm was trained on lawn/Comm-v1 with num_agvs=4 and acts only there; this scenario has num_agvs=8")
    board, refs = outcome.tables["board.md"], outcome.tables["references.md"]
    assert {p.name for p in tmp_path.iterdir()} == {"episodes.csv", "per_slot.csv", "board.md", "references.md",
                                                    "structure.md", "tasks.md", "per_slot.png"}
    agent = next(line for line in board.splitlines() if line.startswith("| zoo:ppo-comm"))
    assert agent.count("n/a") == 1 and "(1 task)" in agent
    assert all(f"| {task} |" in refs for task in tasks)
    per_slot = (tmp_path / "per_slot.csv").read_text().splitlines()
    assert per_slot[0].startswith("task,env,policy,slot,mean_stage_cost") and len(per_slot) > 120


# ---------------------------------------------------------------------- datasets
@pytest.fixture
def datasets_path(tmp_path, monkeypatch):
    pytest.importorskip("minari")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return tmp_path / "minari"


def test_dataset_round_trip_costs_equal_lawn_evaluate(datasets_path):
    import minari

    from training.datasets import create_dataset

    create_dataset("rg-mpc", "lawn/Comm-v1", episodes=2, seed=7, dataset_id="lawn/test/rg-mpc-v0", progress=False)
    dataset = minari.load_dataset("lawn/test/rg-mpc-v0")
    assert dataset.total_episodes == 2 and dataset.total_steps == 240
    episodes = list(dataset.iterate_episodes())
    for i, episode in enumerate(episodes):
        assert episode.observations.shape == (121, 335) and episode.actions.shape == (120, 6)
        assert episode.truncations[-1] and not episode.terminations.any()
        assert set(episode.infos) >= {"stage_cost", "delivered", "power_w", "drone_position"}
        expected = run_episode("rg-mpc", "lawn/Comm-v1", ScenarioConfig(), 7 + i).control_cost
        assert float(np.sum(episode.infos["stage_cost"][1:])) == pytest.approx(expected, rel=1e-12)
        assert float(-np.sum(episode.rewards)) == pytest.approx(expected, rel=1e-12)
    # Minari's normalized score is the package's score / 100 (epa and dv-mpc on the same seeds)
    from evaluation.stats import normalized_score

    costs = {p: {7 + i: run_episode(p, "lawn/Comm-v1", ScenarioConfig(), 7 + i).control_cost for i in range(2)}
             for p in ("epa", "dv-mpc")}
    returns = np.array([float(np.sum(e.rewards)) for e in episodes])
    recorded = {7 + i: -r for i, r in enumerate(returns)}
    assert minari.get_normalized_score(dataset, returns.mean()) == pytest.approx(
        normalized_score(recorded, costs["epa"], costs["dv-mpc"])[0] / 100, rel=1e-9)
    env = dataset.recover_environment()
    assert env.spec.id == "lawn/Comm-v1"
    obs, _ = env.reset(seed=7)
    np.testing.assert_array_equal(obs, episodes[0].observations[0])
    assert env.step(episodes[0].actions[0])[1] == pytest.approx(episodes[0].rewards[0])


def test_dataset_errors_name_the_problem(datasets_path):
    from training.datasets import create_dataset, load_dataset

    with pytest.raises(ValueError, match="datasets record lawn/Joint-v1 or lawn/Comm-v1"):
        create_dataset("rg-mpc", "lawn/CommRL-v1", 1, 0, "lawn/test/x-v0")
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        create_dataset("nope", "lawn/Comm-v1", 1, 0, "lawn/test/x-v0")
    with pytest.raises(ValueError, match="unknown dataset 'lawn/test/none-v0'"):
        load_dataset("lawn/test/none-v0")
    create_dataset("epa", "lawn/Joint-v1", 1, 0, "lawn/test/epa-v0", progress=False)
    with pytest.raises(ValueError, match="already exists"):
        create_dataset("epa", "lawn/Joint-v1", 1, 0, "lawn/test/epa-v0", progress=False)
    for bad in ("epa", "lawn/epa", "lawn/epa-v"):
        with pytest.raises(ValueError, match=f"--dataset-id '{bad}': Minari ids have the form NAMESPACE/NAME-vN"):
            create_dataset("epa", "lawn/Joint-v1", 1, 0, bad)


def test_bc_data_from_a_dataset_equals_live_labelling(datasets_path):
    from training.bc import collect
    from training.datasets import create_dataset, dataset_transitions

    create_dataset("rg-mpc", "lawn/Joint-v1", 2, 11, "lawn/test/live-v0", progress=False)
    cfg = ScenarioConfig()
    for interface in ("rl", {"base": "rl", "power_anchor": "distance"}, None):
        obs, labels, costs = collect("lawn/Joint-v1", cfg, "rg-mpc", 200, 11, interface)
        d_obs, d_labels, d_costs, seeds, recorded = dataset_transitions("lawn/test/live-v0", "lawn/Joint-v1", cfg, 200,
                                                                        interface)
        assert seeds == [11, 12] and obs.shape == (200, 335) and labels.shape == (200, 14) and recorded == "rg-mpc"
        np.testing.assert_array_equal(d_obs, obs)
        np.testing.assert_array_equal(d_labels, labels)
    assert d_costs[0] == pytest.approx(costs[0], rel=1e-12)
    with pytest.raises(ValueError, match="recorded with config 'default', not this run's scenario"):
        dataset_transitions("lawn/test/live-v0", "lawn/Joint-v1", presets.get("k3"), 10, "rl")


@pytest.mark.slow
def test_bc_from_a_dataset_is_the_clone_of_live_labelling(datasets_path, tmp_path):
    pytest.importorskip("stable_baselines3")
    import torch
    from stable_baselines3 import PPO

    from evaluation.seeds import TRAIN_SEED_BASE
    from training.datasets import create_dataset
    from training.spec import TrainSpec
    from training.train import train

    create_dataset("rg-mpc", "lawn/Comm-v1", 1, TRAIN_SEED_BASE, "lawn/test/bc-v0", progress=False)
    common = dict(algo="bc", env_id="lawn/Comm-v1", config=ScenarioConfig(), timesteps=120, seed=0,
                  hp_overrides={"epochs": 2}, progress=False)
    train(TrainSpec(out_dir=tmp_path / "live", **common))
    train(TrainSpec(out_dir=tmp_path / "data", dataset="lawn/test/bc-v0", **common))
    live = PPO.load(str(tmp_path / "live" / "model.zip")).policy.state_dict()
    data = PPO.load(str(tmp_path / "data" / "model.zip")).policy.state_dict()
    assert all(torch.equal(live[k], data[k]) for k in live)
    with pytest.raises(ValueError, match="holds episodes of lawn/Comm-v1; this run trains on lawn/Joint-v1"):
        train(TrainSpec(out_dir=tmp_path / "x", dataset="lawn/test/bc-v0", **{**common, "env_id": "lawn/Joint-v1"}))
    with pytest.raises(ValueError, match="only behaviour cloning"):
        TrainSpec(out_dir=tmp_path / "y", dataset="lawn/test/bc-v0", **{**common, "algo": "ppo"})


def test_zoo_build_tables_have_the_anchor_rows(tmp_path):
    pytest.importorskip("stable_baselines3")
    from paper.learned import build_zoo
    from training.recipes import RECIPES
    from training.spec import TrainSpec
    from training.train import train

    runs = tmp_path / "runs"
    (tmp_path / "docs").mkdir()
    shutil.copy2(ROOT / "docs" / "LEARNED.md", tmp_path / "docs" / "LEARNED.md")  # the page's blocks
    train(TrainSpec(algo="bc", env_id="lawn/Comm-v1", config=ScenarioConfig(), timesteps=120, seed=0, out_dir=runs / "bc-comm" / "seed-0", hp_overrides={"epochs": 1, "dagger_iterations": 0}, progress=False))
    table = build_zoo(runs, tmp_path / "docs" / "LEARNED.md", workers=1, progress=False, episodes=3,
                      target=tmp_path / "zoo")
    from evaluation.run import own_anchor

    anchor = own_anchor(f"bc:{runs / 'bc-comm' / 'seed-0'}")  # the hyperparameter file's interface: anchor:stake
    rows = table.splitlines()
    assert "vs own anchor (paired)" in rows[0] and "score v3" in rows[0]
    label = RECIPES["bc-comm"].label
    assert [r.split(" | ")[0] for r in rows[2:6]] == ["| dv-mpc", "| epa", f"| {anchor}",
                                                      f"| {label} (`zoo:bc-comm`, seed 0)"]
    assert rows[5].split(" | ")[3] == anchor
    doc = (tmp_path / "docs" / "LEARNED.md").read_text()
    assert f"| `bc-comm` (shipped) | 0 | {anchor} |" in doc and "3 test seeds (0-2)" in doc
    assert "| selected validation: vs rg-mpc (cost, episodes) |" in doc
    assert f"`dv-mpc` itself against each anchor (the \"vs own anchor\" of a perfect clone of the expert): `{anchor}` on " \
           "lawn/Comm-v1 " in table
    episodes = (tmp_path / "docs" / "learned" / "episodes.csv").read_text()
    assert anchor in episodes and "stage_costs" not in episodes.splitlines()[0]
    assert (tmp_path / "docs" / "learned" / "curves.png").stat().st_size > 5000
    record = json.loads((tmp_path / "zoo" / "bc-comm" / "agent.json").read_text())  # the export stage
    assert record["shipped_seed"] == 0 and record["benchmark"]["test_seeds"] == "0-2"
    assert record["benchmark"]["anchor"] == anchor and record["command"] == RECIPES["bc-comm"].command()


def test_zoo_stages_on_a_recorded_run(tmp_path):
    """The zoo's stages one by one: finished runs, evaluation, table rows, render, export."""
    pytest.importorskip("stable_baselines3")
    from training.recipes import RECIPES
    from training.spec import TrainSpec
    from training.train import train
    from training.zoo import evaluate_zoo, export_zoo, finished_runs, render_zoo, zoo_tables

    runs = tmp_path / "runs"
    with pytest.raises(ValueError, match="no finished recipe runs"):
        finished_runs(runs)
    tiny = {"bc-comm": dataclasses.replace(RECIPES["bc-comm"], seeds=(0, 1), timesteps=120)}
    for s in (0, 1):
        train(TrainSpec(algo="bc", env_id="lawn/Comm-v1", config=ScenarioConfig(), timesteps=120, seed=s, out_dir=runs / "bc-comm" / f"seed-{s}", hp_overrides={"epochs": 1, "dagger_iterations": 0}, progress=False))
    found = finished_runs(runs, tiny)
    assert [(r.name, [d.name for d in dirs]) for r, dirs in found] == [("bc-comm", ["seed-0", "seed-1"])]
    ev = evaluate_zoo(found, episodes=2, workers=1, progress=False)
    assert ev.envs == ["lawn/Comm-v1"] and {r.seed for r in ev.rows} == {0, 1}
    tables = zoo_tables(ev)
    assert [row["label"] for row in tables.recipe_rows][:2] == ["dv-mpc", "epa"]
    assert len(tables.run_rows) == 2 and sum("(shipped)" in row["recipe"] for row in tables.run_rows) == 1
    assert len(tables.shipped) == 1 and tables.shipped[0].run_dir in found[0][1]
    table, per_run = render_zoo(tables)
    assert table.count("\n| ") == len(tables.recipe_rows) and "2 test seeds (0-1)" in table  # the rows below the header
    assert per_run.count("\n") == len(tables.run_rows) + 1
    [exported] = export_zoo(tables, ev, tmp_path / "zoo")
    assert exported == tmp_path / "zoo" / "bc-comm" and (exported / "agent.json").exists()


# ---------------------------------------------------------------------- the command line
def test_evaluate_prints_the_score_beside_the_cost(tmp_path, capsys):
    from evaluation.episode import read_csv
    from lawn_cli import main

    out = tmp_path / "rows.csv"
    common = ["--episodes", "3", "--set", "num_slots=15", "--workers", "1", "--quiet", "--out", str(out)]
    assert main(["evaluate", "--policy", "pid", *common]) == 0
    printed = capsys.readouterr().out
    header = next(line for line in printed.splitlines() if line.startswith("| policy"))
    row = next(line for line in printed.splitlines() if line.startswith("| pid "))
    assert "score" in header and "(score: epa and dv-mpc on the same seeds)" in printed
    cell = row.split("|")[header.split("|").index(next(c for c in header.split("|") if "score" in c))].strip()
    assert math.isfinite(float(cell.split()[0]))
    assert {r["policy"] for r in read_csv(out)} == {"pid"}  # references not written
    assert main(["evaluate", "--policy", "pid", "--no-score", *common, "--overwrite"]) == 0
    printed = capsys.readouterr().out
    assert "score" not in next(line for line in printed.splitlines() if line.startswith("| policy"))
    # a reference with other settings is another policy under the reference's name: no score against itself
    assert main(["evaluate", "--policy", "dv-mpc", "--policy-arg", "power_levels=30", *common, "--overwrite"]) == 0
    printed = capsys.readouterr().out
    assert "no score: --policy-arg changes the reference dv-mpc itself" in printed


def test_benchmark_protocol_flags_are_checked(tmp_path, capsys):
    from lawn_cli import main

    out = ["--out", str(tmp_path / "b"), "--quiet"]
    cases = [(["--suite", "--protocol", "learned"], "--suite and --protocol learned are two protocols"),
             (["--suite", "--seed", "5"], "--seed 5: --suite fixes the test seeds"),
             (["--protocol", "learned", "--env", "lawn/Comm-v1"], "--env lawn/Comm-v1: --protocol learned runs each"),
             (["--suite", "--preset", "k3"], "choose tasks with --tasks"),
             (["--protocol", "learned", "--set", "num_slots=5"], "--protocol learned fixes the scenario"),
             (["--tasks", "k3"], "--tasks and --docs belong to --suite"),
             (["--suite", "--policies", "anchor:nope"], "unknown anchor 'nope'")]
    for flags, message in cases:
        assert main(["benchmark", *flags, *out]) == 2, flags
        assert message in capsys.readouterr().err, flags


def test_benchmark_suite_on_a_task_subset_writes_the_board(tmp_path, capsys):
    from lawn_cli import main

    out, docs = tmp_path / "suite", tmp_path / "docs"
    docs.mkdir()
    shutil.copy2(ROOT / "docs" / "LEADERBOARD.md", docs / "LEADERBOARD.md")  # the page's blocks
    assert main(["benchmark", "--suite", "--tasks", "k3", "--policies", "anchor:stake", "--episodes", "3",
                 "--workers", "1", "--quiet", "--out", str(out), "--docs", str(docs)]) == 0
    printed = capsys.readouterr().out
    assert "1 policies x 1 tasks, 3 seeds each" in printed
    board = (out / "board.md").read_text()
    assert board.splitlines()[0] == "| policy | env | k3 | IQM over tasks [95 %] |"
    names = [line.split("|")[1].strip() for line in first_table(board)[2:]]
    assert names == ["noise:dv-mpc", "limit:fast-drone", "limit:perfect-links", "actuator:buffer", "anchor:stake"]
    page = (docs / "LEADERBOARD.md").read_text()
    assert board.strip() in page and (out / "structure.md").read_text().strip() in page
    assert "1 policies x 1 tasks (k3), test seeds 0-2" in board and (docs / "figures" / "suite-per-slot.png").exists()
    from evaluation.cells import format_score
    from evaluation.episode import read_results
    from evaluation.stats import scores_by_policy

    scores = scores_by_policy(read_results(out / "episodes.csv"))  # the board's scores are the episodes' statistics
    for line in first_table(board)[2:]:
        policy, env, cell = (c.strip() for c in line.strip("|").split("|")[:3])
        assert cell == format_score(scores.get(("k3", env, policy))), policy
    assert "| k3 | lawn/Joint-v1 | 3 |" in (out / "references.md").read_text()


def test_dataset_command_and_bc_from_it(datasets_path, tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    from lawn_cli import main

    assert main(["dataset", "create", "--policy", "epa", "--env", "lawn/Comm-v1", "--episodes", "1", "--seed", "3",
                 "--dataset-id", "lawn/test/epa-v0", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "--preset default --dataset lawn/test/epa-v0 --timesteps 120 --out runs/bc-epa-v0 --hp expert=epa" in printed
    assert main(["dataset", "create", "--policy", "pid", "--env", "lawn/Comm-v1", "--episodes", "1",
                 "--dataset-id", "lawn/test/epa-v0", "--quiet"]) == 2  # never over an existing dataset
    assert "--dataset-id 'lawn/test/epa-v0' already exists under MINARI_DATASETS_PATH" in capsys.readouterr().err
    assert main(["dataset", "create", "--policy", "epa", "--env", "lawn/Comm-v1", "--episodes", "1",
                 "--dataset-id", "epa", "--quiet"]) == 2
    assert "--dataset-id 'epa': Minari ids have the form" in capsys.readouterr().err
    common = ["train", "--algo", "bc", "--env", "lawn/Comm-v1", "--dataset", "lawn/test/epa-v0", "--timesteps", "60",
              "--hp", "epochs=1", "--quiet"]
    assert main([*common, "--hp", "dagger_iterations=1", "--out", str(tmp_path / "mixed")]) == 2
    assert "holds episodes of epa, DAgger's expert is rg-mpc" in capsys.readouterr().err
    assert main([*common, "--hp", "expert=epa", "--hp", "dagger_iterations=1", "--hp", "dagger_timesteps=60",
                 "--out", str(tmp_path / "clone")]) == 0
    run = json.loads((tmp_path / "clone" / "run.json").read_text())
    hp = json.loads((tmp_path / "clone" / "hyperparams.json").read_text())
    assert hp["expert"] == "epa" and run["dataset"] == {"id": "lawn/test/epa-v0", "episode_seeds": [3]}


def test_train_recipes_skips_finished_runs_restarts_unfinished_ones_and_trains_fine_tunes_second(tmp_path, monkeypatch):
    """``lawn zoo train``: a finished run is kept, an unfinished one deleted and trained again, and a
    recipe that starts from another trains in a second phase from that recipe's run of the same seed."""
    import training.recipes as recipes_module
    import training.train as train_module
    from training.recipes import Recipe, finished
    from training.train import train_recipes

    tiny = {"clone": Recipe("clone", "BC", "bc", "lawn/Comm-v1", 100, seeds=(0, 1)),
            "tune": Recipe("tune", "PPO from the clone", "ppo", "lawn/Comm-v1", 50, seeds=(0, 1), init_from="clone")}
    monkeypatch.setattr(recipes_module, "RECIPES", tiny)
    monkeypatch.setattr(train_module, "RECIPES", tiny)
    runs = tmp_path / "runs"
    done0 = runs / "clone" / "seed-0"
    done0.mkdir(parents=True)
    (done0 / "run.json").write_text(json.dumps({"trainer": "bc", "num_timesteps": 100, "algo": "ppo",
                                                 "env": "lawn/Comm-v1", "seed": 0}))
    half = runs / "clone" / "seed-1"
    half.mkdir(parents=True)
    (half / "model.zip").write_text("an interrupted run's leftovers")
    phases = []

    def fake_pool_map(fn, tasks, workers, progress, desc=""):
        assert fn is train_module.train
        phases.append([(t.out_dir.parent.name, t.seed, t.init_from) for t in tasks])
        for t in tasks:  # the unfinished run was deleted before its task was made
            assert not t.out_dir.exists()
            t.out_dir.mkdir(parents=True)
            (t.out_dir / "run.json").write_text(json.dumps({"trainer": "bc" if t.algo == "bc" else "sb3",
                                                            "num_timesteps": t.timesteps, "algo": "ppo",
                                                            "env": t.env_id, "seed": t.seed}))
        return []

    monkeypatch.setattr(train_module, "pool_map", fake_pool_map)
    dirs = train_recipes(runs, workers=1, progress=False)
    assert phases == [[("clone", 1, None)],
                      [("tune", 0, runs / "clone" / "seed-0"), ("tune", 1, runs / "clone" / "seed-1")]]
    assert dirs == [done0, half, runs / "tune" / "seed-0", runs / "tune" / "seed-1"]
    assert all(finished(d, 50) for d in dirs)
    phases.clear()
    train_recipes(runs, workers=1, progress=False)  # everything finished: nothing to train
    assert phases == [[], []]
    with pytest.raises(ValueError, match="unknown recipe 'nope'; valid: clone, tune"):
        train_recipes(runs, ["nope"])


def test_the_learning_curve_shows_the_paired_interval_against_the_start(tmp_path):
    """``write_learning_curve``: the selected validation's paired change against the run's start and
    its 95 % interval in the summary, and a second panel of that change when the curve has it."""
    from training.validation import append_learning_curve, write_learning_curve

    spec = {"algo": "ppo", "env": "lawn/Joint-v1", "seed": 0}
    rows = [(0, {"control_cost": 10.0, "control_cost_ci95": 1.0, "vs_reference": 0.1, "vs_reference_ci95": 0.02,
                 "vs_start": 0.0, "vs_start_ci95": 0.0}),
            (64, {"control_cost": 9.0, "control_cost_ci95": 1.0, "vs_reference": 0.0, "vs_reference_ci95": 0.02,
                  "vs_start": -0.05, "vs_start_ci95": 0.01})]
    for steps, row in rows:
        append_learning_curve(tmp_path, steps, row)
    summary = write_learning_curve(tmp_path, spec)
    assert summary.best_at_timesteps == 64  # -5 % ± 1 %: significantly better than the start
    assert (summary.best_validation_vs_start, summary.best_validation_vs_start_ci95) == (-0.05, 0.01)
    from PIL import Image

    with Image.open(tmp_path / "learning_curve.png") as image:
        tall = image.size[1]
    (tmp_path / "learning_curve.csv").write_text("timesteps,control_cost,control_cost_ci95\n0,10,1\n64,9,1\n")
    write_learning_curve(tmp_path, spec)  # behaviour cloning's curve: no start to pair with, one panel
    with Image.open(tmp_path / "learning_curve.png") as image:
        assert image.size[1] < tall


def test_a_protocol_names_only_tables_it_can_make():
    from evaluation.episode import Entry
    from evaluation.protocols import Batch, Protocol
    from lawn_env import ScenarioConfig

    batch = Batch("default", ScenarioConfig(), (Entry("epa", "lawn/Joint-v1"),), (0,))
    with pytest.raises(ValueError, match=r"unknown tables \['boards'\]; valid: summary, learned, board"):
        Protocol("mine", (batch,), {"board.md": "boards"})
    assert Protocol("mine", (batch, batch), {"tasks.md": "tasks"}).entries == [Entry("epa", "lawn/Joint-v1")]
