"""The planners' search and refinement as they were in Python before :mod:`agents.search` compiled them:
the oracle the compiled kernels are checked against (``tests/test_search.py``), as cvxpy is the QP's.
Copied from ``agents/optim.py`` and ``agents/reduced.py`` at 87a95e4, made free functions of a
:class:`agents.dv_mpc.DeliveryProblem`; the one change: psi as the compiled search evaluates it, in
Erlang's closed form (``lawn_env.channel.outage_law``'s SERIES, checked against scipy in test_channel.py),
and the coarse scores' ties in grid order (a stable sort)."""

from __future__ import annotations

import math

import numpy as np

from agents.search import min_plus
from lawn_env import channel
from lawn_env.products import matmul


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


def success(problem, power_w, d2):
    """psi as dv-mpc's search evaluates it (Erlang's closed form, ``lawn_env.channel.outage_law``'s SERIES)
    at powers and squared distances that broadcast, one link at a time."""
    x = problem.link.outage_argument_sq(power_w, d2)
    m = float(problem.link.m)
    return np.vectorize(lambda v: channel.outage_law(m, float(v), channel.SERIES), otypes=[float])(x)


def phi_at(problem, power_w, q):
    """(Phi, psi) of the delivery problem at (p, q)."""
    psi = success(problem, power_w, problem.link.distance_sq(q, problem.agv_xy))
    return float((problem.lost - psi * problem.worth).sum()), psi


def gradient(problem, power_w, q):
    _, dpsi_dp, dpsi_dq = channel.success_and_gradients(power_w, q, problem.agv_xy, problem.link)
    slopes = np.broadcast_to(-problem.worth, problem.worth.shape)
    return slopes * dpsi_dp, matmul(slopes, dpsi_dq)


def grid_search(problem, positions, levels, coarse_levels, keep):
    def split(positions, levels):
        units = np.arange(levels + 1) * (problem.budget / levels)
        d2 = problem.link.distance_sq(positions[:, None, :], problem.agv_xy[None, :, :])
        psi = success(problem, units[None, None, :], d2[:, :, None])
        return min_plus(np.ascontiguousarray(problem.lost[:, None] - psi * problem.worth[:, None]))

    if coarse_levels < levels and positions.shape[0] > keep:
        scores, _ = split(positions, coarse_levels)
        positions = positions[np.argsort(scores, kind="stable")[:keep]]
    values, alloc = split(positions, levels)
    best = int(np.argmin(values))
    return alloc[best] * (problem.budget / levels), positions[best]


def refine(problem, power_w, q, iterations, armijo=1e-4, max_backtracks=20, tolerance=1e-10):
    """ReducedProblem.refine on the delivery problem: returns (Phi, p, q, evaluations)."""
    phi, _ = phi_at(problem, power_w, q)
    evaluations = 0
    steps = {"p": None, "q": None}
    grad_p, grad_q = gradient(problem, power_w, q)
    for _ in range(iterations):
        improved = False
        for block in ("p", "q"):
            g = grad_p if block == "p" else grad_q
            x = power_w if block == "p" else q
            gnorm = math.sqrt(float(matmul(g, g)))
            if gnorm == 0.0 or not math.isfinite(gnorm):
                continue
            alpha = steps[block] or 0.5 * (problem.budget if block == "p" else problem.reach) / gnorm
            if not (math.isfinite(alpha) and alpha > 0.0):
                continue
            accepted = None
            for _ in range(max_backtracks):
                if block == "p":
                    x_new = project_budget(x - alpha * g, problem.budget)
                else:
                    x_new = project_disc_box(x - alpha * g, problem.q_prev, problem.reach, problem.area)
                delta = x_new - x
                if not np.all(np.isfinite(delta)) or float(matmul(delta, delta)) == 0.0:
                    break
                cand = (x_new, q) if block == "p" else (power_w, x_new)
                cand_phi, _ = phi_at(problem, *cand)
                evaluations += 1
                if cand_phi <= phi + armijo * float(matmul(g, delta)):
                    accepted = cand
                    break
                alpha *= 0.5
            if accepted is None:
                continue
            new_grad_p, new_grad_q = gradient(problem, *accepted)
            y = (new_grad_p - grad_p) if block == "p" else (new_grad_q - grad_q)
            sy = float(matmul(delta, y))
            steps[block] = float(matmul(delta, delta)) / sy if sy > 0 else None
            if phi - cand_phi > tolerance * abs(phi):
                improved = True
            phi, (power_w, q), grad_p, grad_q = cand_phi, accepted, new_grad_p, new_grad_q
        if not improved:
            break
    return phi, power_w, q, evaluations


def decide(problem, last, settings):
    """dv-mpc's decision of one problem as ReducedGradientPlanner.plan took it: (Phi, p, q, start)."""
    s = settings
    positions = disc_box_grid(problem.q_prev, problem.reach, problem.area, s.drone_spacing_m, s.max_drone_points)
    p, q = grid_search(problem, positions, s.power_levels, s.coarse_power_levels, s.keep_positions)
    k = problem.lost.size
    starts = {"search": (p, q), "equal": (np.full(k, problem.budget / k), problem.q_prev)}
    if last is not None:
        p_last, v_last = last
        starts["previous"] = (p_last, project_disc_box(problem.q_prev + v_last, problem.q_prev, problem.reach,
                                                       problem.area))
    values = {name: phi_at(problem, *point)[0] for name, point in starts.items()}
    origin = min(values, key=lambda name: values[name])
    phi, p, q, _ = refine(problem, *starts[origin], s.refine_iterations)
    return phi, p, q, origin


def hermite_grid_search(grid, values, slopes, agv, positions, levels, coarse_levels, keep, budget, link):
    """ReducedProblem.grid_search of rg-mpc and global-mpc at 87a95e4: V_k tabulated on ``grid`` (values and
    envelope slopes (M, K)), cubic Hermite between points, psi by scipy's law (LinkParams.success_sq);
    returns (value, p, q)."""
    def table(psi):  # the pre-change _hermite kernel's expression, element by element
        out = np.empty_like(psi)
        top = grid.size - 2
        for idx in np.ndindex(psi.shape):
            x, k = psi[idx], idx[1]
            i = min(max(int(np.searchsorted(grid, x, side="right")) - 1, 0), top)
            h = grid[i + 1] - grid[i]
            t = (x - grid[i]) / h
            t2 = t * t
            t3 = t2 * t
            out[idx] = ((2 * t3 - 3 * t2 + 1) * values[i, k] + (t3 - 2 * t2 + t) * h * slopes[i, k]
                        + (-2 * t3 + 3 * t2) * values[i + 1, k] + (t3 - t2) * h * slopes[i + 1, k])
        return out

    def split(positions, levels):
        units = np.arange(levels + 1) * (budget / levels)
        d2 = link.distance_sq(positions[:, None, :], agv[None, :, :])
        return min_plus(np.ascontiguousarray(table(link.success_sq(units[None, None, :], d2[:, :, None]))))

    if coarse_levels < levels and positions.shape[0] > keep:
        scores, _ = split(positions, coarse_levels)
        positions = positions[np.argsort(scores, kind="stable")[:keep]]
    found, alloc = split(positions, levels)
    best = int(np.argmin(found))
    return float(found[best]), alloc[best] * (budget / levels), positions[best]
