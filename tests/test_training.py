"""Training round trips with tiny budgets (seconds each); skipped without the rl extra."""

import csv
import json
import math
import re

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("supersuit")

from stable_baselines3.common.callbacks import BaseCallback

from agents import make_policy
from evaluation.seeds import VALIDATION_SEED_BASE
from lawn_cli import main
from lawn_env import ScenarioConfig
from training.callbacks import latest_checkpoint
from training.spec import TrainSpec, load_hyperparams
from training.train import resume, train

SMALL = ScenarioConfig(num_slots=12)
FAST = {"ppo": {"n_steps": 64, "batch_size": 64, "n_epochs": 2}, "a2c": {"n_steps": 8},
        "sac": {"learning_starts": 64, "buffer_size": 2000, "batch_size": 32},
        "td3": {"learning_starts": 64, "buffer_size": 2000, "batch_size": 32}}


def _train(tmp_path, algo, env_id="lawn/Joint-v1", steps=256, name=None, **kwargs):
    out = tmp_path / (name or f"{algo}-{env_id.split('/')[-1]}")
    hp = {**FAST.get(algo, {}), **kwargs.pop("hp_overrides", {})}
    n_envs = kwargs.pop("n_envs", 2 if algo in ("ppo", "a2c") else 1)
    callbacks = kwargs.pop("callbacks", None)
    spec = TrainSpec(algo=algo, env_id=env_id, config=SMALL, timesteps=steps, seed=3, out_dir=out, hp_overrides=hp,
                     n_envs=n_envs, eval_every=128, eval_episodes=1, checkpoint_every=128, progress=False, **kwargs)
    summary = train(spec, callbacks=callbacks)
    assert TrainSpec(**json.loads((out / "spec.json").read_text())) == spec  # the run records what made it
    return out, summary


def _run_episode(policy, env_id):
    env = gym.make(env_id, config=SMALL)
    obs, _ = env.reset(seed=0)
    policy.reset(0)
    done = False
    while not done:
        action = policy.act(obs)
        assert env.action_space.contains(action)
        obs, _, _, done, info = env.step(action)
    return info["episode_metrics"]


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3", "a2c"])
def test_train_save_load_evaluate(tmp_path, algo):
    env_id = "lawn/Comm-v1" if algo == "sac" else "lawn/Joint-v1"
    out, summary = _train(tmp_path, algo, env_id)
    for name in ("model.zip", "vecnormalize.pkl", "best_model.zip", "best_vecnormalize.pkl", "run.json", "config.json",
                 "hyperparams.json", "learning_curve.csv", "learning_curve.png", "summary.md"):
        assert (out / name).exists(), name
    assert (out / "tb").is_dir() and (out / "checkpoints" / str(run_steps(out)) / "model.zip").exists()
    run = json.loads((out / "run.json").read_text())
    assert run["num_timesteps"] >= 256 and run["hyperparams_version"] >= 2 and "torch" in run["versions"]
    assert run["interface"]["action_scheme"] == "anchored"  # the RL interface is the default
    assert ScenarioConfig.from_dict(json.loads((out / "config.json").read_text())) == SMALL
    policy = make_policy(f"sb3:{out}")
    assert policy.env_id == env_id
    metrics = _run_episode(policy, env_id)
    assert np.isfinite(metrics["control_cost"])


def test_same_seed_same_agent(tmp_path):
    a, _ = _train(tmp_path, "ppo", name="a")
    b, _ = _train(tmp_path, "ppo", name="b")
    pa, pb = make_policy(f"sb3:{a}"), make_policy(f"sb3:{b}")
    obs = gym.make("lawn/Joint-v1", config=SMALL).reset(seed=5)[0]
    assert np.array_equal(pa.act(obs), pb.act(obs))


def run_steps(out):
    return json.loads((out / "run.json").read_text())["num_timesteps"]


class _Kill(BaseCallback):
    """Stops training abruptly at ``at`` steps, as a SIGKILL would (nothing after it runs)."""

    def __init__(self, at):
        super().__init__()
        self.at = at

    def _on_step(self):
        if self.num_timesteps >= self.at:
            raise KeyboardInterrupt
        return True


def _history(out):
    run = json.loads((out / "run.json").read_text())
    curve = [int(r["timesteps"]) for r in csv.DictReader((out / "learning_curve.csv").open())]
    episodes = {p.name: len(p.read_text().splitlines()) - 2 for p in sorted((out / "monitor").glob("*.csv"))}
    return run["num_timesteps"], run["updates"], curve, episodes


@pytest.mark.parametrize("algo, env_id, kill_at", [("ppo", "lawn/Joint-v1", 450), ("sac", "lawn/Comm-v1", 300)])
def test_a_killed_and_resumed_run_equals_an_uninterrupted_one(tmp_path, algo, env_id, kill_at):
    whole, _ = _train(tmp_path, algo, env_id, steps=640, name="whole")
    with pytest.raises(KeyboardInterrupt):
        _train(tmp_path, algo, env_id, steps=640, name="killed", callbacks=[_Kill(kill_at)])
    out = tmp_path / "killed"
    assert not (out / "model.zip").exists() and latest_checkpoint(out).steps < kill_at
    summary = resume(out, progress=False)
    assert summary.resumed_from == kill_at // 128 * 128  # the last checkpoint (every 128 steps) before the kill
    steps, updates, curve, episodes = _history(out)
    assert (steps, updates, curve) == _history(whole)[:3] and steps == 640 and updates > 0
    # the monitor kept the episodes before the checkpoint and appended the rest (12-slot episodes;
    # the checkpoints fall on episode boundaries of every copy here, so the counts match too)
    assert episodes == _history(whole)[3] and set(episodes.values()) == {640 // len(episodes) // 12}
    if algo == "sac":  # the replay buffer came back: as full as the uninterrupted run's
        import pickle

        buffers = [pickle.load(open(latest_checkpoint(d).file("replay_buffer.pkl"), "rb")) for d in (whole, out)]
        assert buffers[0].pos == buffers[1].pos == 640 and buffers[1].observations[:300].any()


def test_resume_extends_finished_runs_only_when_asked_and_restarts_runs_without_a_checkpoint(tmp_path, capsys):
    out, _ = _train(tmp_path, "ppo", steps=256)
    model = (out / "model.zip").read_bytes()
    with pytest.raises(ValueError, match="the run is finished \\(256 steps, target 256\\)"):
        resume(out)
    assert (out / "model.zip").read_bytes() == model  # untouched
    summary = resume(out, timesteps=512, progress=False)
    assert run_steps(out) == 512 and summary.timesteps == 512 and summary.resumed_from == 256
    with pytest.raises(ValueError, match="finished \\(512 steps, target 128\\); pass --timesteps above 512"):
        resume(out, timesteps=128)
    with pytest.raises(ValueError, match="no run.json"):
        resume(tmp_path / "nowhere")
    # killed before its first checkpoint: neither resumable nor restartable before; now it restarts
    with pytest.raises(KeyboardInterrupt):
        _train(tmp_path, "ppo", steps=256, name="early", callbacks=[_Kill(64)])
    early = tmp_path / "early"
    assert latest_checkpoint(early) is None
    summary = resume(early, progress=False)
    assert summary.resumed_from is None and run_steps(early) == 256
    assert _history(early)[:3] == (256, 2 * 2, [0, 128, 256])  # 2 rollouts of 2 x 64 steps, 2 epochs each
    # a damaged run directory names the file
    (early / "hyperparams.json").unlink()
    (early / "run.json").write_text(json.dumps({**json.loads((early / "run.json").read_text()), "num_timesteps": 0}))
    with pytest.raises(ValueError, match="no hyperparams.json in .*the run directory is incomplete"):
        resume(early)
    (early / "run.json").write_text("{not json")
    assert main(["train", "--resume", str(early), "--quiet"]) == 2
    assert "run.json is not valid JSON (line 1, column 2" in capsys.readouterr().err


def test_behaviour_cloning_reduces_loss_and_warm_starts_ppo(tmp_path):
    out, summary = _train(tmp_path, "bc", "lawn/Comm-v1", steps=120, name="bc",
                          hp_overrides={"epochs": 8, "dagger_iterations": 1, "dagger_timesteps": 36})
    history = json.loads((out / "bc_losses.json").read_text())
    assert history[0]["losses"][-1] < history[0]["losses"][0]
    assert history[1]["samples"] == 156
    assert summary.bc_loss_last < summary.bc_loss_first
    record = json.loads((out / "run.json").read_text())  # the expert's labels: 156 decisions of the run's time
    assert 0 < record["expert_decision_s"] < record["wall_time_s"]
    assert summary.expert_share == round(record["expert_decision_s"] / record["wall_time_s"], 3)
    assert f"- expert_share: {summary.expert_share}" in (out / "summary.md").read_text()
    with pytest.raises(ValueError, match="bc runs are not resumable"):
        resume(out, timesteps=10_000)
    metrics = _run_episode(make_policy(f"bc:{out}"), "lawn/Comm-v1")
    assert np.isfinite(metrics["control_cost"])
    # PPO started from the cloned policy: same weights before any update
    from stable_baselines3 import PPO

    from training.sb3 import init_from, make_train_env

    env = make_train_env("lawn/Comm-v1", SMALL, 1, 0, {"norm_obs": True}, None)
    model = PPO("MlpPolicy", env, policy_kwargs={"net_arch": [128, 128], "log_std_init": -1.0}, seed=0)
    init_from(model, out, env)
    cloned = PPO.load(str(out / "model.zip"))
    for p, q in zip(model.policy.parameters(), cloned.policy.parameters()):
        assert np.array_equal(p.detach().numpy(), q.detach().numpy())


def test_multi_agent_round_trip(tmp_path):
    out, _ = _train(tmp_path, "ppo", "lawn/Parallel-v0", steps=128, n_envs=1)
    policy = make_policy(f"marl:{out}")
    assert policy.env_id == "lawn/Joint-v1"
    obs = gym.make("lawn/Joint-v1", config=SMALL).reset(seed=1)[0]
    agent_obs = policy.agent_observations(obs)
    assert agent_obs.shape == (5, policy.network.observation_space.shape[0])
    assert np.array_equal(agent_obs[:, -5:], np.eye(5))  # SuperSuit's one-hot agent indicator
    metrics = _run_episode(policy, "lawn/Joint-v1")
    assert np.isfinite(metrics["control_cost"])
    with pytest.raises(ValueError, match="marl:"):
        make_policy(f"sb3:{out}")


def test_errors_name_the_problem(tmp_path, capsys):
    with pytest.raises(ValueError, match="unknown algorithm 'ddpg'"):
        load_hyperparams("ddpg", "lawn/Joint-v1")
    with pytest.raises(ValueError, match="unknown env id 'lawn/Nope-v0'"):
        load_hyperparams("ppo", "lawn/Nope-v0")
    with pytest.raises(ValueError, match="unknown PPO hyperparameters \\['lerning_rate'\\]"):
        TrainSpec(algo="ppo", env_id="lawn/Joint-v1", timesteps=64, out_dir=tmp_path / "x",
                  hp_overrides={"lerning_rate": 1e-3})
    with pytest.raises(ValueError, match="not a lawn train run directory"):
        make_policy(f"sb3:{tmp_path / 'missing'}")
    with pytest.raises(ValueError, match="unknown policy prefix 'zz'"):
        make_policy("zz:somewhere")
    with pytest.raises(SystemExit):
        main(["train", "--algo", "ddpg", "--env", "lawn/Joint-v1", "--timesteps", "10", "--out", str(tmp_path / "y")])
    assert "invalid choice: 'ddpg'" in capsys.readouterr().err
    assert main(["train", "--resume", str(tmp_path / "nowhere"), "--quiet"]) == 2
    assert "no run.json" in capsys.readouterr().err
    assert main(["benchmark", "--include", str(tmp_path / "nowhere"), "--quiet", "--episodes", "1"]) == 2
    assert "no run.json" in capsys.readouterr().err
    out, _ = _train(tmp_path, "ppo", steps=64, name="exists")
    with pytest.raises(ValueError, match="already holds a run"):
        _train(tmp_path, "ppo", steps=64, name="exists")


def test_interface_trained_agents_are_evaluated_on_full_unmodified_episodes(tmp_path):
    from evaluation.run import episode_row
    from evaluation.seeds import VALIDATION_SEED_BASE
    from evaluation.stats import paired_difference
    from training.validation import read_learning_curve

    out, summary = _train(tmp_path, "ppo", "lawn/Comm-v1", steps=256, name="rl")
    curve = read_learning_curve(out)
    header = (out / "learning_curve.csv").read_text().splitlines()[0]
    assert header == ("timesteps,control_cost,control_cost_ci95,vs_reference,vs_reference_ci95,vs_start,vs_start_ci95,"
                      "vs_reference_geometric,vs_start_geometric,vs_start_geometric_low,vs_start_geometric_high")
    assert [r["timesteps"] for r in curve] == [0, 128, 256]  # the starting policy is validated too
    start = json.loads((out / "validation_start.json").read_text())
    assert list(start) == [str(VALIDATION_SEED_BASE)] and float(start[str(VALIDATION_SEED_BASE)]) == curve[0]["control_cost"]
    assert curve[0]["vs_start"] == 0.0 and all(math.isnan(r["vs_start_ci95"]) for r in curve[1:])
    # on one validation seed no later policy is significantly better than the start: the start is kept
    best = curve[0]
    assert summary.best_at_timesteps == 0 and summary.best_validation_vs_reference == best["vs_reference"]
    assert summary.best_validation_cost == best["control_cost"]
    policy = make_policy(f"sb3:{out}")
    assert policy.interface.action_scheme == "anchored" and policy.env_id == "lawn/Comm-v1"
    seeds = [VALIDATION_SEED_BASE]  # _train validates on one episode
    rows = {s: episode_row(policy, "lawn/Comm-v1", SMALL, seed=s) for s in seeds}
    assert all(r.slots == SMALL.num_slots for r in rows.values())  # no termination on the unmodified scenario
    reference = {s: episode_row(make_policy("rg-mpc", SMALL, env_id="lawn/Comm-v1"), "lawn/Comm-v1", SMALL, s)
                 .control_cost for s in seeds}
    selected = paired_difference({s: r.control_cost for s, r in rows.items()}, reference)[0]
    assert best["vs_reference"] == pytest.approx(selected, rel=1e-9)  # sb3:DIR plays the selected model


def test_plain_v0_interface_on_request(tmp_path):
    out, _ = _train(tmp_path, "ppo", steps=128, name="v0", interface="v0")
    run = json.loads((out / "run.json").read_text())
    assert run["interface"]["action_scheme"] == "direct" and run["interface"]["reward"] == "cost"
    assert make_policy(f"sb3:{out}").interface.action_scheme == "direct"


def test_several_training_seeds_in_one_command(tmp_path):
    from training.train import train_seeds
    from training.validation import read_learning_curve, selected_validation

    spec = TrainSpec(algo="ppo", env_id="lawn/Joint-v1", config=SMALL, timesteps=128, out_dir=tmp_path / "multi",
                     hp_overrides=FAST["ppo"], n_envs=2, eval_every=128, eval_episodes=1, checkpoint_every=128,
                     progress=False)
    result = train_seeds(spec, [3, 4], workers=1)
    for s in (3, 4):
        run = json.loads((tmp_path / "multi" / f"seed-{s}" / "run.json").read_text())
        assert run["seed"] == s and (tmp_path / "multi" / f"seed-{s}" / "learning_curve.png").exists()
    saved = json.loads((tmp_path / "multi" / "seeds.json").read_text())
    assert saved["seeds"] == [3, 4] and [r["seed"] for r in saved["runs"]] == [3, 4]
    # each run's selected validation, read from its own learning curve
    best = [selected_validation(read_learning_curve(tmp_path / "multi" / f"seed-{s}"))["control_cost"] for s in (3, 4)]
    assert [r["best_validation_cost"] for r in saved["runs"]] == best
    assert [r.best_validation_cost for r in result.runs] == best and result.seeds == [3, 4]
    assert saved["best_validation_cost_mean"] == result.best_validation_cost_mean == pytest.approx(np.mean(best))
    assert np.isfinite(saved["best_validation_cost_ci95"])
    with pytest.raises(ValueError, match="distinct seeds"):
        train_seeds(spec, [1, 1])


def test_exported_agent_loads_as_zoo_name(tmp_path, monkeypatch):
    from agents import learned

    out, _ = _train(tmp_path, "ppo", "lawn/Comm-v1", steps=128, name="exp")
    monkeypatch.setattr(learned, "ZOO_DIR", tmp_path / "zoo")
    learned.export_agent(out, tmp_path / "zoo" / "tiny", {"label": "tiny test agent"})
    files = sorted(p.name for p in (tmp_path / "zoo" / "tiny").iterdir())
    assert files == ["agent.json", "normalizer.npz", "policy.zip"]
    assert (tmp_path / "zoo" / "tiny" / "policy.zip").stat().st_size < 1_000_000
    shipped, original = make_policy("zoo:tiny"), make_policy(f"sb3:{out}")
    obs = gym.make("lawn/Comm-v1", config=SMALL).reset(seed=2)[0]
    np.testing.assert_allclose(shipped.act(obs), original.act(obs), atol=1e-5)
    with pytest.raises(ValueError, match="unknown zoo agent 'nope'; shipped: tiny"):
        make_policy("zoo:nope")


@pytest.mark.parametrize("name", sorted(__import__("agents.learned", fromlist=["zoo_agents"]).zoo_agents()))
def test_shipped_agents_load_and_act(name):
    from agents import trained_config
    from agents.learned import zoo_agents

    record = zoo_agents()[name]
    policy = make_policy(f"zoo:{name}", trained_config(f"zoo:{name}"))  # its training scenario (K = 16, 64, a law)
    assert policy.env_id == record.evaluated_on
    env = gym.make(policy.env_id, config=policy.config)
    obs, _ = env.reset(seed=0)
    policy.reset(0)
    for _ in range(5):
        action = policy.act(obs)
        assert env.action_space.contains(action)
        obs, *_ = env.step(action)


def test_agents_are_shipped():
    from agents.learned import zoo_agents

    shipped = zoo_agents()
    for name in ("ppo-comm", "ppo-joint", "ppo-marl"):
        assert name in shipped, f"zoo:{name} is not shipped (lawn zoo build exports it)"


def test_critic_warmup_keeps_the_cloned_actor(tmp_path):
    """With actor_warmup_steps beyond the run, PPO's updates move only the value function."""
    out, _ = _train(tmp_path, "ppo", "lawn/Comm-v1", steps=128, name="base", n_envs=2)
    tuned, _ = _train(tmp_path, "ppo", "lawn/Comm-v1", steps=256, name="warm", n_envs=2, init_from=out,
                      hp_overrides={"actor_warmup_steps": 10_000, "init_log_std": -2.5})
    from stable_baselines3 import PPO

    before, after = PPO.load(str(out / "model.zip")), PPO.load(str(tuned / "model.zip"))
    b, a = before.policy.state_dict(), after.policy.state_dict()
    actor = [k for k in b if k.startswith(("mlp_extractor.policy_net", "action_net"))]
    critic = [k for k in b if k.startswith(("mlp_extractor.value_net", "value_net"))]
    assert actor and critic
    for k in actor:
        assert np.array_equal(b[k].numpy(), a[k].numpy()), k
    assert any(not np.array_equal(b[k].numpy(), a[k].numpy()) for k in critic)
    assert float(a["log_std"].mean()) == pytest.approx(-2.5)
    # a start whose network differs from the run's is named before any torch error
    with pytest.raises(ValueError, match=r"--init-from .*net_arch=\[128, 128\], this run builds net_arch=\[32\]"):
        _train(tmp_path, "ppo", "lawn/Comm-v1", steps=128, name="other", n_envs=2, init_from=out,
               hp_overrides={"policy_kwargs": {"net_arch": [32]}})


def test_zoo_command_lists_the_shipped_agents(capsys):
    from agents.learned import zoo_agents

    assert main(["zoo"]) == 0
    printed = capsys.readouterr().out
    for name in zoo_agents():
        assert f"zoo:{name}" in printed
    for name in ("ppo-comm-scratch", "ppo-joint-scratch"):  # each agent's budget and its runs' speed
        rec = zoo_agents()[name]
        rate = rec.budget_steps / np.mean(rec.wall_time_s)
        assert f"{rec.budget_steps:,} steps at {rate:,.0f} steps/s" in printed
    assert main(["zoo", "build", "--runs", "/nonexistent/runs", "--quiet"]) == 2
    assert "no finished recipe runs" in capsys.readouterr().err


@pytest.mark.slow
def test_a_sigkilled_lawn_train_resumes_to_the_uninterrupted_counts(tmp_path):
    """The same as the in-process kill, with a real SIGKILL of the command line mid-run."""
    import os
    import signal
    import subprocess
    import sys
    import time

    def cmd(out):
        return [sys.executable, "-m", "lawn_cli", "train", "--algo", "ppo", "--env", "lawn/Joint-v1",
                "--timesteps", "2048", "--seed", "3", "--out", str(out), "--n-envs", "2", "--eval-every", "256",
                "--eval-episodes", "1", "--checkpoint-every", "256", "--quiet", "--set", "num_slots=12",
                "--hp", "n_steps=64", "--hp", "batch_size=64", "--hp", "n_epochs=2"]

    subprocess.run(cmd(tmp_path / "whole"), check=True, cwd=os.getcwd())
    proc = subprocess.Popen(cmd(tmp_path / "killed"), cwd=os.getcwd())
    deadline = time.time() + 120
    while time.time() < deadline and (latest_checkpoint(tmp_path / "killed") is None
                                      or latest_checkpoint(tmp_path / "killed").steps < 768):
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (tmp_path / "killed" / "model.zip").exists(), "kill it before the end"
    subprocess.run([sys.executable, "-m", "lawn_cli", "train", "--resume", str(tmp_path / "killed"), "--quiet"],
                   check=True, cwd=os.getcwd())
    assert _history(tmp_path / "killed")[:3] == _history(tmp_path / "whole")[:3]


def test_recipe_commands_parse_as_lawn_train():
    """Every zoo recipe's printed command is one `lawn train` accepts, with its budget, seeds,
    vector env and hyperparameters (shell-quoted JSON) exactly as the recipe trains them."""
    import shlex

    from lawn_cli import build_parser
    from lawn_cli.common import parse_overrides
    from training.recipes import RECIPES

    for recipe in RECIPES.values():
        argv = shlex.split(recipe.command().replace("<s>", "0"))
        assert argv[:2] == ["lawn", "train"]
        args = build_parser().parse_args(argv[1:])
        assert (args.algo, args.env, args.timesteps) == (recipe.algo, recipe.env_id, recipe.timesteps)
        assert tuple(args.seeds) == recipe.seeds and args.vec == recipe.vec
        assert parse_overrides(args.hp, "--hp") == recipe.hp
    assert any(r.vec == "native" for r in RECIPES.values())


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_start_at_anchor_makes_the_untrained_policy_play_the_zero_action(algo):
    from agents.runs import algorithm_class
    from training.sb3 import start_at_anchor

    env = gym.make("lawn/CommRL-v1", num_slots=4)
    model = algorithm_class(algo)("MlpPolicy", env, seed=0, **({"learning_starts": 10} if algo == "sac" else {}))
    obs, _ = env.reset(seed=0)
    before, _ = model.predict(obs, deterministic=True)
    assert np.abs(before).max() > 1e-3  # SB3's init acts away from zero (SAC's by far)
    start_at_anchor(model, algo)
    after, _ = model.predict(obs, deterministic=True)
    np.testing.assert_array_equal(after, np.zeros_like(after))
    with pytest.raises(ValueError, match="start_at_anchor: supported for sac, ppo, not 'td3'"):
        start_at_anchor(model, "td3")


@pytest.mark.parametrize("bad, message", [
    ("learnin_rate=1e-4", "unknown PPO hyperparameters \\['learnin_rate'\\]"),
    ("n_envs=0", "--hp n_envs=0: should be greater than or equal to 1 \\(allowed: an integer >= 1\\)"),
    ("init_log_std=\"low\"", "--hp init_log_std='low': should be a valid number"),
    ("normalize=\"yes\"", "--hp normalize='yes': should be a valid boolean"),
    ("actor_warmup_steps=abc", "--hp actor_warmup_steps='abc'"),
    ("policy=Foo", "--hp policy='Foo': PPO takes"),
    ("seed=3", "unknown PPO hyperparameters \\['seed'\\]"),
    ('normalize={"bad": 1}', "unknown VecNormalize options \\['bad'\\]"),
    ('learning_rate="lin_x"', "--hp learning_rate='lin_x'"),
    ('policy_kwargs={"bogus": 1}', "bogus"),
])
def test_a_failed_lawn_train_leaves_nothing_and_the_corrected_command_runs(tmp_path, capsys, bad, message):
    """Every option is checked before the run directory gets its files, or the files are removed when
    SB3 refuses the model: the corrected command with the same --out then trains."""
    out = tmp_path / "r3"
    args = ["train", "--algo", "ppo", "--env", "CartPole-v1", "--timesteps", "64", "--out", str(out), "--quiet",
            "--hp", "n_steps=32", "--hp", "batch_size=32"]
    assert main(args + ["--hp", bad]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err) and "internal error" not in err, err
    assert not out.exists()
    assert main(args) == 0 and (out / "run.json").exists()


def test_the_valid_keys_are_the_public_ones():
    from training.spec import split_params

    with pytest.raises(ValueError) as info:
        split_params("ppo", "lawn/Joint-v1", {"learnin_rate": 1e-4})
    listed = str(info.value).split("valid: ")[1].split(", ")
    assert "learning_rate" in listed and "init_log_std" in listed and "actor_warmup_steps" in listed
    assert not any(k.startswith("_") for k in listed) and "seed" not in listed and "verbose" not in listed
    with pytest.raises(ValueError, match="--hp init_log_std: applies to ppo, a2c, not sac"):
        split_params("sac", "lawn/Joint-v1", {"init_log_std": -1.0})


def _truncate(path):
    """Rewrite the zip at ``path`` with its largest member cut to half its length."""
    import zipfile

    with zipfile.ZipFile(path) as zf:
        members = {info.filename: zf.read(info.filename) for info in zf.infolist()}
    biggest = max(members, key=lambda name: len(members[name]))
    members[biggest] = members[biggest][: len(members[biggest]) // 2]
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)


def test_a_damaged_checkpoint_names_its_file(tmp_path, monkeypatch, capsys):
    import shutil

    from agents import learned

    zoo = tmp_path / "zoo"
    shutil.copytree(learned.ZOO_DIR / "ppo-comm", zoo / "ppo-comm")
    _truncate(zoo / "ppo-comm" / "policy.zip")
    monkeypatch.setattr(learned, "ZOO_DIR", zoo)
    with pytest.raises(ValueError, match=r"policy\.zip: cannot read this zoo agent's ppo network: the file is damaged"):
        make_policy("zoo:ppo-comm")
    out, _ = _train(tmp_path, "ppo", steps=64, name="cut")
    (out / "best_model.zip").unlink(missing_ok=True)
    _truncate(out / "model.zip")
    assert main(["evaluate", "--policy", f"sb3:{out}", "--episodes", "1", "--no-score", "--quiet",
                 "--out", str(tmp_path / "rows.csv")]) == 2
    err = capsys.readouterr().err
    assert f"{out / 'model.zip'}: cannot read this ppo model" in err and "internal error" not in err
    (out / "model.zip").write_bytes(b"")  # an empty file
    with pytest.raises(ValueError, match="damaged or truncated"):
        make_policy(f"sb3:{out}")


def test_zoo_lists_each_agents_real_trainer(capsys):
    assert main(["zoo"]) == 0
    printed = capsys.readouterr().out
    block = printed.split("zoo:bc-comm")[1].split("zoo:")[0]
    assert "bc, a ppo network" in block
    assert ", ppo)" in printed.split("zoo:ppo-comm ")[1].split("zoo:")[0]


@pytest.mark.parametrize("change, message", [
    ({"algo": "ddpg"}, "algo='ddpg': unknown algorithm; valid: ppo, a2c, sac, td3, fleet, bc"),
    ({"timesteps": 0}, "timesteps=0: should be greater than or equal to 1"),
    ({"timesteps": "many"}, "timesteps='many'"),
    ({"hp_overrides": {"lerning_rate": 1e-3}}, "unknown PPO hyperparameters \\['lerning_rate'\\]; valid: .*learning_rate"),
    ({"algo": "bc", "hp_overrides": {"epoch": 3}}, "unknown bc hyperparameters \\['epoch'\\]; valid: .*epochs"),
    ({"algo": "sac", "env_id": "CartPole-v1"}, "env_id='CartPole-v1': sac trains on lawn/Joint-v1, lawn/Comm-v1"),
    ({"env_id": "lawn/Nope-v0"}, "env_id='lawn/Nope-v0': ppo trains on"),
    ({"vec": "fast"}, "vec='fast': should be 'dummy' or 'native'"),
    ({"vec": "native", "env_id": "lawn/Parallel-v0"}, "--vec native runs lawn/Joint-v1"),
    ({"dataset": "lawn/x-v0"}, "only behaviour cloning"),
    ({"eval_episodes": 0}, "eval_episodes=0"),
    ({"seed": -1}, "seed=-1"),
    ({"hp": {}}, "unknown TrainSpec field 'hp'.*valid TrainSpec fields: algo, env_id"),
])
def test_the_spec_names_the_bad_field_its_value_and_what_is_allowed(tmp_path, change, message):
    from lawn_env import ConfigError

    base = dict(algo="ppo", env_id="lawn/Joint-v1", timesteps=64, out_dir=tmp_path / "r")
    with pytest.raises(ConfigError, match=message):
        TrainSpec(**{**base, **change})
    assert not (tmp_path / "r").exists()  # a spec writes nothing


def test_the_spec_is_frozen_and_a_replaced_copy_is_checked_again(tmp_path):
    import dataclasses

    spec = TrainSpec(algo="ppo", env_id="lawn/Joint-v1", timesteps=64, out_dir=str(tmp_path))
    assert spec.out_dir == tmp_path and spec.config == ScenarioConfig() and spec.vec == "dummy"
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.seed = 1
    assert dataclasses.replace(spec, seed=5).seed == 5 and spec.seed == 0
    with pytest.raises(ValueError, match="timesteps=-1"):
        dataclasses.replace(spec, timesteps=-1)
    params, version = dataclasses.replace(spec, n_envs=3, interface="v0").hyperparams()
    assert params["n_envs"] == 3 and params["interface"]["action_scheme"] == "direct" and version >= 1


def test_the_registry_matches_the_hyperparameter_files_and_the_loaders():
    """Every algorithm has an entry for exactly the envs it trains on in its own file; an SB3
    algorithm's learner is the class that ``sb3:DIR`` loads its runs with; no other name trains."""
    import yaml

    from agents.runs import ALGORITHMS as LOADERS
    from training.spec import ALGORITHMS, ALGOS, HYPERPARAMS_DIR, TRAIN_ENV_IDS

    assert ALGOS == ("ppo", "a2c", "sac", "td3", "fleet", "bc")
    for name, algo in ALGORITHMS.items():
        data = yaml.safe_load((HYPERPARAMS_DIR / algo.hyperparams).read_text())
        assert set(data) - {"version"} == set(algo.envs), name
        assert set(algo.envs) <= set(TRAIN_ENV_IDS)
        if algo.learner.startswith("stable_baselines3:"):
            assert LOADERS[name][0] == algo.learner
            assert algo.load().__name__ == name.upper()
        else:
            assert callable(algo.load())
    with pytest.raises(ValueError, match="unknown algorithm 'ddpg'; valid: ppo, a2c, sac, td3, fleet, bc"):
        load_hyperparams("ddpg", "lawn/Joint-v1")


def test_rl_zoo_reads_the_recipes_module():
    from training import recipes

    assert set(recipes.hyperparams) == {"lawn/JointRL-v1", "lawn/CommRL-v1"}
    entry = next(iter(recipes.hyperparams.values()))
    assert "interface" not in entry and entry["policy"] == "MlpPolicy" and isinstance(entry["normalize"], str)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        recipes.nope


def test_paired_reward_run_trains_on_the_paired_reward_and_logs_the_envs_own(tmp_path):
    # PPO on the RL interface with the reward paired against epa: the monitor logs keep the env's rewards
    out, _ = _train(tmp_path, "ppo", steps=128, interface="rl", hp_overrides={"paired_anchor": "epa", "gamma": 0.9})
    assert json.loads((out / "hyperparams.json").read_text())["paired_anchor"] == "epa"
    from stable_baselines3.common.monitor import Monitor

    from training.paired import PairedReward
    from training.sb3 import make_train_env

    venv = make_train_env("lawn/Joint-v1", SMALL, 1, 0, False, tmp_path / "m", interface="rl",
                          paired={"anchor": "epa", "gamma": 0.9})
    wrapper = venv.envs[0]
    assert isinstance(wrapper, PairedReward) and isinstance(wrapper.env, Monitor)  # the monitor logs the env's reward
    assert wrapper.gamma == 0.9 and wrapper.anchor.name == "epa"
    returns = [float(row["r"]) for f in sorted((out / "monitor").glob("*.monitor.csv"))
               for row in csv.DictReader(f.read_text().splitlines()[1:])]
    assert returns and all(r <= 0 for r in returns)  # the RL interface's rewards are at most zero; pairs are not
    with pytest.raises(ValueError, match="paired_anchor='nope': unknown policy"):
        TrainSpec(algo="ppo", env_id="lawn/Joint-v1", timesteps=64, out_dir=tmp_path / "x",
                  hp_overrides={"paired_anchor": "nope"})
    with pytest.raises(ValueError, match="paired_anchor='bogus:x': unknown policy"):
        TrainSpec(algo="ppo", env_id="lawn/Joint-v1", timesteps=64, out_dir=tmp_path / "x",
                  hp_overrides={"paired_anchor": "bogus:x"})
    assert TrainSpec(algo="ppo", env_id="lawn/Joint-v1", timesteps=64, out_dir=tmp_path / "z",
                     hp_overrides={"paired_anchor": "anchor:stake"}).hyperparams()[0]["paired_anchor"] == "anchor:stake"
    with pytest.raises(ValueError, match="paired reward wraps"):
        TrainSpec(algo="ppo", env_id="CartPole-v1", timesteps=64, out_dir=tmp_path / "y",
                  hp_overrides={"paired_anchor": "epa"})


def test_residual_run_records_its_scheme_and_acts_by_it(tmp_path):
    # PPO around epa, started at the anchor: validation plays the residual, and so does the loaded agent
    residual = {"anchor": "epa", "scale": 0.3}
    out, _ = _train(tmp_path, "ppo", steps=128, interface="rl", n_envs=1,
                    hp_overrides={"residual": residual, "start_at_anchor": True})
    assert json.loads((out / "run.json").read_text())["residual"] == residual
    policy = make_policy(f"sb3:{out}", SMALL)
    assert policy.residual is not None and policy.residual.anchor.name == "epa" and policy.residual.scale == 0.3
    start = [r for r in csv.DictReader((out / "learning_curve.csv").read_text().splitlines())][0]
    from agents.residual import AnchorResidual

    zero = AnchorResidual(gym.make("lawn/Joint-v1", config=SMALL, interface="rl"), make_policy("epa", SMALL), 0.3)
    zero.reset(seed=VALIDATION_SEED_BASE)
    while not zero.unwrapped.sim.done:
        zero.step(np.zeros(zero.action_space.shape, np.float32))
    # the run starts at the anchor: its first validation is the zero residual's episode, which zero:sb3:DIR plays
    assert float(start["control_cost"]) == pytest.approx(zero.unwrapped.episode_metrics()["control_cost"], rel=1e-6)
    from evaluation.run import own_anchor, policy_env
    from lawn_env.rollouts import rollout

    at_zero = make_policy(f"zero:sb3:{out}", SMALL)
    assert at_zero.name == f"zero:sb3:{out}" and own_anchor(f"sb3:{out}") == at_zero.name
    assert policy_env(at_zero.name) == "lawn/Joint-v1"
    played = rollout(gym.make("lawn/Joint-v1", config=SMALL), at_zero, VALIDATION_SEED_BASE).metrics["control_cost"]
    assert played == pytest.approx(float(start["control_cost"]), rel=1e-6)
    for bad, match in (("zero:epa", "zero:zoo:NAME"), ("zero:anchor:stake", "zero:zoo:NAME")):
        with pytest.raises(ValueError, match=match):
            make_policy(bad, SMALL)
    with pytest.raises(ValueError, match="action_scheme='direct'"):
        TrainSpec(algo="ppo", env_id="lawn/Joint-v1", timesteps=64, out_dir=tmp_path / "x",
                  hp_overrides={"residual": residual, "interface": "v0"})
    with pytest.raises(ValueError, match="scale=5"):
        TrainSpec(algo="ppo", env_id="lawn/Joint-v1", timesteps=64, out_dir=tmp_path / "x",
                  hp_overrides={"residual": {"anchor": "epa", "scale": 5}, "interface": "rl"})
    from training.sb3 import make_train_env

    with pytest.raises(ValueError, match="residual scheme wraps single envs"):
        make_train_env("lawn/Joint-v1", SMALL, 1, 0, False, None, interface="rl", vec="native", residual=residual)


def test_a_residual_of_the_link_on_the_paired_reward_records_its_expert_time(tmp_path):
    # the learner moves the power and the drone only; both anchors (the residual's and the paired reward's
    # shadow) and validation's decide on the run's clock, which run.json and summary.md report
    residual = {"anchor": "epa", "scale": 0.3, "moves": ["power", "drone"]}
    out, summary = _train(tmp_path, "ppo", steps=128, interface="rl", n_envs=1,
                          hp_overrides={"residual": residual, "paired_anchor": "epa", "start_at_anchor": True})
    record = json.loads((out / "run.json").read_text())
    assert record["residual"] == residual
    assert 0 < record["expert_decision_s"] < record["wall_time_s"]
    assert summary.expert_share == round(record["expert_decision_s"] / record["wall_time_s"], 3) > 0
    policy = make_policy(f"sb3:{out}", SMALL)
    assert policy.residual.size == SMALL.num_agvs + 2 and policy.network.action_space.shape == (SMALL.num_agvs + 2,)
    state = json.loads(next((out / "checkpoints").glob("*/state.json")).read_text())
    assert state["expert_decision_s"] == pytest.approx(record["expert_decision_s"])  # the final checkpoint's
    resume(out, timesteps=256, progress=False)  # the resumed run adds its expert time to the checkpoint's
    assert json.loads((out / "run.json").read_text())["expert_decision_s"] > record["expert_decision_s"]
    plain, _ = _train(tmp_path, "ppo", steps=128, interface="rl", n_envs=1, name="plain")
    assert json.loads((plain / "run.json").read_text())["expert_decision_s"] == 0.0  # no expert decides
