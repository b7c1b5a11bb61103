"""Drone kinematics at fixed altitude (MODEL.md §1, §4).

Per slot the drone moves at most V_max * Delta-tau and stays inside the area D:
``||q[n] - q[n-1]|| <= V_max Delta-tau`` and ``q[n] in D`` (paper, constraints of P1).

One rule for one drone and for a batch of them: :func:`move_drone` takes positions and
velocities with any leading axes, (2,) or (B, 2), and runs one compiled loop: the speed by
CPython's ``math.hypot``, ``v * V_max / speed`` for the radial clip, then the area box. The
speed's rounding decides whether a move is clipped, so :func:`hypot` reproduces CPython's
two-argument ``math.hypot`` (3.11), which a test checks against ``math.hypot`` itself: a move
computed in Python (a planner's) and in the kernel agree to the bit.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["move_drone", "toward", "hypot", "move_rows", "drift"]


@numba.njit(cache=True, inline="always")
def _split(x: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """Veltkamp's split: x = hi + lo exactly, each half with 26 significant bits."""
    t = x * 134217729.0  # 2^27 + 1
    hi = t - (t - x)
    return hi, x - hi


@numba.njit(cache=True, inline="always")
def _mul(x: float, y: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """Dekker's exact product: x * y = hi + lo, hi the rounded product."""
    xh, xl = _split(x)
    yh, yl = _split(y)
    hi = x * y
    lo = ((xh * yh - hi) + xh * yl + xl * yh) + xl * yl
    return hi, lo


@numba.njit(cache=True)
def hypot(a: float, b: float) -> float:  # pragma: no cover - compiled
    """``math.hypot(a, b)`` exactly as CPython computes it (``vector_norm`` of Modules/mathmodule.c:
    lossless scaling, exact squares and sums, one differential correction), so compiled code
    reproduces the interpreter's value to the last bit whenever the larger magnitude is a normal
    number (when both are subnormal, to a subnormal's last place or two)."""
    x0, x1 = abs(a), abs(b)
    found_nan = math.isnan(x0) or math.isnan(x1)
    top = 0.0
    if not math.isnan(x0) and x0 > top:
        top = x0
    if not math.isnan(x1) and x1 > top:
        top = x1
    if math.isinf(top):
        return top
    if found_nan:
        return math.nan
    if top == 0.0:
        return top
    tiny = 2.2250738585072014e-308  # DBL_MIN
    if math.frexp(top)[1] < -1023:  # subnormal: lift to normal numbers, as CPython does
        lifted: float = hypot(x0 / tiny, x1 / tiny)
        return tiny * lifted
    scale = math.ldexp(1.0, -math.frexp(top)[1])
    csum, frac1, frac2 = 1.0, 0.0, 0.0
    for v in (x0, x1):
        x = v * scale
        p_hi, p_lo = _mul(x, x)
        s_hi = csum + p_hi
        s_lo = (csum - s_hi) + p_hi
        csum = s_hi
        frac1 += p_lo
        frac2 += s_lo
    h: float = math.sqrt(csum - 1.0 + (frac1 + frac2))
    p_hi, p_lo = _mul(-h, h)
    s_hi = csum + p_hi
    s_lo = (csum - s_hi) + p_hi
    csum = s_hi
    frac1 += p_lo
    frac2 += s_lo
    x = csum - 1.0 + (frac1 + frac2)
    h += x / (2.0 * h)
    return h / scale


@numba.njit(cache=True, inline="always")
def _clip(v: float, lo: float, hi: float) -> float:  # pragma: no cover - compiled
    """Python's ``min(max(v, lo), hi)``, signed zeros and all."""
    if lo > v:  # noqa: PLR1730 - numba's max/min differ from Python's on signed zeros and NaN
        v = lo
    if hi < v:  # noqa: PLR1730
        v = hi
    return v


@numba.njit(cache=True)
def move_rows(  # noqa: PLR0913 - a compiled kernel (up to 12 arguments)
    position: np.ndarray, velocity: np.ndarray, max_speed: float, slot_s: float, x0: float, x1: float,
    y0: float, y1: float, out: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """The compiled rule of :func:`move_drone` on rows: positions and velocities (B, 2), the next
    positions written to ``out`` (B, 2); other kernels call it."""
    for i in range(position.shape[0]):
        vx, vy = velocity[i, 0], velocity[i, 1]
        speed = hypot(vx, vy)
        if speed > max_speed:
            vx, vy = vx * max_speed / speed, vy * max_speed / speed
        out[i, 0] = _clip(position[i, 0] + vx * slot_s, x0, x1)
        out[i, 1] = _clip(position[i, 1] + vy * slot_s, y0, y1)


@numba.njit(cache=True)
def _toward(  # noqa: PLR0913  # pragma: no cover - compiled
    position: np.ndarray, target: np.ndarray, max_speed: float, slot_s: float, x0: float, x1: float, y0: float,
    y1: float, out: np.ndarray,
) -> None:
    reach = max_speed * slot_s
    velocity = np.empty((position.shape[0], 2))
    for i in range(position.shape[0]):
        sx, sy = target[i, 0] - position[i, 0], target[i, 1] - position[i, 1]
        dist = hypot(sx, sy)
        if dist <= reach:
            velocity[i, 0], velocity[i, 1] = sx / slot_s, sy / slot_s
        else:
            velocity[i, 0], velocity[i, 1] = sx * (max_speed / dist), sy * (max_speed / dist)
    move_rows(position, velocity, max_speed, slot_s, x0, x1, y0, y1, out)


def _pair(position_m: np.ndarray, other: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(position_m, dtype=np.float64)
    v = np.asarray(other, dtype=np.float64)
    if p.shape != v.shape or p.shape[-1:] != (2,):
        raise ValueError(f"position {p.shape} and {name} {v.shape}: expected the same shape (..., 2)")
    return p, v


def move_drone(position_m: np.ndarray, velocity_mps: np.ndarray, max_speed_mps: float, slot_s: float,
               area_m: tuple[float, float, float, float]) -> np.ndarray:
    """Next drone positions: each commanded velocity clipped to V_max (radially), integrated over
    one slot, then clipped into the area box (which only shortens the move, so the speed limit
    still holds). Positions and velocities (..., 2), one drone or a batch; a new array of their shape."""
    p, v = _pair(position_m, velocity_mps, "velocity")
    out = np.empty(p.shape)
    x0, x1, y0, y1 = area_m
    move_rows(p.reshape(-1, 2), v.reshape(-1, 2), max_speed_mps, slot_s, x0, x1, y0, y1, out.reshape(-1, 2))
    return out


def toward(position_m: np.ndarray, target_m: np.ndarray, max_speed_mps: float, slot_s: float,
           area_m: tuple[float, float, float, float]) -> np.ndarray:
    """Next drone positions flying toward ``target_m`` (..., 2): straight there when it is within
    one slot's reach V_max Delta-tau, else the full reach along the way (then :func:`move_drone`'s
    rule)."""
    p, t = _pair(position_m, target_m, "target")
    out = np.empty(p.shape)
    x0, x1, y0, y1 = area_m
    _toward(p.reshape(-1, 2), t.reshape(-1, 2), max_speed_mps, slot_s, x0, x1, y0, y1, out.reshape(-1, 2))
    return out


def drift(drone_next: np.ndarray, wind_mps: np.ndarray, slot_s: float, area_lo: np.ndarray,
          area_hi: np.ndarray) -> np.ndarray:
    """The drone's next position (..., 2) drifted by the slot's wind (mean plus gust, (..., 2) m/s)
    and kept in the area (disturbance mode, MODEL.md §7)."""
    return np.clip(drone_next + wind_mps * slot_s, area_lo, area_hi)
