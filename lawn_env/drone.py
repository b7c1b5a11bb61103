"""Drone kinematics at fixed altitude (MODEL.md §1, §4).

Per slot the drone moves at most V_max * Delta-tau and stays inside the area D:
``||q[n] - q[n-1]|| <= V_max Delta-tau`` and ``q[n] in D`` (paper, constraints of P1).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["move_drone", "move_drones"]


def move_drone(position_m: np.ndarray, velocity_mps: np.ndarray, max_speed_mps: float, slot_s: float,
               area_m: tuple[float, float, float, float]) -> np.ndarray:
    """Next drone position: the commanded velocity clipped to V_max (radially), integrated over
    one slot, then clipped into the area box. Clipping into the box only shortens the move, so
    the speed limit still holds. (Scalar arithmetic: this runs every env step.)"""
    vx, vy = velocity_mps
    vx, vy = float(vx), float(vy)
    speed = math.hypot(vx, vy)
    if speed > max_speed_mps:
        vx, vy = vx * max_speed_mps / speed, vy * max_speed_mps / speed
    x0, x1, y0, y1 = area_m
    px, py = position_m.tolist() if isinstance(position_m, np.ndarray) else map(float, position_m)
    qx = min(max(px + vx * slot_s, x0), x1)
    qy = min(max(py + vy * slot_s, y0), y1)
    return np.array([qx, qy])


def move_drones(position_m: np.ndarray, velocity_mps: np.ndarray, max_speed_mps: float, slot_s: float,
                area_m: tuple[float, float, float, float]) -> np.ndarray:
    """:func:`move_drone` over a batch: positions and velocities (B, 2) -> next positions (B, 2).
    The same rule (radial speed clip, integrate, clip into the box); a test checks the two agree."""
    velocity = np.asarray(velocity_mps, dtype=float)
    speed = np.sqrt((velocity * velocity).sum(axis=-1, keepdims=True))
    velocity = velocity * np.minimum(1.0, max_speed_mps / np.maximum(speed, 1e-300))
    x0, x1, y0, y1 = area_m
    nxt = np.asarray(position_m, dtype=float) + velocity * slot_s
    np.clip(nxt, (x0, y0), (x1, y1), out=nxt)
    return nxt
