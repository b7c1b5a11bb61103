"""The demo: one seeded episode of ``lawn/Joint-v0`` under the scripted heuristic."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym

import lawn_env  # noqa: F401  (registers the ids)
from agents import HeuristicPolicy, rollout
from lawn_env import ScenarioConfig
from lawn_env.render import plot_episode


def run_demo(seed: int, out_dir: Path, config: ScenarioConfig | str | None = None,
             overrides: dict | None = None) -> dict:
    """Run one episode, write ``metrics.json`` and ``paths.png`` into ``out_dir``; return the metrics."""
    env = gym.make("lawn/Joint-v0", config=config, **(overrides or {}))
    episode = rollout(env, HeuristicPolicy(env.unwrapped.config), seed)
    metrics = dict(episode.metrics)
    metrics["decision_time_median_s"] = episode.decision_time_median_s
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2))
    plot_episode(env.unwrapped.sim, env.unwrapped.engine.trail, out_dir / "paths.png",
                 title=f"lawn/Joint-v0, scripted heuristic, seed {seed}: cost {metrics['control_cost']:.0f}")
    env.close()
    return metrics
