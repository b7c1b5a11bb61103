"""The learners' ladder: its presets, its recipes, a tiny from-scratch run on every rung, the gap
measure, and the vector-env training path against SB3's env of single envs."""

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

from lawn_env import ENV_IDS, ConfigError, presets
from lawn_env.interface import RLInterface, resolve_interface

pytest.importorskip("stable_baselines3")

from paper.ladder import EXPERT, gap_closed, ladder_recipes
from training.recipes import RECIPES, recipe
from training.spec import TrainSpec, split_params
from training.train import train
from training.validation import read_learning_curve, selection_of


def _episode_metrics(preset, env_id, policy="anchor:distance-lqr", seed=0):
    from agents import make_policy
    from lawn_env.rollouts import rollout

    env = gym.make(env_id, config=preset)
    try:
        return rollout(env, make_policy(policy, preset, env_id=env_id), seed).metrics
    finally:
        env.close()


def test_every_rung_is_a_registered_preset_on_a_central_env_with_one_scratch_recipe():
    assert [r.preset for r in presets.LADDER][:3] == ["learn-power", "learn-tracking", "steady"]
    for rung in presets.LADDER:
        assert rung.preset in presets.names() and rung.env_id in ENV_IDS and rung.learns
    pairs = ladder_recipes()
    assert len(pairs) == len(presets.LADDER)
    for rung, r in pairs:
        assert (r.preset, r.env_id, r.timesteps) == (rung.preset, rung.env_id, 10_000_000)
        assert r.section == ("scratch" if rung.preset == "default" else "ladder")
        assert r.hp["start_at_anchor"] is True  # every run starts at the prior it is measured against
    assert {r.name for _, r in pairs} >= {"ppo-comm-scratch", "ppo-joint-scratch"}


def test_learn_power_holds_the_drone_and_learn_tracking_loses_nothing():
    power = presets.get("learn-power")
    assert power.drone.start_m == (100.0, 100.0) and power.drone.max_speed_mps == 0.01
    assert power.reference.initial_offset_std_m == 0.0
    moved = _episode_metrics("learn-power", "lawn/Comm-v1", "anchor:distance")["drone_path_length_m"]
    assert moved <= 0.01 * power.slot_s * power.num_slots + 1e-9  # the drone's half of the action moves nothing
    tracking = presets.get("learn-tracking")
    assert tracking.channel.rate_threshold_bps_hz == 1.0
    metrics = _episode_metrics("learn-tracking", "lawn/Joint-v1")
    assert metrics["outage_rate"] == 0.0 and metrics["outage_rate_predicted"] < 1e-5


def test_the_rung_presets_are_checked_like_any_config():
    with pytest.raises(ConfigError, match="max_speed_mps"):
        presets.get("learn-power").override({"drone.max_speed_mps": 0.0})
    with pytest.raises(ValueError, match="learn-power"):
        presets.get("learn-powr")  # the error lists the valid presets, the rungs among them
    with pytest.raises(ValueError, match="already registered"):
        presets.register("learn-power", presets.get("default"))


def test_the_log_reward_counts_a_slot_by_its_order_of_magnitude():
    iface = RLInterface(reward="log", cost_clip=1e4, cost_scale=10.0)
    costs = np.array([0.0, 10.0, 990.0, 1e6])
    assert np.allclose(iface.rewards_from_costs(costs), -np.log1p(np.minimum(costs, 1e4) / 10.0))
    assert iface.reward_floor == pytest.approx(-math.log(1001.0))
    assert np.allclose(iface.terminal_penalties(np.array([0, 3])), [0.0, 3 * iface.reward_floor])
    with pytest.raises(ConfigError, match="'scaled' or 'log'"):
        RLInterface(reward="cost", termination_distance_m=25.0)
    with pytest.raises(ConfigError, match="reward"):
        RLInterface(reward="logarithmic")


def test_torch_threads_is_checked_and_named():
    assert split_params("ppo", "lawn/Comm-v1", {"torch_threads": 2}).torch_threads == 2
    with pytest.raises(ConfigError, match="torch_threads"):
        split_params("ppo", "lawn/Comm-v1", {"torch_threads": 0})


def test_gap_closed_is_zero_at_the_prior_and_a_hundred_at_the_expert():
    rng = np.random.default_rng(0)
    prior = {s: float(c) for s, c in enumerate(rng.uniform(50, 500, size=40))}
    expert = {s: c * float(rng.uniform(0.5, 0.8)) for s, c in prior.items()}
    half = {s: math.sqrt(prior[s] * expert[s]) for s in prior}  # halfway on every seed's log scale
    assert gap_closed(prior, prior, expert).closed == pytest.approx(0.0, abs=1e-9)
    assert gap_closed(expert, prior, expert).closed == pytest.approx(100.0)
    g = gap_closed(half, prior, expert)
    assert g.closed == pytest.approx(50.0) and g.low <= 50.0 <= g.high and g.seeds == 40
    assert math.isnan(gap_closed({0: 1.0}, {0: 2.0}, {0: 1.5}).low)  # no interval below three seeds
    with pytest.raises(ValueError, match="share no seed"):
        gap_closed({1: 1.0}, {2: 1.0}, {2: 1.0})
    assert EXPERT == "dv-mpc"


@pytest.mark.parametrize("rung", presets.LADDER, ids=lambda r: f"{r.preset}-{r.env_id.split('/')[-1]}")
def test_a_tiny_scratch_run_on_every_rung_records_its_speed_and_its_curve(tmp_path, rung):
    r = next(r for rg, r in ladder_recipes() if rg == rung)
    spec = dataclasses.replace(r.spec(tmp_path, 0), timesteps=256, eval_every=128, eval_episodes=2,
                               checkpoint_every=128, hp_overrides={**r.hp, "n_envs": 16, "n_steps": 8,
                                                                   "batch_size": 64})
    summary = train(spec)
    assert summary.timesteps == 256 and summary.steps_per_s > 0
    assert summary.steps_per_s == pytest.approx(summary.timesteps / summary.wall_time_s, rel=1e-2)
    curve = read_learning_curve(spec.out_dir)
    assert [row["timesteps"] for row in curve] == [0, 128, 256]
    assert curve[0]["vs_start"] == 0.0  # the start is the prior: the curve's change is against it
    assert all(math.isfinite(row["control_cost"]) for row in curve)
    assert resolve_interface(spec.hyperparams().params["interface"]).reward == "log"
    assert selection_of(spec.out_dir) == r.hp.get("selection", "relative")  # the run records its selection rule
    assert all("vs_start_geometric_high" in row for row in curve[1:])


@pytest.mark.parametrize("env_id", ["lawn/Comm-v1", "lawn/Joint-v1"])
def test_native_vector_training_equals_training_on_single_envs(env_id):
    """The same seed, the same PPO: lawn's batched env and SB3's DummyVecEnv of single envs give the same
    network, bit for bit, over episodes that end within the rollouts (autoresets and truncation's
    bootstrap included); with every scenario's draws from one generator they do not."""
    import torch
    from stable_baselines3 import PPO

    from lawn_env import ScenarioConfig
    from training.sb3 import make_train_env

    iface = dict(recipe("ppo-joint-scratch" if env_id == "lawn/Joint-v1" else "ppo-comm-scratch").hp["interface"])
    config = ScenarioConfig(num_slots=20)

    def weights(vec, independent=True):
        env = make_train_env(env_id, config, 3, 7, {"norm_obs": True, "norm_reward": True, "gamma": 0.98}, None,
                             interface=iface, vec=vec)
        if vec == "native":
            env.venv.venv.independent_draws = independent  # VecNormalize(VecMonitor(NativeVecEnv))
        model = PPO("MlpPolicy", env, seed=7, n_steps=32, batch_size=48, n_epochs=2, device="cpu",
                    policy_kwargs={"net_arch": [16, 16]})
        model.learn(2 * 3 * 32)
        env.close()
        return [p.detach().clone() for p in model.policy.parameters()]

    torch.set_num_threads(1)
    single, native = weights("dummy"), weights("native")
    assert all(torch.equal(a, b) for a, b in zip(single, native, strict=True))
    shared = weights("native", independent=False)
    assert not all(torch.equal(a, b) for a, b in zip(single, shared, strict=True))


def test_the_scratch_recipes_say_what_they_train_with():
    for name in ("ppo-comm-scratch", "ppo-joint-scratch"):
        r = RECIPES[name]
        spec = r.spec(__import__("pathlib").Path("/tmp/unused"), 0)
        assert isinstance(spec, TrainSpec) and spec.vec == "native" and spec.eval_episodes == 50
        assert "--eval-episodes 50" in r.command() and "--checkpoint-every 500000" in r.command()
        params = spec.hyperparams().params
        assert params["n_envs"] * params["n_steps"] == 30_720 and params["batch_size"] == 7_680


def test_the_ladder_page_from_a_tiny_run(tmp_path, monkeypatch, capsys):
    """``python -m paper.ladder`` end to end on one rung: the prior, dv-mpc and a run on both test ranges,
    the table, the episodes and the figure written after everything was played."""
    from paper import ladder

    r = recipe("ppo-learn-power-scratch")
    runs = tmp_path / "runs"
    spec = dataclasses.replace(r.spec(runs, 0), timesteps=128, eval_every=128, eval_episodes=2, checkpoint_every=128,
                               hp_overrides={**r.hp, "n_envs": 16, "n_steps": 8, "batch_size": 64})
    train(spec)
    monkeypatch.setattr(ladder, "finished", lambda run_dir, steps: (run_dir / "run.json").exists())
    out = tmp_path / "out"
    assert ladder.main(["--runs", str(runs), "--out", str(out), "--episodes", "3", "--workers", "1", "--quiet"]) == 0
    table = (out / "ladder.md").read_text()
    assert "`learn-power` (Comm-v1)" in table and "`ppo-learn-power-scratch` seed 0" in table
    assert sum(line.startswith("|") for line in table.splitlines()) == 3  # one run: the other rungs have none here
    assert "| 0 % [0, 0] | 0 % [0, 0] |" in table  # its selected model is its start, the prior: nothing closed
    assert (out / "ladder.png").stat().st_size > 0 and len((out / "ladder.csv").read_text().splitlines()) == 1 + 3 * 6
    before = (out / "ladder.md").read_text()
    with pytest.raises(SystemExit):  # an earlier run's files are kept unless asked
        ladder.main(["--runs", str(runs), "--out", str(out), "--episodes", "3", "--workers", "1", "--quiet"])
    assert (out / "ladder.md").read_text() == before
    assert "pass --overwrite" in capsys.readouterr().err
    with pytest.raises(ValueError, match="no finished run"):
        ladder.evaluate_ladder(tmp_path / "empty", episodes=3, workers=1, progress=False)
