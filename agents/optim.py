"""Small exact subproblems of the planners: projections and linear minimization.

* :func:`project_budget`: Euclidean projection onto {p >= 0, sum p <= P} (the power set of P4).
* :func:`linear_argmin_disc_box`: minimize g'q over the drone's feasible set, the speed disc
  around q[n-1] intersected with the area box (problem P6 with the linear SCA surrogate).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["project_budget", "linear_argmin_disc_box", "project_disc_box", "disc_box_grid", "min_plus_allocation"]


def project_budget(v: np.ndarray, total: float) -> np.ndarray:
    """Exact Euclidean projection of ``v`` (K,) onto {p >= 0, sum p <= total}.

    If clipping at zero already satisfies the budget that is the projection; otherwise the
    projection lies on the simplex sum p = total and is ``max(v - theta, 0)`` with the threshold
    theta found by sorting (Held, Wolfe and Crowder 1974; Duchi et al. 2008).
    """
    clipped: np.ndarray = np.maximum(v, 0.0)
    if clipped.sum() <= total:
        return clipped
    theta = (v.sum() - total) / v.size  # common case: every entry stays positive on the face
    shifted: np.ndarray = v - theta
    if shifted.min() >= 0.0:
        return shifted
    u = np.sort(v)[::-1]
    css = np.cumsum(u) - total
    idx = _ranks(u.size)
    rho = int(np.count_nonzero(u * idx > css))  # the condition holds exactly for the first rho entries
    theta = css[rho - 1] / rho
    projected: np.ndarray = np.maximum(v - theta, 0.0)
    return projected


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


def project_disc_box(point: np.ndarray, center: np.ndarray, radius: float,
                     area_m: tuple[float, float, float, float]) -> np.ndarray:
    """Exact Euclidean projection of ``point`` onto {||q - center|| <= radius} ∩ box.

    The set is convex; its projection is the point itself, the disc's projection (if it lies in
    the box), or the projection onto one of the box edges clipped to the part of the edge inside
    the disc. ``center`` must lie in the box.
    """
    px, py = float(point[0]), float(point[1])
    cx, cy = float(center[0]), float(center[1])
    x0, x1, y0, y1 = area_m
    if not (math.isfinite(px) and math.isfinite(py)):
        raise ValueError(f"project_disc_box: point {point!r} is not finite")
    dx, dy = px - cx, py - cy
    dist = math.hypot(dx, dy)
    inside_box = x0 <= px <= x1 and y0 <= py <= y1
    if dist <= radius and inside_box:
        return np.array([px, py])
    candidates = []
    if dist > radius:
        qx, qy = cx + dx * radius / dist, cy + dy * radius / dist
    else:
        qx, qy = px, py
    if x0 - 1e-12 <= qx <= x1 + 1e-12 and y0 - 1e-12 <= qy <= y1 + 1e-12:
        candidates.append((min(max(qx, x0), x1), min(max(qy, y0), y1)))
    r2 = radius * radius
    for xe in (x0, x1):  # segment x = xe, y in [y0, y1] ∩ [cy - h, cy + h]
        h2 = r2 - (xe - cx) ** 2
        if h2 >= 0:
            h = math.sqrt(h2)
            lo, hi = max(y0, cy - h), min(y1, cy + h)
            if lo <= hi:
                candidates.append((xe, min(max(py, lo), hi)))
    for ye in (y0, y1):
        h2 = r2 - (ye - cy) ** 2
        if h2 >= 0:
            h = math.sqrt(h2)
            lo, hi = max(x0, cx - h), min(x1, cx + h)
            if lo <= hi:
                candidates.append((min(max(px, lo), hi), ye))
    if not candidates:  # rounding at coordinates far above the radius: the center is always feasible
        candidates.append((min(max(cx, x0), x1), min(max(cy, y0), y1)))
    best = min(candidates, key=lambda c: (c[0] - px) ** 2 + (c[1] - py) ** 2)
    return np.array(best)


def disc_box_grid(center: np.ndarray, radius: float, area_m: tuple[float, float, float, float],
                  spacing: float, max_points: int = 10_000) -> np.ndarray:
    """Points of a square grid of ``spacing`` (m) centred on ``center`` that lie in the disc and
    the box, plus the center itself: (n, 2).

    The grid is laid over the disc's bounding square clipped to the box, so its cost follows the
    reachable area, not the disc; when that would still exceed ``max_points`` points (a long slot
    or a fast drone: the disc grows with (V_max Δτ)²) the spacing is widened until it does not.
    """
    cx, cy = float(center[0]), float(center[1])
    x0, x1, y0, y1 = area_m
    radius = max(float(radius), 0.0)
    spacing = float(spacing)
    lo = np.array([max(x0, cx - radius) - cx, max(y0, cy - radius) - cy])
    hi = np.array([min(x1, cx + radius) - cx, min(y1, cy + radius) - cy])
    extent = np.maximum(hi - lo, 0.0)
    cells = float(np.prod(extent / spacing + 1.0))
    if cells > max_points:
        spacing *= math.sqrt(cells / max_points) * 1.01
    axes = [np.arange(math.ceil(lo[i] / spacing - 1e-9), math.floor(hi[i] / spacing + 1e-9) + 1) * spacing
            for i in range(2)]
    gx, gy = np.meshgrid(axes[0], axes[1], indexing="ij")
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    pts = pts[(pts**2).sum(axis=1) <= radius * radius + 1e-9] + np.array([cx, cy])
    keep = (pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1)
    pts = pts[keep]
    if not (pts == [cx, cy]).all(axis=1).any():
        pts = np.vstack([pts, [cx, cy]])
    return pts


def min_plus_allocation(costs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact split of J units among K users on a grid: min over sum j_k <= J of sum_k costs[:, k, j_k].

    ``costs`` (B, K, J+1) holds, for B independent problems (e.g. drone positions), user k's cost
    with j units. Min-plus dynamic programming over users (compiled; ties go to the fewest units
    and the smallest budget). Returns the optimal values (B,) and allocations (B, K) in units.
    """
    costs = np.ascontiguousarray(costs, dtype=float)
    if costs.ndim != 3 or costs.shape[1] < 1 or costs.shape[2] < 1:
        raise ValueError(f"costs has shape {costs.shape}; expected (B, K, J+1) with K >= 1 and J >= 0")
    values_alloc: tuple[np.ndarray, np.ndarray] = _min_plus(costs)
    return values_alloc


@numba.njit(cache=True)  # type: ignore[untyped-decorator]  # numba is not followed (pyproject.toml: numba's follow_imports)
def _min_plus(costs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    b_total, k, levels = costs.shape
    values = np.empty(b_total)
    alloc = np.empty((b_total, k), dtype=np.int64)
    f = np.empty(levels)
    g = np.empty(levels)
    choice = np.empty((k, levels), dtype=np.int64)
    for b in range(b_total):
        best, arg = np.inf, 0
        for budget in range(levels):  # the first user, at most ``budget`` units
            if costs[b, 0, budget] < best:
                best, arg = costs[b, 0, budget], budget
            f[budget] = best
            choice[0, budget] = arg
        for user in range(1, k):
            for budget in range(levels):
                best, arg = np.inf, 0
                for units in range(budget + 1):
                    total = f[budget - units] + costs[b, user, units]
                    if total < best:
                        best, arg = total, units
                g[budget] = best
                choice[user, budget] = arg
            f[:] = g
        budget = 0
        for j in range(1, levels):
            if f[j] < f[budget]:
                budget = j
        values[b] = f[budget]
        for user in range(k - 1, -1, -1):
            units = choice[user, budget]
            alloc[b, user] = units
            budget -= units
    return values, alloc
