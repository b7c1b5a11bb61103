"""Small exact subproblems of the planners: projections and linear minimization (the compiled ones,
:mod:`agents.search`'s, for arrays from Python).

* :func:`project_budget`: Euclidean projection onto {p >= 0, sum p <= P} (the power set of P4).
* :func:`linear_argmin_disc_box`: minimize g'q over the drone's feasible set, the speed disc
  around q[n-1] intersected with the area box (problem P6 with the linear SCA surrogate).
"""

from __future__ import annotations

import math

import numpy as np

from . import search

__all__ = ["project_budget", "linear_argmin_disc_box", "project_disc_box", "disc_box_grid", "min_plus_allocation"]


def project_budget(v: np.ndarray, total: float) -> np.ndarray:
    """Exact Euclidean projection of ``v`` (K,) onto {p >= 0, sum p <= total}
    (:func:`agents.search.project_budget`, compiled)."""
    projected: np.ndarray = search.project_budget(np.ascontiguousarray(v, dtype=float), float(total))
    return projected


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


def project_disc_box(point: np.ndarray, center: np.ndarray, radius: float,
                     area_m: tuple[float, float, float, float]) -> np.ndarray:
    """Exact Euclidean projection of ``point`` onto {||q - center|| <= radius} ∩ box
    (:func:`agents.search.project_disc_box`, compiled). ``center`` must lie in the box."""
    point = np.asarray(point, dtype=float)
    if not np.all(np.isfinite(point)):
        raise ValueError(f"project_disc_box: point {point!r} is not finite")
    projected: np.ndarray = search.project_disc_box(point, np.asarray(center, dtype=float), float(radius),
                                                    np.asarray(area_m, dtype=float))
    return projected


def disc_box_grid(center: np.ndarray, radius: float, area_m: tuple[float, float, float, float],
                  spacing: float, max_points: int = 10_000) -> np.ndarray:
    """Points of a square grid of ``spacing`` (m) centred on ``center`` that lie in the disc and
    the box, plus the center itself: (n, 2) (:func:`agents.search.disc_box_grid`, compiled)."""
    grid: np.ndarray = search.disc_box_grid(np.asarray(center, dtype=float), float(radius),
                                            np.asarray(area_m, dtype=float), float(spacing), int(max_points))
    return grid


def min_plus_allocation(costs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact split of J units among K users on a grid: min over sum j_k <= J of sum_k costs[:, k, j_k].

    ``costs`` (B, K, J+1) holds, for B independent problems (e.g. drone positions), user k's cost
    with j units. Min-plus dynamic programming over users (compiled; ties go to the fewest units
    and the smallest budget). Returns the optimal values (B,) and allocations (B, K) in units.
    """
    costs = np.ascontiguousarray(costs, dtype=float)
    if costs.ndim != 3 or costs.shape[1] < 1 or costs.shape[2] < 1:
        raise ValueError(f"costs has shape {costs.shape}; expected (B, K, J+1) with K >= 1 and J >= 0")
    values_alloc: tuple[np.ndarray, np.ndarray] = search.min_plus(costs)
    return values_alloc
