"""The demo: one seeded episode of ``lawn/Joint-v0`` under the scripted heuristic."""

from __future__ import annotations

import json
import time
from pathlib import Path

import gymnasium as gym

import lawn_env  # noqa: F401  (registers the ids)
from agents import HeuristicPolicy
from lawn_env.render import plot_episode


def run_demo(seed: int, out_dir: Path, config=None, overrides: dict | None = None) -> dict:
    """Run one episode, write ``metrics.json`` and ``paths.png`` into ``out_dir``; return the metrics."""
    env = gym.make("lawn/Joint-v0", config=config, **(overrides or {}))
    policy = HeuristicPolicy(env.unwrapped.config)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    done = False
    decision_s = []
    while not done:
        start = time.perf_counter()
        action = policy.act(obs)
        decision_s.append(time.perf_counter() - start)
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    metrics = dict(info["episode_metrics"])
    metrics["decision_time_median_s"] = sorted(decision_s)[len(decision_s) // 2]
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2))
    plot_episode(env.unwrapped.sim, out_dir / "paths.png",
                 title=f"lawn/Joint-v0, scripted heuristic, seed {seed}: cost {metrics['control_cost']:.0f}")
    env.close()
    return metrics
