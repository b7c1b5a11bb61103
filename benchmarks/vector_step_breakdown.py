"""Where a native vector env step spends its time: each part of
``JointVectorEnv.step`` timed on its own at N envs, beside the whole step, in one run.

Parts: checking the actions, decoding them, the slot's draws, the simulation step
(:func:`lawn_env.core.step`, pure: the same slot every call), and the observation
(``ObservationLayout.encode``).
Each figure is the best of ``--repeats`` timings of ``--number`` calls, in microseconds per
batched step, with the env-steps/s the part alone would allow.

Usage: ``python benchmarks/vector_step_breakdown.py [--num-envs 1024] [--num-agvs 4]``
"""

from __future__ import annotations

import argparse
import timeit

import gymnasium as gym

import lawn_env  # noqa: F401  (registers the ids)
from lawn_env import core
from lawn_env.spaces import check_action


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--num-envs", type=int, default=1024)
    parser.add_argument("--num-agvs", type=int, default=4)
    parser.add_argument("--number", type=int, default=50, help="calls per timing (default: 50)")
    parser.add_argument("--repeats", type=int, default=5, help="timings per part; the best counts (default: 5)")
    parser.add_argument("--markdown", help="also write the README's table of this run to this file")
    args = parser.parse_args(argv)
    envs = gym.make_vec("lawn/Joint-v1", num_envs=args.num_envs, vectorization_mode="vector_entry_point",
                        num_agvs=args.num_agvs)
    env = envs.unwrapped
    envs.reset(seed=0)
    envs.action_space.seed(0)
    action = envs.action_space.sample()
    for _ in range(5):
        envs.step(action)
    engine, sim = env.engine, env.sim
    checked = check_action(action, env.single_action_space.shape[0], "action", env.num_envs)
    state = sim.state

    def decode():
        return engine.actions.decode(checked, state.x_obs, None, state.drone_position, state.slot)

    decision = decode()  # the parts of step, timed one by one
    decisions = core.Decisions(decision.increment, decision.power_w, decision.drone_next)
    draws = env._draw()
    parts = [
        ("whole step (its autoresets included)", lambda: envs.step(action)),
        ("check the actions", lambda: check_action(action, env.single_action_space.shape[0], "action", env.num_envs)),
        ("decode the actions", decode),
        ("draw the slot's randomness", env._draw),
        ("simulation step", lambda: core.step(sim.params, state, decisions, draws)),
        ("observation (encode)", lambda: engine.observe()),
    ]
    print(f"lawn/Joint-v1 vector env, N = {args.num_envs}, K = {args.num_agvs}: microseconds per batched step")
    print(f"{'part':45s} {'us/step':>10s} {'env-steps/s alone':>18s}")
    rows = []
    for name, fn in parts:
        best = min(timeit.repeat(fn, number=args.number, repeat=args.repeats)) / args.number
        rows.append((name.strip(), best))
        print(f"{name:45s} {best * 1e6:10.1f} {args.num_envs / best:18,.0f}")
    envs.close()
    if args.markdown:
        lines = [f"`lawn/Joint-v1` vector env, N = {args.num_envs}, K = {args.num_agvs} "
                 f"(best of {args.repeats} timings of {args.number} calls):", "",
                 "| part of a step | µs per batched step | env-steps/s it alone allows |", "|---|---|---|"]
        lines += [f"| {name} | {best * 1e6:,.0f} | {args.num_envs / best:,.0f} |" for name, best in rows]
        with open(args.markdown, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
