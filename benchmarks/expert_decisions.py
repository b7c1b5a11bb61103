"""The experts' decisions, one at a time and in batches, and an evaluation's episodes: the figures
``benchmarks/side_by_side.py`` compares with the commit before a change.

* ``EXPERT K=k single (ms)``: the median of one decision's time (a batch of one) along a closed-loop
  episode of ``lawn/Joint-v1`` (the default task at K = 4, the presets ``k16`` and ``k32``), its first
  slots (the tail's tables built on first use) left out;
* ``EXPERT K=k batch B (ms/scenario)``: B scenarios (seeds 0..B-1) decided together, the median batch's
  time over B. A policy that decides a batch at once (``Policy.batched``: ``dv-mpc``) plans them in one
  call; the others (and every policy of a tree without the batched interface) decide them one by one;
* ``evaluate EXPERT (s/episode)``: ``evaluation.run.evaluate`` of 2 and of 2 + E episodes of the
  default task (``lawn evaluate --workers 1``), the difference over E: an episode beyond start-up.

CPU seconds of this single-threaded process (a busy host's other work does not inflate them).

``--link-law`` reports instead psi = gammaincc(2, x) per link by scipy's routine and by Erlang's closed
form (``lawn_env.channel.outage_law``'s SERIES, ``dv-mpc``'s search); ``--memory B`` reports instead the peak resident memory of ``dv-mpc`` deciding B scenarios at K = 32
together (the native vector env, a few slots).

Usage: ``python benchmarks/expert_decisions.py [--experts dv-mpc rg-mpc ao-mpc] [--sizes 4 16 32]
[--batch 256] [--episodes 8] [--json FILE] [--markdown FILE] [--memory B]``; side by side:
``python benchmarks/side_by_side.py --commit C --repeats 3 --figures -- python benchmarks/expert_decisions.py``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import gymnasium as gym
import numpy as np

import lawn_env
from agents import make_policy
from lawn_env import ScenarioConfig, presets

JOINT = next(i for i in lawn_env.ENV_IDS if i.startswith("lawn/Joint-"))
WARMUP = 4  # slots left out of the single-decision figure (the tail's tables, the QPs' first solves)


def _config(k: int) -> ScenarioConfig:
    return ScenarioConfig() if k == 4 else presets.get(f"k{k}")


def single(expert: str, k: int, slots: int) -> float:
    """The median CPU seconds of one decision along a closed-loop episode (seed 0)."""
    config = _config(k)
    env = gym.make(JOINT, config=config)
    policy = make_policy(expert, config)
    obs, _ = env.reset(seed=0)
    policy.reset(0)
    times = []
    for _ in range(WARMUP + slots):
        start = time.process_time()
        action = policy.act(obs)
        times.append(time.process_time() - start)
        obs, *_ = env.step(action)
    return statistics.median(times[WARMUP:])


def batch(expert: str, k: int, size: int, slots: int) -> float:
    """The median CPU seconds per scenario of a batch of ``size`` scenarios' decisions (seeds 0..size-1)."""
    config = _config(k)
    envs = [gym.make(JOINT, config=config) for _ in range(size)]
    obs = np.stack([env.reset(seed=i)[0] for i, env in enumerate(envs)])
    policy = make_policy(expert, config)
    batched = getattr(policy, "batched", False)
    if batched:
        policy.reset_scenarios(list(range(size)))
    else:  # one by one: a policy per scenario, as a tree without the batched interface plays them
        policies = [make_policy(expert, config) for _ in range(size)]
        for i, p in enumerate(policies):
            p.reset(i)
    times = []
    for _ in range(WARMUP + slots):
        start = time.process_time()
        actions = policy.act_scenarios(obs) if batched else np.stack([p.act(o) for p, o in zip(policies, obs)])
        times.append(time.process_time() - start)
        obs = np.stack([env.step(a)[0] for env, a in zip(envs, actions)])
    return statistics.median(times[WARMUP:]) / size


def link_law() -> tuple[float, float]:
    """CPU nanoseconds per link of psi (m = 2) over a million outage arguments: scipy's gammaincc (every
    caller's law, ``LinkParams.success_at``) and Erlang's closed form (``dv-mpc``'s search), each in one
    compiled loop."""
    import numba

    from lawn_env import channel

    @numba.njit
    def law(x: np.ndarray, part: int) -> float:
        total = 0.0
        for v in x:
            total += channel.outage_law(2.0, v, part)
        return total

    x = np.random.default_rng(0).uniform(0.0, 6.0, 1_000_000)
    out = []
    for part in (channel.SUCCESS, channel.SERIES):
        law(x[:10], part)
        runs = []
        for _ in range(3):
            start = time.process_time()
            law(x, part)
            runs.append(time.process_time() - start)
        out.append(1e9 * min(runs) / x.size)
    return out[0], out[1]


def episodes(expert: str, extra: int) -> float:
    """CPU seconds per episode beyond start-up of ``evaluate`` (one process) on the default task."""
    from evaluation.episode import EpisodeSpec
    from evaluation.run import evaluate

    def play(count: int) -> float:
        tasks = [EpisodeSpec(expert, JOINT, ScenarioConfig(), seed) for seed in range(count)]
        start = time.process_time()
        evaluate(tasks, workers=1, progress=False)
        return time.process_time() - start

    play(1)  # compiled kernels loaded, tables built
    return (play(2 + extra) - play(2)) / extra


def memory(size: int, k: int = 32, slots: int = 4) -> float:
    """Peak resident memory (GB) of this process after ``dv-mpc`` decides ``size`` scenarios at K = k together
    for a few slots (the native vector env's scenarios, independent draws)."""
    import resource

    config = _config(k)
    envs = gym.make_vec(JOINT, num_envs=size, vectorization_mode="vector_entry_point", config=config)
    obs, _ = envs.reset(seed=list(range(size)), options={"independent_draws": True})
    policy = make_policy("dv-mpc", config)
    policy.reset_scenarios(list(range(size)))
    for _ in range(slots):
        obs, *_ = envs.step(policy.act_scenarios(obs))
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # kB on Linux


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experts", nargs="+", default=["dv-mpc", "rg-mpc", "ao-mpc"])
    parser.add_argument("--sizes", nargs="+", type=int, default=[4, 16, 32])
    parser.add_argument("--batch", type=int, default=256, help="B of the batched figures (default: %(default)s)")
    parser.add_argument("--slots", type=int, default=12, help="timed slots per figure (default: %(default)s)")
    parser.add_argument("--episodes", type=int, default=8, help="E of the evaluate figures (default: %(default)s)")
    parser.add_argument("--link-law", action="store_true", help="only the link law's two forms, timed")
    parser.add_argument("--memory", type=int, metavar="B", help="only the peak memory of B scenarios at K = 32 "
                        "decided together (this tree's batched interface)")
    parser.add_argument("--json", help="also write the figures to this JSON file")
    parser.add_argument("--markdown", help="also write them as a Markdown table to this file")
    args = parser.parse_args(argv)
    if args.memory:
        print(f"peak resident memory, dv-mpc deciding {args.memory} scenarios at K = 32 together: "
              f"{memory(args.memory):.2f} GB")
        return 0
    if args.link_law:
        scipy_ns, series_ns = link_law()
        print(f"psi (m = 2) per link: scipy's gammaincc {scipy_ns:.1f} ns, Erlang's closed form {series_ns:.1f} ns "
              f"({scipy_ns / series_ns:.1f}x)")
        return 0
    figures: dict[str, float] = {}
    for expert in args.experts:
        for k in args.sizes:
            figures[f"{expert} K={k} single (ms)"] = 1e3 * single(expert, k, args.slots)
            size = args.batch if expert == "dv-mpc" else 8  # one by one: a few scenarios say the same
            figures[f"{expert} K={k} batch {size} (ms/scenario)"] = 1e3 * batch(expert, k, size, args.slots)
    for expert in args.experts:
        if expert != "ao-mpc":
            figures[f"evaluate {expert} (s/episode)"] = episodes(expert, args.episodes)
    for name, value in figures.items():
        print(f"{name:<40}{value:>12.4f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(figures, fh, indent=1)
    if args.markdown:
        with open(args.markdown, "w") as fh:
            fh.write("| figure | value |\n|---|---|\n" + "".join(f"| {n} | {v:.4g} |\n" for n, v in figures.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
