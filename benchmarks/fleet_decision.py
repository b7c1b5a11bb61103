"""How long a fleet network takes to decide, compiled and in torch, beside rg-mpc.

``agents.fleet.FleetInference`` replaces the torch forward pass of a fleet network
(``agents.fleet.FleetPolicy``) for one observation; the torch module stays the oracle
(tests/test_fleet.py). This script times, for fleets of 4 to 64 AGVs on ``lawn/Joint-v1``'s
entity layout, the forward pass both ways (interleaved, the median of repeated blocks) on the
states of one rg-mpc episode, with the shipped size of the network (``training/hyperparams/fleet.yml``:
width 32, 4 heads, 2 layers; random weights: the time does not depend on them), and rg-mpc's own
decision on the same states (timed as it played them). Ratios, not times, are the result.

Usage: ``python benchmarks/fleet_decision.py [--markdown out.md]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

SIZES = (4, 16, 32, 64)
WIDTH, HEADS, LAYERS = 32, 4, 2
STATES = 12
REPEATS = 7


def _states(k: int) -> tuple[list, list, object]:
    """The entity observations of the first slots of one rg-mpc episode at K = k, the expert's
    time to decide each (warm-started along the episode, as it runs) and the layout."""
    import gymnasium as gym

    from agents import make_policy
    from lawn_env import ScenarioConfig
    from lawn_env.entities import EntityLayout
    from lawn_env.interface import resolve_interface

    config = ScenarioConfig(num_agvs=k)
    env = gym.make("lawn/Joint-v1", config=config)
    expert = make_policy("rg-mpc", config, env_id="lawn/Joint-v1")
    obs, _ = env.reset(seed=0)
    expert.reset(0)
    iface = resolve_interface({"base": "rl", "layout": "entities"})
    layout = EntityLayout(config, "joint", iface.obs_bound, iface.action_scheme)
    entity, expert_s = [], []
    for _ in range(STATES):
        entity.append({key: value[0] for key, value in layout.observe(iface.observe(obs.copy())[None]).items()})
        start = time.perf_counter()
        action = expert.act(obs)
        expert_s.append(time.perf_counter() - start)
        obs, *_ = env.step(action)
    return entity, expert_s, layout


def _block(fn, items) -> float:
    start = time.perf_counter()
    for x in items:
        fn(x)
    return (time.perf_counter() - start) / len(items)


def measure(k: int) -> dict[str, float]:
    import torch

    from agents.fleet import FleetInference, FleetPolicy

    torch.set_num_threads(1)
    entity, expert_s, layout = _states(k)
    policy = FleetPolicy(layout.observation_space, layout.action_space, lambda _: 1e-3, width=WIDTH, heads=HEADS,
                         layers=LAYERS)
    fast = FleetInference(policy)
    tensors = [{key: torch.as_tensor(v)[None] for key, v in x.items()} for x in entity]

    def slow(x):
        with torch.no_grad():
            return policy.get_distribution(x).mode()

    times = {"compiled": [], "torch": []}
    fast(entity[0])
    slow(tensors[0])
    for _ in range(REPEATS):  # interleaved blocks
        times["compiled"].append(_block(fast, entity))
        times["torch"].append(_block(slow, tensors))
    return {**{name: float(np.median(t)) for name, t in times.items()}, "rg-mpc": float(np.median(expert_s))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--markdown", help="also write the table to this file")
    args = parser.parse_args(argv)
    lines = [f"Fleet network of the shipped size (width {WIDTH}, {HEADS} heads, {LAYERS} layers) on "
             f"`lawn/Joint-v1`'s entity layout, one observation at a time, one thread, {STATES} states of an rg-mpc "
             f"episode, median of {REPEATS} interleaved blocks; rg-mpc's decision: the median over the same "
             "states, as it decided them in the episode (the forward pass alone, not the whole decision: "
             "docs/LEARNED.md's table over fleet sizes times whole decisions side by side):", "",
             "| K | compiled forward (ms) | torch forward (ms) | torch / compiled | rg-mpc decision (ms) "
             "| rg-mpc / compiled |", "|---|---|---|---|---|---|"]
    for k in SIZES:
        t = measure(k)
        lines.append(f"| {k} | {t['compiled'] * 1e3:.3f} | {t['torch'] * 1e3:.3f} | {t['torch'] / t['compiled']:.1f}× "
                     f"| {t['rg-mpc'] * 1e3:.2f} | {t['rg-mpc'] / t['compiled']:.0f}× |")
    print("\n".join(lines))
    if args.markdown:
        Path(args.markdown).write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
