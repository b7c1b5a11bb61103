"""Where learning from scratch stops: what the learner's reward tells it, per rung of the ladder.

For each rung of ``lawn_env.presets.LADDER`` and the interface of its scratch recipe
(``paper.ladder.ladder_recipes``), on ``--seeds`` validation seeds (500,000..), common random numbers throughout:

* **signal against noise per slot.** The prior (the interface's zero action) and ``dv-mpc`` play the
  same seeds; per slot, the reward the learner would get (the interface's transform of the stage cost)
  differs between them by a mean (the signal: what a better policy earns there) with a spread over the
  seeds (the noise one sample of that slot carries). Printed: the episode's summed signal, the
  per-slot signal-to-noise ratio (median over slots of |mean| / std; inf where a slot's reward has no
  noise) and the share of the stage cost's
  gain (dv-mpc against the prior, summed over slots) that falls in slots where the transform is flat
  (the prior's cost above the clip: no gradient there).
* **credit over the horizon.** The prior plays, but at slot ``t0`` takes ``dv-mpc``'s decision
  (dv-mpc follows the episode throughout); the stage-cost change that one decision makes, slot by
  slot after it: the slots until 90 % of it has arrived, beside the discount's horizon
  ``1 / (1 - gamma)`` and GAE's ``1 / (1 - gamma lambda)``.
* **exploration scale.** ``dv-mpc``'s decisions in the interface's action units (the prior is 0): their
  RMS per action group (power, drone, increments) and the share outside [-1, 1] (out of the policy's
  reach), beside the policy's initial noise ``exp(log_std_init)``.

Usage: ``python benchmarks/learning_signal.py [--seeds 24] [--reward scaled:100 log:10000] [--json FILE]
[--markdown FILE]``
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

from agents import make_policy
from agents.anchors import anchor_name
from lawn_env import presets
from lawn_env.interface import resolve_interface
from paper.ladder import ladder_recipes
from training.datasets import label_transitions

SEED_BASE = 500_000  # the validation seeds: no test seed is used to diagnose
T0 = (0, 3, 10, 40)  # the slots whose one decision is swapped


def play(env_id: str, config, prior, expert, seed: int, swap: int | None = None, record: bool = False):
    """One episode of the plain env: the prior's decisions (``swap``: the expert's at that slot only; None with
    ``prior=None``: the expert's throughout); the stage costs, and the v0 observations and expert actions."""
    env = gym.make(env_id, config=config)
    obs, _ = env.reset(seed=seed)
    for p in (prior, expert):
        if p is not None:
            p.reset(seed=seed)
    costs, observations, actions, done, t = [], [], [], False, 0
    while not done:
        a_expert = expert.act(obs)
        action = a_expert if prior is None or t == swap else prior.act(obs)
        if record:
            observations.append(obs)
            actions.append(a_expert)
        obs, _, terminated, truncated, info = env.step(action)
        costs.append(float(info["stage_cost"]))
        done, t = terminated or truncated, t + 1
    env.close()
    return np.array(costs), (np.array(observations), np.array(actions))


def diagnose(rung: presets.Rung, seeds: int, rewards: list[str]) -> dict[str, float]:
    recipe = dict(ladder_recipes())[rung]
    config, env_id = presets.get(rung.preset), rung.env_id
    iface = resolve_interface(recipe.hp["interface"])
    prior_name = anchor_name(iface)
    prior, expert = make_policy(prior_name, config, env_id=env_id), make_policy("dv-mpc", config, env_id=env_id)
    base, best, recorded = [], [], []
    for i in range(seeds):
        base.append(play(env_id, config, prior, expert, SEED_BASE + i)[0])
        c, episode = play(env_id, config, None, expert, SEED_BASE + i, record=True)
        best.append(c)
        recorded.append(episode)
    base, best = np.array(base), np.array(best)
    out: dict[str, float] = {"prior_cost": float(base.sum(1).mean()), "expert_cost": float(best.sum(1).mean())}
    gain = (base - best).sum()
    for variant in rewards:
        reward, _, clip = variant.partition(":")
        transform = dataclasses.replace(iface, reward=reward, cost_clip=float(clip or iface.cost_clip))
        diff = transform.rewards_from_costs(best) - transform.rewards_from_costs(base)
        std = diff.std(0, ddof=1)
        out[f"{variant}_signal_per_episode"] = float(diff.sum(1).mean())
        mean = np.abs(diff.mean(0))
        noisy = std > 1e-9 * np.maximum(mean, 1e-12)  # links that lose nothing: a slot's reward has no noise
        out[f"{variant}_slot_snr"] = float(np.median(np.where(noisy, mean / np.where(noisy, std, 1.0), np.inf)))
        flat = base > transform.cost_clip
        out[f"{variant}_gain_in_flat_slots"] = float(((base - best) * flat).sum() / gain) if gain else float("nan")
    params = recipe.spec(Path("."), 0).hyperparams().params  # the recipe's over the hyperparameter file's
    gamma, lam = float(params["gamma"]), float(params["gae_lambda"])
    out["discount_horizon"], out["gae_horizon"] = 1 / (1 - gamma), 1 / (1 - gamma * lam)
    for t0 in T0:
        swapped = np.array([play(env_id, config, prior, expert, SEED_BASE + i, swap=t0)[0] for i in range(seeds)])
        effect = (swapped - base).mean(0)[t0:]
        total = effect.sum()
        reach = np.cumsum(effect) / total if total else np.zeros_like(effect)
        out[f"credit_t{t0}_change"] = float(total)
        out[f"credit_t{t0}_slots_to_90pct"] = float(np.argmax(np.abs(reach) >= 0.9) + 1) if total else float("nan")
    actions = label_transitions(config, env_id, iface, recorded).actions
    k = config.num_agvs
    inc = 2 * k if env_id == "lawn/Joint-v1" else 0  # the actions: [increments (Joint)], power, drone
    groups = {"increments": slice(0, inc), "power": slice(inc, inc + k), "drone": slice(inc + k, inc + k + 2)}
    for name, cols in groups.items():
        part = actions[:, cols]
        if part.size:
            out[f"expert_rms_{name}"] = float(np.sqrt(np.mean(part**2)))
            out[f"expert_outside_{name}"] = float(np.mean(np.abs(part) > 1))
    out["initial_noise_std"] = float(np.exp(recipe.hp["policy_kwargs"]["log_std_init"]))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=24)
    parser.add_argument("--reward", nargs="+", default=["scaled:100", "log:10000"],
                        help="interface rewards to compare, REWARD[:COST_CLIP] (default: %(default)s)")
    parser.add_argument("--json", help="write the figures to this file")
    parser.add_argument("--markdown", help="write the page's table to this file")
    args = parser.parse_args(argv)
    figures = {}
    for rung in presets.LADDER:
        name = f"{rung.preset} ({rung.env_id.removeprefix('lawn/')})"
        figures[name] = diagnose(rung, args.seeds, args.reward)
        print(name)
        for key, value in figures[name].items():
            print(f"  {key:<34}{value:12.4g}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(figures, fh, indent=2)
    if args.markdown:
        with open(args.markdown, "w") as fh:
            fh.write(markdown(figures, args.reward, args.seeds) + "\n")
    return 0


def markdown(figures: dict[str, dict[str, float]], rewards: list[str], seeds: int) -> str:
    """The page's table: per rung, the costs, each reward's flat share and signal-to-noise, the credit of
    one decision, and the expert's distance from the prior in action units beside the initial noise."""
    head = ["rung", "prior / dv-mpc cost", *(f"gain where `{v}` is flat" for v in rewards),
            *(f"slot SNR, `{v}`" for v in rewards), "one decision at slot 3: change, slots to 90 %",
            "horizons: discount / GAE (slots)",
            "dv-mpc in action units (RMS): increments / power / drone", "initial noise (std)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, f in figures.items():
        rms = " / ".join(f"{f[k]:.2f}" if k in f else "–" for k in
                         ("expert_rms_increments", "expert_rms_power", "expert_rms_drone"))
        cells = [name, f"{f['prior_cost']:,.1f} / {f['expert_cost']:,.1f}",
                 *(f"{100 * f[f'{v}_gain_in_flat_slots']:.0f} %" for v in rewards),
                 *(f"{f[f'{v}_slot_snr']:.2f}" for v in rewards),
                 f"{f['credit_t3_change']:+,.2f}, {f['credit_t3_slots_to_90pct']:.0f}",
                 f"{f['discount_horizon']:.0f} / {f['gae_horizon']:.1f}", rms,
                 f"{f['initial_noise_std']:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", (f"{seeds} validation seeds (500,000..) a rung, common random numbers; the discount's horizon is "
                   "1 / (1 - gamma), GAE's 1 / (1 - gamma lambda), with the rung's recipe's gamma and lambda.")]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
