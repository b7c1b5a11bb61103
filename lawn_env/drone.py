"""Drone kinematics at fixed altitude (MODEL.md §1, §4).

Per slot the drone moves at most V_max * Delta-tau and stays inside the area D:
``||q[n] - q[n-1]|| <= V_max Delta-tau`` and ``q[n] in D`` (paper, constraints of P1).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["move_drone", "clip_to_speed", "project_feasible"]


def clip_to_speed(velocity_mps: np.ndarray, max_speed_mps: float) -> np.ndarray:
    """Scale a velocity (..., 2) radially so that its norm is at most ``max_speed_mps``."""
    v = np.asarray(velocity_mps, dtype=float)
    speed = np.sqrt(np.einsum("...i,...i->...", v, v))
    scale = np.minimum(1.0, max_speed_mps / np.maximum(speed, 1e-300))
    return v * scale[..., None] if v.ndim > 1 else v * scale


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


def project_feasible(target_m: np.ndarray, position_m: np.ndarray, max_step_m: float,
                     area_m: tuple[float, float, float, float]) -> np.ndarray:
    """A feasible next position toward ``target_m``: the target pulled onto the step disc around
    ``position_m`` and clipped into the area (feasible, not the Euclidean projection onto the
    disc-box intersection)."""
    step = np.asarray(target_m, dtype=float) - np.asarray(position_m, dtype=float)
    return move_drone(position_m, step, max_step_m, 1.0, area_m)
