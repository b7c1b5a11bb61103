"""A simple scripted policy for ``lawn/Joint-v1``: the demo's driver and a sanity baseline.

It reads only the observation (decoded with :class:`lawn_env.ObservationLayout`):

* each AGV: a PD tracking law with acceleration feed-forward,
  ``u = a_ref + k_p (p_ref - p) + k_d (v_ref - v)``, sent as the increment ``u - u[n-1]``;
* power: split in proportion to the squared distance to each AGV (equalizes mean SNR);
* drone: flies toward the centroid of the AGVs at full speed.

It is not one of the paper's baselines (:mod:`agents.policies` has those); it is the "do something
reasonable" reference point for the demo and for smoke tests.
"""

from __future__ import annotations

import math

import numpy as np

from lawn_env.channel import LinkParams
from lawn_env.core import Decisions
from lawn_env.dynamics import ACCELERATION, POSITION, VELOCITY
from lawn_env.presets import ConfigLike

from .base import JOINT, Policy

__all__ = ["HeuristicPolicy"]


class HeuristicPolicy(Policy):
    """PD tracking + distance-proportional power + centroid-seeking drone, from observations."""

    name = "heuristic"
    env_ids = (JOINT,)

    def __init__(self, config: ConfigLike = None, env_id: str = JOINT, seed: int | None = None, kp: float = 0.4,
                 kd: float = 0.9):
        super().__init__(config, env_id, seed)
        self.kp, self.kd = float(kp), float(kd)
        self.link = LinkParams.from_config(self.config)

    def act(self, obs: np.ndarray) -> np.ndarray:
        cfg = self.config
        s = self.layout.decode(obs)
        x, ref, q = s["x_aug"], s["reference"], s["drone_position"]
        target = ref[:, 1]  # the reference one slot ahead
        u = (target[:, ACCELERATION] + self.kp * (target[:, POSITION] - x[:, POSITION])
             + self.kd * (target[:, VELOCITY] - x[:, VELOCITY]))
        amax = cfg.control.accel_max_mps2
        du = np.clip(u, -amax, amax) - x[:, ACCELERATION]
        d2 = self.link.distance_sq(q, x[:, POSITION])
        power = cfg.power_budget_w * d2 / d2.sum()
        centroid = x[:, POSITION].mean(axis=0)
        step = centroid - q
        dist = math.hypot(*step.tolist())
        reach = cfg.drone_reach_m
        q_next = centroid if dist <= reach else q + step * (reach / dist)
        return self.actions.encode(Decisions(du, power, q_next), x, None, q)
