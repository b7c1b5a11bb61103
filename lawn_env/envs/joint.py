"""``lawn/Joint-v0``: the agent makes every decision of a slot."""

from __future__ import annotations

from typing import Any, Mapping

import gymnasium as gym
import numpy as np

from ..config import ScenarioConfig
from ..spaces import check_action, decode_power
from .base import LawnEnvBase

__all__ = ["JointEnv"]


class JointEnv(LawnEnvBase):
    """
    ## Description

    A drone at fixed altitude serves K ground AGVs that track reference paths. Every slot
    (0.5 s) the agent chooses each AGV's acceleration increment, the split of the transmit power
    budget over the K links and the drone's move. Each command reaches its AGV only if the
    short-packet link is not in outage (Nakagami-m fading, finite blocklength, MODEL.md §2); a
    lost command leaves the AGV on its previous acceleration. This is problem P1 of the paper
    with the agent in place of the optimizer.

    ## Action Space

    ``Box(-1, 1, (3K + 2,), float32)``:

    | index        | meaning                              | scaling                                              |
    |--------------|--------------------------------------|------------------------------------------------------|
    | 0 .. 2K-1    | increment Delta-u of AGV k (x, y)    | ``a * Delta-a_max`` m/s^2, then saturated so |u| <= a_max |
    | 2K .. 3K-1   | power weight of link k               | ``w = (a+1)/2``, ``p = P_max w / max(1, sum w)``      |
    | 3K .. 3K+1   | drone velocity (x, y)                | ``a * V_max`` m/s, clipped to norm V_max, kept in area |

    Actions outside [-1, 1], NaN, or of the wrong size raise ``ValueError``.

    ## Observation Space

    ``Box(-inf, inf, (K (17 + 6 (N_p+1)) + 3,), float32)``, normalized to order one: per AGV its
    position, velocity and previous acceleration, its tracking error, the reference window of N_p + 1 slots
    (relative position, velocity, acceleration), its position relative to the drone, the last
    outage probability, whether the last command arrived and the last power; then the drone
    position and the time. The table with scalings is :class:`lawn_env.spaces.ObservationLayout`;
    ``env.unwrapped.layout.decode(obs)`` inverts it.

    ## Rewards

    Minus the realized stage cost of the slot, summed over AGVs:
    ``e' Q1 e + Delta-u' Q2 Delta-u`` with ``e`` the augmented tracking error at slot n+1 and
    ``Delta-u`` the delivered increment (0 when lost). ``info["reward_terms"]`` splits it into
    ``tracking`` and ``effort``.

    ## Starting State

    AGVs start at their reference start plus N(0, 3 m) per axis, with the reference velocity
    and zero previous acceleration; the drone starts at ``drone.start_m`` (0, 100) m. Reference
    paths are the paper-like set for K = 3, 4, otherwise drawn from the seed.

    ## Episode End

    No termination; truncation after ``num_slots`` (120) slots. The last step's
    ``info["episode_metrics"]`` holds the metrics of MODEL.md §6.

    ## Arguments

    ``gym.make("lawn/Joint-v0", config=None, render_mode=None, **overrides)``: ``config`` is a
    :class:`~lawn_env.ScenarioConfig`, a dict or a preset name; overrides are top-level config
    fields or a section mapped to a dict, e.g. ``num_agvs=3, channel={"blocklength": 256}``.

    ## Version History

    * v0: initial version.
    """

    def __init__(self, config: ScenarioConfig | Mapping | str | None = None, render_mode: str | None = None,
                 **overrides: Any):
        super().__init__(config, render_mode, **overrides)
        k = self.num_agvs
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(3 * k + 2,), dtype=np.float32)
        self._size = 3 * k + 2
        ctl = self.config.control
        self._inc_max = ctl.accel_increment_max_mps2
        self._vmax = self.config.drone.max_speed_mps
        self._pmax = self.config.power_budget_w

    def step(self, action):
        self._check_running()
        a = check_action(action, self._size)
        k = self.num_agvs
        increment = a[: 2 * k].reshape(k, 2) * self._inc_max
        power = decode_power(a[2 * k : 3 * k], self._pmax)
        vx, vy = a[3 * k :].tolist()
        drone_next = self.sim.drone_target((vx * self._vmax, vy * self._vmax))
        return self._finish_step(self.sim.step(increment, power, drone_next))
