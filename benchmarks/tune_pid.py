"""Grid search of the predictive PID's gains (the defaults of ``agents.policies.PIDGains``).

Tracking only: perfect links (the ``paper-nominal`` preset, where outage is ~1e-6), equal power,
hovering drone, so the gains are judged on control alone. Objective: mean realized control cost
over seeds 0..2 of ``lawn/Joint-v1``. Prints the best gains and the ten best rows.

Usage: ``python benchmarks/tune_pid.py``
"""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np

import lawn_env  # noqa: F401
from agents import rollout
from agents.tracking import PIDGains, pid_rollout
from lawn_env import presets
from lawn_env.core import Decisions
from lawn_env.dynamics import PredictionModel
from lawn_env.spaces import DirectActions


class TrackingPID:
    """The PID tracking law alone (equal power, hovering drone), acting on the env's full state."""

    def __init__(self, env, gains: PIDGains):
        self.env, self.gains = env, gains
        self.cfg = env.config
        self.model = PredictionModel.from_config(self.cfg)
        k, budget = self.cfg.num_agvs, self.cfg.power_budget_w
        self.power = np.full(k, budget / k)
        self.actions = DirectActions(self.cfg, "joint")

    def reset(self, seed: int | None = None) -> None:
        self.integral = np.zeros((self.cfg.num_agvs, 2))

    def act(self, obs: np.ndarray) -> np.ndarray:
        c = self.cfg.control
        snap = self.env.snapshot()
        du, self.integral = pid_rollout(snap.x_aug, snap.reference, self.integral, self.model, self.gains,
                                        c.accel_max_mps2, c.accel_increment_max_mps2)
        q = snap.drone_position
        return self.actions.encode(Decisions(du[:, 0], self.power, q), snap.x_aug, None, q)  # a hovering drone


def episode_cost(kp: float, ki: float, kd: float, seed: int) -> float:
    env = gym.make("lawn/Joint-v1", config=presets.get("paper-nominal")).unwrapped
    return rollout(env, TrackingPID(env, PIDGains(kp=kp, ki=ki, kd=kd, integral_limit=10.0)), seed).metrics["control_cost"]


def main() -> None:
    rows = []
    for kp, ki, kd in itertools.product([0.1, 0.2, 0.3, 0.5, 0.8], [0.0, 0.02, 0.05], [0.4, 0.6, 0.9, 1.2]):
        cost = float(np.mean([episode_cost(kp, ki, kd, seed) for seed in range(3)]))
        rows.append((cost, kp, ki, kd))
    rows.sort()
    print(f"{'cost':>10} {'kp':>5} {'ki':>5} {'kd':>5}")
    for cost, kp, ki, kd in rows[:10]:
        print(f"{cost:10.1f} {kp:5.2f} {ki:5.2f} {kd:5.2f}")
    print(f"best: kp={rows[0][1]}, ki={rows[0][2]}, kd={rows[0][3]}")


if __name__ == "__main__":
    main()
