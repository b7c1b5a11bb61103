"""Small exact subproblems of the planners: projections and linear minimization.

* :func:`project_budget`: Euclidean projection onto {p >= 0, sum p <= P} (the power set of P4).
* :func:`linear_argmin_disc_box`: minimize g'q over the drone's feasible set, the speed disc
  around q[n-1] intersected with the area box (problem P6 with the linear SCA surrogate).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["project_budget", "linear_argmin_disc_box"]


def project_budget(v: np.ndarray, total: float) -> np.ndarray:
    """Exact Euclidean projection of ``v`` (K,) onto {p >= 0, sum p <= total}.

    If clipping at zero already satisfies the budget that is the projection; otherwise the
    projection lies on the simplex sum p = total and is ``max(v - theta, 0)`` with the threshold
    theta found by sorting (Held, Wolfe and Crowder 1974; Duchi et al. 2008).
    """
    clipped = np.maximum(v, 0.0)
    if clipped.sum() <= total:
        return clipped
    theta = (v.sum() - total) / v.size  # common case: every entry stays positive on the face
    shifted = v - theta
    if shifted.min() >= 0.0:
        return shifted
    u = np.sort(v)[::-1]
    css = np.cumsum(u) - total
    idx = _ranks(u.size)
    rho = int(np.count_nonzero(u * idx > css))  # the condition holds exactly for the first rho entries
    theta = css[rho - 1] / rho
    return np.maximum(v - theta, 0.0)


_RANKS: dict[int, np.ndarray] = {}


def _ranks(n: int) -> np.ndarray:
    if n not in _RANKS:
        _RANKS[n] = np.arange(1, n + 1, dtype=float)
    return _RANKS[n]


def linear_argmin_disc_box(g: np.ndarray, center: np.ndarray, radius: float,
                           area_m: tuple[float, float, float, float]) -> np.ndarray:
    """argmin g'q over {||q - center|| <= radius} intersected with the box ``area_m``.

    Exact: the minimizer of a linear function over this convex set is the disc's minimizer if
    it lies in the box; otherwise it is a corner of the set, i.e. a box vertex inside the disc
    or an intersection of the circle with a box edge. ``center`` must lie in the box.
    """
    cx, cy = float(center[0]), float(center[1])
    gx, gy = float(g[0]), float(g[1])
    norm = math.hypot(gx, gy)
    if norm == 0.0 or radius <= 0.0:
        return np.array([cx, cy])
    x0, x1, y0, y1 = area_m
    best = (cx - radius * gx / norm, cy - radius * gy / norm)
    eps = 1e-9 * max(1.0, radius)
    if x0 - eps <= best[0] <= x1 + eps and y0 - eps <= best[1] <= y1 + eps:
        return np.array([min(max(best[0], x0), x1), min(max(best[1], y0), y1)])
    r2 = radius * radius
    candidates = [(cx, cy)]
    for vx in (x0, x1):
        for vy in (y0, y1):
            if (vx - cx) ** 2 + (vy - cy) ** 2 <= r2:
                candidates.append((vx, vy))
    for xe in (x0, x1):  # vertical edges x = xe
        h = r2 - (xe - cx) ** 2
        if h >= 0:
            for yy in (cy - math.sqrt(h), cy + math.sqrt(h)):
                if y0 - eps <= yy <= y1 + eps:
                    candidates.append((xe, min(max(yy, y0), y1)))
    for ye in (y0, y1):  # horizontal edges y = ye
        h = r2 - (ye - cy) ** 2
        if h >= 0:
            for xx in (cx - math.sqrt(h), cx + math.sqrt(h)):
                if x0 - eps <= xx <= x1 + eps:
                    candidates.append((min(max(xx, x0), x1), ye))
    values = [gx * px + gy * py for px, py in candidates]
    return np.array(candidates[int(np.argmin(values))])
