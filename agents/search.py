"""The reduced planners' search and refinement, compiled (MODEL.md §4; :mod:`agents.reduced` and the planners
on it, :mod:`agents.rg_mpc`, :mod:`agents.global_mpc`, :mod:`agents.dv_mpc`).

One slot's reduced problem is ``min over (p, q) of Phi(p, q) = sum_k V_k(psi_k(p_k, q))``. What
``rg-mpc``, ``dv-mpc`` and ``global-mpc`` do with it is here, as numba kernels over a batch of
scenarios (a single decision is the batch of one):

* :func:`disc_box_grid`: the drone's candidate positions, a square grid over the disc ∩ area;
* :func:`grid_search`: the best (p, q) of a value table over those positions and power splits
  (min-plus DP on a coarse power grid for every position, the best ``keep`` split finely);
* :func:`project_budget`, :func:`project_disc_box`: the exact projections onto the feasible sets;
* :func:`delivery_decisions`: ``dv-mpc``'s whole decision after its two QPs per AGV (its values are
  ``V_k(psi) = V_k^lost - psi w_k``, so Phi and its gradient are the channel alone): the search, the
  comparison with equal power at hover and with the previous slot's continuation, and the projected
  gradient refinement with Armijo backtracking and Barzilai-Borwein steps, alternating p and q.

Every sum is taken in the order the planners' numpy code took it (:func:`vector_sum` is numpy's
pairwise summation; products sum their index ascending, as :func:`lawn_env.products.matmul`), so the
compiled decisions are the Python planners' to the last bit: ``tests/oracle_search.py`` keeps the
pre-compiled Python code as the oracle, which ``tests/test_search.py`` checks against. The differences:
positions whose coarse scores tie exactly keep their grid order (numpy's ``argsort`` left their order
unspecified), and ``dv-mpc``'s search evaluates psi in Erlang's closed form
(``lawn_env.channel.outage_law``'s SERIES; the oracle does too).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numba
import numpy as np

from lawn_env.channel import (
    DENSITY,
    POWER_FLOOR_W,
    SERIES,
    SUCCESS,
    LinkParams,
    link_argument,
    link_distance_sq,
    outage_law,
)
from lawn_env.drone import hypot

__all__ = ["vector_sum", "min_plus", "project_budget", "project_disc_box", "disc_box_grid", "grid_search", "LINEAR",
           "HERMITE", "delivery_decisions", "decide", "Decisions", "hermite", "SEARCH", "EQUAL", "PREVIOUS", "STARTS"]

#: What a value table holds (:func:`grid_search`): ``LINEAR`` V = lost - psi w (``dv-mpc``: ``table``
#: (2, K), lost then worth); ``HERMITE`` V tabulated on a psi grid with envelope slopes, cubic Hermite
#: between points (``rg-mpc``, ``global-mpc``: ``table`` (2 M, K), values then slopes, and ``grid`` (M,)).
LINEAR, HERMITE = 0, 1
#: Where :func:`delivery_decisions`' refinement started: the search, equal power at hover, the previous
#: slot's continuation (their names in a plan's ``info["start"]``: :data:`STARTS`).
SEARCH, EQUAL, PREVIOUS = 0, 1, 2
STARTS = ("search", "equal", "previous")


class Decisions(NamedTuple):
    """:func:`delivery_decisions`' results for B scenarios: power (B, K), drone position (B, 2), psi
    (B, K), Phi (B,), the start refined (B,), the starts' Phi (B, 3) (NaN where not tried) and the
    evaluations of Phi (B,)."""

    power: np.ndarray
    position: np.ndarray
    psi: np.ndarray
    phi: np.ndarray
    origin: np.ndarray
    start_values: np.ndarray
    evaluations: np.ndarray


class _Problem(Protocol):
    """What :func:`decide` reads of one scenario's delivery problem (:class:`agents.dv_mpc.DeliveryProblem`)."""

    lost: np.ndarray
    worth: np.ndarray
    agv_xy: np.ndarray
    q_prev: np.ndarray
    reach: float
    area: tuple[float, float, float, float]
    budget: float
    link: LinkParams


class _Settings(Protocol):
    """The search's settings (:class:`agents.DeliverySettings`)."""

    @property
    def drone_spacing_m(self) -> float: ...
    @property
    def max_drone_points(self) -> int: ...
    @property
    def power_levels(self) -> int: ...
    @property
    def coarse_power_levels(self) -> int: ...
    @property
    def keep_positions(self) -> int: ...
    @property
    def refine_iterations(self) -> int: ...


def decide(problems: Sequence[_Problem], last: Sequence[tuple[np.ndarray, np.ndarray] | None], settings: _Settings,
           search_only: bool = False) -> Decisions:
    """:func:`delivery_decisions` of B problems that share a config (its area and power budget), each
    continuing from its ``last`` (power, move) or from nothing (None)."""
    k = problems[0].lost.size
    count = len(problems)
    has_last = np.array([entry is not None for entry in last])
    last_power, last_move = np.zeros((count, k)), np.zeros((count, 2))
    for i, entry in enumerate(last):
        if entry is not None:
            last_power[i], last_move[i] = entry
    s = settings
    scenarios = (np.stack([p.lost for p in problems]), np.stack([p.worth for p in problems]),
                 np.stack([p.agv_xy for p in problems]), np.stack([p.q_prev for p in problems]),
                 np.array([p.reach for p in problems], dtype=float))
    shared = (np.asarray(problems[0].area, dtype=float), float(problems[0].budget), problems[0].link.constants)
    resolution = (float(s.drone_spacing_m), int(s.max_drone_points), int(s.power_levels), int(s.coarse_power_levels),
                  int(s.keep_positions), int(s.refine_iterations))
    return Decisions(*delivery_decisions(scenarios, (last_power, last_move, has_last), shared, resolution,
                                         search_only))


_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def _block_sum(a: np.ndarray, lo: int, n: int) -> float:  # pragma: no cover - compiled
    """numpy's pairwise sum of ``a[lo:lo + n]`` for n <= 128: a plain loop below 8, else eight
    accumulators combined as a tree, then the rest."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@_jit
def vector_sum(a: np.ndarray) -> float:  # pragma: no cover - compiled
    """``a.sum()`` of a contiguous 1-D float64 array, bit for bit: numpy's pairwise summation (blocks of
    at most 128 summed by :func:`_block_sum`, longer ranges halved at a multiple of 8 and their sums
    added, the tree walked with a stack: numba's cache does not keep recursive kernels)."""
    los, ns = np.empty(64, dtype=np.int64), np.empty(64, dtype=np.int64)
    state, left = np.zeros(64, dtype=np.int64), np.empty(64)
    top, ret = 0, 0.0
    los[0], ns[0] = 0, a.size
    while top >= 0:  # each frame: 0 sum the left half, 1 then the right, 2 add them
        lo, n = los[top], ns[top]
        if n <= 128:
            ret = _block_sum(a, lo, n)
            top -= 1
            continue
        half = n // 2
        half -= half % 8
        if state[top] == 0:
            state[top] = 1
            top += 1
            los[top], ns[top], state[top] = lo, half, 0
        elif state[top] == 1:
            left[top], state[top] = ret, 2
            top += 1
            los[top], ns[top], state[top] = lo + half, n - half, 0
        else:
            ret = left[top] + ret
            top -= 1
    return ret


@_jit
def _dot(a: np.ndarray, b: np.ndarray) -> float:  # pragma: no cover - compiled
    """``sum_i a[i] b[i]`` with i ascending (:func:`lawn_env.products.matmul` of two vectors)."""
    acc = 0.0
    for i in range(a.size):
        acc += a[i] * b[i]
    return acc


@_jit
def project_budget(v: np.ndarray, total: float) -> np.ndarray:  # pragma: no cover - compiled
    """Exact Euclidean projection of ``v`` (K,) onto {p >= 0, sum p <= total}.

    If clipping at zero already satisfies the budget that is the projection; otherwise the
    projection lies on the simplex sum p = total and is ``max(v - theta, 0)`` with the threshold
    theta found by sorting (Held, Wolfe and Crowder 1974; Duchi et al. 2008)."""
    n = v.size
    clipped = np.maximum(v, 0.0)
    if vector_sum(clipped) <= total:
        return clipped
    theta = (vector_sum(v) - total) / n  # common case: every entry stays positive on the face
    shifted = v - theta
    if shifted.min() >= 0.0:
        return shifted
    u = np.sort(v)[::-1]
    css = np.cumsum(u) - total
    rho = 0
    for i in range(n):  # the condition holds exactly for the first rho entries
        if u[i] * (i + 1.0) > css[i]:
            rho += 1
    theta = css[rho - 1] / rho
    return np.maximum(v - theta, 0.0)


@_jit
def _disc_box(px: float, py: float, cx: float, cy: float, radius: float, area: np.ndarray
              ) -> tuple[float, float]:  # pragma: no cover - compiled
    x0, x1, y0, y1 = area[0], area[1], area[2], area[3]
    dx, dy = px - cx, py - cy
    dist = hypot(dx, dy)
    if dist <= radius and x0 <= px <= x1 and y0 <= py <= y1:
        return px, py
    best_x, best_y, best = 0.0, 0.0, math.inf
    if dist > radius:
        qx, qy = cx + dx * radius / dist, cy + dy * radius / dist
    else:
        qx, qy = px, py
    if x0 - 1e-12 <= qx <= x1 + 1e-12 and y0 - 1e-12 <= qy <= y1 + 1e-12:
        best_x, best_y = min(max(qx, x0), x1), min(max(qy, y0), y1)
        best = (best_x - px) ** 2 + (best_y - py) ** 2
    r2 = radius * radius
    for side in range(4):  # the edges x = x0, x = x1 (y clipped), then y = y0, y = y1 (x clipped)
        vertical = side < 2
        edge = area[side]
        h2 = r2 - (edge - (cx if vertical else cy)) ** 2
        if h2 < 0:
            continue
        h = math.sqrt(h2)
        if vertical:
            lo, hi = max(y0, cy - h), min(y1, cy + h)
            if lo > hi:
                continue
            ex, ey = edge, min(max(py, lo), hi)
        else:
            lo, hi = max(x0, cx - h), min(x1, cx + h)
            if lo > hi:
                continue
            ex, ey = min(max(px, lo), hi), edge
        dist2 = (ex - px) ** 2 + (ey - py) ** 2
        if dist2 < best:  # the first of equally near candidates, in this order
            best_x, best_y, best = ex, ey, dist2
    if best == math.inf:  # rounding at coordinates far above the radius: the center is always feasible
        return min(max(cx, x0), x1), min(max(cy, y0), y1)
    return best_x, best_y


@_jit
def project_disc_box(point: np.ndarray, center: np.ndarray, radius: float, area: np.ndarray
                     ) -> np.ndarray:  # pragma: no cover - compiled
    """Exact Euclidean projection of ``point`` (2,) onto {||q - center|| <= radius} ∩ the box ``area``
    (x0, x1, y0, y1): the point itself, the disc's projection (if it lies in the box), or the nearest
    point of a box edge clipped to the part of the edge inside the disc. ``center`` must lie in the box."""
    out = np.empty(2)
    out[0], out[1] = _disc_box(point[0], point[1], center[0], center[1], radius, area)
    return out


@_jit
def disc_box_grid(center: np.ndarray, radius: float, area: np.ndarray, spacing: float, max_points: int
                  ) -> np.ndarray:  # pragma: no cover - compiled
    """Points of a square grid of ``spacing`` (m) centred on ``center`` that lie in the disc and the box
    ``area`` (x0, x1, y0, y1), plus the center itself: (n, 2), the first axis outer.

    The grid is laid over the disc's bounding square clipped to the box, so its cost follows the
    reachable area, not the disc; when that would still exceed ``max_points`` points (a long slot or a
    fast drone: the disc grows with (V_max Δτ)²) the spacing is widened until it does not."""
    cx, cy = center[0], center[1]
    x0, x1, y0, y1 = area[0], area[1], area[2], area[3]
    radius = max(radius, 0.0)
    lo0, lo1 = max(x0, cx - radius) - cx, max(y0, cy - radius) - cy
    hi0, hi1 = min(x1, cx + radius) - cx, min(y1, cy + radius) - cy
    cells = (max(hi0 - lo0, 0.0) / spacing + 1.0) * (max(hi1 - lo1, 0.0) / spacing + 1.0)
    if cells > max_points:
        spacing *= math.sqrt(cells / max_points) * 1.01
    first0, last0 = math.ceil(lo0 / spacing - 1e-9), math.floor(hi0 / spacing + 1e-9)
    first1, last1 = math.ceil(lo1 / spacing - 1e-9), math.floor(hi1 / spacing + 1e-9)
    count = max(last0 - first0 + 1, 0) * max(last1 - first1 + 1, 0)
    out = np.empty((count + 1, 2))
    limit = radius * radius + 1e-9
    n = 0
    has_center = False
    for i in range(first0, last0 + 1):
        gx = i * spacing
        for j in range(first1, last1 + 1):
            gy = j * spacing
            if gx ** 2 + gy ** 2 > limit:
                continue
            px, py = gx + cx, gy + cy
            if px >= x0 and px <= x1 and py >= y0 and py <= y1:
                out[n, 0], out[n, 1] = px, py
                has_center = has_center or (px == cx and py == cy)
                n += 1
    if not has_center:
        out[n, 0], out[n, 1] = cx, cy
        n += 1
    return out[:n]


@_jit
def min_plus(costs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Exact split of J units among K users on a grid, for B problems ``costs`` (B, K, J+1): min-plus
    dynamic programming over users (ties go to the fewest units and the smallest budget); the values
    (B,) and allocations (B, K) in units (:func:`agents.optim.min_plus_allocation`)."""
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


@_jit
def _hermite_value(grid: np.ndarray, table: np.ndarray, k: int, x: float) -> float:  # pragma: no cover
    """Cubic Hermite interpolation of AGV k's column at psi = x (``table`` (2 M, K): values, then the
    envelope slopes). The order of the expression's terms is part of the result (floating point):
    reordering them changes the tabulated V in the last bits, and with it the searches' choices."""
    m = grid.size
    top = m - 2
    i = min(max(np.searchsorted(grid, x, side="right") - 1, 0), top)
    h = grid[i + 1] - grid[i]
    t = (x - grid[i]) / h
    t2 = t * t
    t3 = t2 * t
    return ((2 * t3 - 3 * t2 + 1) * table[i, k] + (t3 - 2 * t2 + t) * h * table[m + i, k]
            + (-2 * t3 + 3 * t2) * table[i + 1, k] + (t3 - t2) * h * table[m + i + 1, k])


@_jit
def hermite(grid: np.ndarray, table: np.ndarray, psi: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Each AGV's tabulated V at its psi (K,) (:func:`_hermite_value`)."""
    out = np.empty(psi.size)
    for k in range(psi.size):
        out[k] = _hermite_value(grid, table, k, psi[k])
    return out


@_jit
def _value(kind: int, grid: np.ndarray, table: np.ndarray, k: int, psi: float) -> float:  # pragma: no cover
    """V_k(psi) of a value table (:data:`LINEAR` or :data:`HERMITE`)."""
    if kind == LINEAR:
        return table[0, k] - psi * table[1, k]
    return _hermite_value(grid, table, k, psi)


@_jit
def _success(kind: int, m: float, x: float) -> float:  # pragma: no cover - compiled
    """psi at the outage argument x: ``dv-mpc``'s search (:data:`LINEAR`) in Erlang's closed form
    (:func:`lawn_env.channel.outage_law`'s SERIES), the tabulated planners' (:data:`HERMITE`) by scipy's
    routine as their exact evaluations read it (SUCCESS)."""
    return outage_law(m, x, SERIES if kind == LINEAR else SUCCESS)


@_jit
def _split(kind: int, grid: np.ndarray, table: np.ndarray, agv: np.ndarray, positions: np.ndarray, levels: int,
           budget: float, link: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """The tabulated Phi's exact split of the budget in ``levels`` units at every position: (values
    (n,), allocations (n, K) in units)."""
    k = agv.shape[0]
    unit = budget / levels
    costs = np.empty((positions.shape[0], k, levels + 1))
    for b in range(positions.shape[0]):
        for a in range(k):
            d2 = link_distance_sq(agv[a, 0] - positions[b, 0], agv[a, 1] - positions[b, 1], link[3])
            for j in range(levels + 1):
                x = link_argument(d2, j * unit, link[1], link[2])
                costs[b, a, j] = _value(kind, grid, table, a, _success(kind, link[0], x))
    values, alloc = min_plus(costs)
    return values, alloc


@_jit
def grid_search(kind: int, grid: np.ndarray, table: np.ndarray, agv: np.ndarray, positions: np.ndarray,
                resolution: tuple[int, int, int], budget: float, link: np.ndarray
                ) -> tuple[float, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Best (p, q) of the tabulated Phi (``kind``, ``grid``, ``table``: :data:`LINEAR`, :data:`HERMITE`)
    for the AGVs at ``agv`` (K, 2) over ``positions`` (n, 2) and power splits in units of
    ``budget / levels`` (exact on that grid, min-plus DP); ``resolution`` is (levels, coarse_levels,
    keep). With ``coarse_levels < levels`` and more than ``keep`` positions every position is first
    scored on the coarser power grid and only the ``keep`` best (ties in grid order) are split finely.
    ``link``: (m, c_d, c_ce, H^2) of the planning link. Returns (value, p (K,), q (2,))."""
    levels, coarse_levels, keep = resolution
    if coarse_levels < levels and positions.shape[0] > keep:
        scores, _ = _split(kind, grid, table, agv, positions, coarse_levels, budget, link)
        positions = positions[np.argsort(scores, kind="mergesort")[:keep]]
    values, alloc = _split(kind, grid, table, agv, positions, levels, budget, link)
    best = 0
    for i in range(1, values.size):
        if values[i] < values[best]:
            best = i
    power = np.empty(agv.shape[0])
    for a in range(agv.shape[0]):
        power[a] = alloc[best, a] * (budget / levels)
    return values[best], power, positions[best].copy()


@_jit
def _evaluate(lost: np.ndarray, worth: np.ndarray, agv: np.ndarray, power: np.ndarray, q: np.ndarray,
              link: np.ndarray, psi: np.ndarray, values: np.ndarray) -> float:  # pragma: no cover - compiled
    """Phi(p, q) = sum_k V_k^lost - psi_k w_k of the delivery problem; fills ``psi`` and ``values``."""
    for a in range(lost.size):
        d2 = link_distance_sq(agv[a, 0] - q[0], agv[a, 1] - q[1], link[3])
        psi[a] = outage_law(link[0], link_argument(d2, power[a], link[1], link[2]), SERIES)
        values[a] = lost[a] - psi[a] * worth[a]
    return vector_sum(values)


@_jit
def _gradient(worth: np.ndarray, agv: np.ndarray, power: np.ndarray, q: np.ndarray, link: np.ndarray,
              grad_p: np.ndarray, grad_q: np.ndarray) -> None:  # pragma: no cover - compiled
    """dPhi/dp (K,) and dPhi/dq (2,) of the delivery problem (slope -w_k times d psi_k, the gradients of
    :func:`lawn_env.channel.success_and_gradients`)."""
    gx = 0.0
    gy = 0.0
    for a in range(worth.size):
        dx, dy = q[0] - agv[a, 0], q[1] - agv[a, 1]
        d2 = link_distance_sq(dx, dy, link[3])
        p = max(power[a], POWER_FLOOR_W)
        x = link_argument(d2, p, link[1], link[2])
        g = outage_law(link[0], x, DENSITY) * (x - link[2])
        slope = -worth[a]
        grad_p[a] = slope * (g / p)
        scale = -2.0 * g / d2
        gx += slope * (scale * dx)
        gy += slope * (scale * dy)
    grad_q[0], grad_q[1] = gx, gy


@_jit
def _backtrack(block: int, problem: tuple, space: tuple, power: np.ndarray, q: np.ndarray,  # noqa: PLR0913
               phi: float, g: np.ndarray, alpha: float, work: tuple
               ) -> tuple[bool, float, np.ndarray, int]:  # pragma: no cover - compiled
    """Armijo backtracking (1e-4, at most 20 halvings of ``alpha``) along the projection arc of a step in
    p (``block`` 0) or q (1) down ``g``: (accepted, its Phi, the step, the evaluations made), the point in
    the buffers ``work`` (p, q, psi, V) (``problem``, ``space``: :func:`_refine`'s)."""
    lost, worth, agv = problem
    q_prev, reach, area, budget, link = space
    new_p, new_q, cand_psi, values = work
    x = power if block == 0 else q
    delta = np.zeros(x.size)
    tried = 0
    for _ in range(20):
        trial = x - alpha * g
        if not np.all(np.isfinite(trial)):
            break
        x_new = project_budget(trial, budget) if block == 0 else project_disc_box(trial, q_prev, reach, area)
        delta = x_new - x
        dd = _dot(delta, delta)
        if not math.isfinite(dd) or dd == 0.0:
            break
        if block == 0:
            new_p[:] = x_new
            new_q[:] = q
        else:
            new_p[:] = power
            new_q[:] = x_new
        cand_phi = _evaluate(lost, worth, agv, new_p, new_q, link, cand_psi, values)
        tried += 1
        if cand_phi <= phi + 1e-4 * _dot(g, delta):
            return True, cand_phi, delta, tried
        alpha *= 0.5
    return False, 0.0, delta, tried


@_jit
def _refine(problem: tuple, space: tuple, power: np.ndarray, q: np.ndarray, phi: float, iterations: int,
            psi: np.ndarray) -> tuple[float, int]:  # pragma: no cover - compiled
    """Projected gradient on Phi from (``power``, ``q``) (updated in place, with ``psi``), alternating a
    step in p (onto the budget set) and one in q (onto the disc ∩ area), each with Armijo backtracking
    (:func:`_backtrack`) and its own Barzilai-Borwein step; stops after
    ``iterations`` rounds or a round that improves Phi by at most 1e-10 relative. ``problem``: (V^lost,
    w, the AGVs' positions); ``space``: (q[n-1], the reach, the area, the budget, the link). Returns (Phi,
    the evaluations made)."""
    lost, worth, agv = problem
    _, reach, _, budget, link = space
    k = lost.size
    tolerance = 1e-10
    grad_p, grad_q = np.empty(k), np.empty(2)
    work = (np.empty(k), np.empty(2), np.empty(k), np.empty(k))
    new_p, new_q, cand_psi, _ = work
    _gradient(worth, agv, power, q, link, grad_p, grad_q)
    steps = np.zeros(2)  # 0: no Barzilai-Borwein step yet
    evaluations = 0
    for _ in range(iterations):
        improved = False
        for block in range(2):
            g = grad_p if block == 0 else grad_q
            gnorm = math.sqrt(_dot(g, g))
            if gnorm == 0.0 or not math.isfinite(gnorm):  # flat, or under/overflowed at extreme configs
                continue
            alpha = steps[block] if steps[block] != 0.0 else 0.5 * (budget if block == 0 else reach) / gnorm
            if not (math.isfinite(alpha) and alpha > 0.0):
                continue
            accepted, cand_phi, delta, tried = _backtrack(block, problem, space, power, q, phi, g, alpha, work)
            evaluations += tried
            if not accepted:
                continue
            old = g.copy()
            _gradient(worth, agv, new_p, new_q, link, grad_p, grad_q)
            y = (grad_p if block == 0 else grad_q) - old
            sy = _dot(delta, y)
            steps[block] = _dot(delta, delta) / sy if sy > 0 else 0.0
            if phi - cand_phi > tolerance * abs(phi):
                improved = True
            phi = cand_phi
            power[:] = new_p
            q[:] = new_q
            psi[:] = cand_psi
        if not improved:
            break
    return phi, evaluations


@_jit
def delivery_decisions(scenarios: tuple, last: tuple, shared: tuple, settings: tuple, search_only: bool
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                  np.ndarray]:  # pragma: no cover - compiled
    """``dv-mpc``'s decisions of B scenarios (:class:`agents.DeliveryValuePlanner`). ``scenarios``: their
    values V^lost and w (B, K), the AGVs' positions (B, K, 2), the drone's (B, 2) and its reach (B,);
    ``last``: the previous slot's power (B, K) and move (B, 2), and where there is one (B,); ``shared``:
    the area (4,), the power budget and the link (:func:`grid_search`); ``settings``: the grid's spacing
    and cap, the power levels, the coarse levels, the positions kept and the refinement's rounds.

    Each: the search's point (:func:`grid_search` of the exact values), equal power at hover and the
    previous continuation compared by Phi, the best refined (:func:`_refine`); with ``search_only`` the
    search's point alone. Returns :class:`Decisions`' fields."""
    lost, worth, agv, q_prev, reach = scenarios
    last_power, last_move, has_last = last
    area, budget, link = shared
    spacing, max_points, levels, coarse_levels, keep, iterations = settings
    count, k = lost.shape
    power_out, q_out, psi_out = np.empty((count, k)), np.empty((count, 2)), np.empty((count, k))
    phi_out, origin = np.empty(count), np.zeros(count, dtype=np.int64)
    start_values = np.full((count, 3), np.nan)
    evaluations = np.zeros(count, dtype=np.int64)
    empty = np.empty(0)
    psi, values = np.empty(k), np.empty(k)
    for b in range(count):
        problem = (lost[b], worth[b], agv[b])
        space = (q_prev[b], reach[b], area, budget, link)
        table = np.empty((2, k))
        table[0], table[1] = lost[b], worth[b]
        positions = disc_box_grid(q_prev[b], reach[b], area, spacing, max_points)
        _, power, q = grid_search(LINEAR, empty, table, agv[b], positions, (levels, coarse_levels, keep), budget, link)
        best = _evaluate(lost[b], worth[b], agv[b], power, q, link, psi, values)
        start_values[b, SEARCH] = best
        if not search_only:
            starts = _starts(problem, space, last_power[b], last_move[b], has_last[b])
            for i in (EQUAL, PREVIOUS):
                start_values[b, i] = starts[i][0]
                if starts[i][0] < best:
                    best, power, q, origin[b] = starts[i][0], starts[i][1], starts[i][2], i
            best = _evaluate(lost[b], worth[b], agv[b], power, q, link, psi, values)
            best, refined = _refine(problem, space, power, q, best, iterations, psi)
            evaluations[b] = refined + 2 + has_last[b]  # the search's, equal power's and the previous
        else:
            evaluations[b] = 1
        power_out[b], q_out[b], psi_out[b], phi_out[b] = power, q, psi, best
    return power_out, q_out, psi_out, phi_out, origin, start_values, evaluations


@_jit
def _starts(problem: tuple, space: tuple, last_power: np.ndarray, last_move: np.ndarray, has_last: bool
            ) -> tuple[tuple[float, np.ndarray, np.ndarray], ...]:  # pragma: no cover - compiled
    """The starts other than the search's, as (Phi, p, q) at index :data:`EQUAL` and :data:`PREVIOUS`
    (index :data:`SEARCH` unused; Phi NaN where not tried): equal power at hover, and the previous slot's
    power with its move continued (projected onto this slot's disc ∩ area)."""
    lost, worth, agv = problem
    q_prev, reach, area, budget, link = space
    k = lost.size
    scratch, values = np.empty(k), np.empty(k)
    equal = np.full(k, budget / k)
    hover = q_prev.copy()
    equal_phi = _evaluate(lost, worth, agv, equal, hover, link, scratch, values)
    if not has_last:
        return (math.nan, equal, hover), (equal_phi, equal, hover), (math.nan, equal, hover)
    moved = project_disc_box(q_prev + last_move, q_prev, reach, area)
    previous = last_power.copy()
    previous_phi = _evaluate(lost, worth, agv, previous, moved, link, scratch, values)
    return (math.nan, equal, hover), (equal_phi, equal, hover), (previous_phi, previous, moved)
