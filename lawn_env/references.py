"""Reference paths of the AGVs (MODEL.md §1, decided).

Each path is a parametric curve c(theta) with analytic c' and c'' and a time warp theta(t)
with analytic theta' and theta'', so position, velocity and acceleration are exact:
vel = c'(theta) theta', acc = c''(theta) theta'^2 + c'(theta) theta''. The warp
``theta(t) = theta0 + w t + a sin(nu t + phi)`` gives the variable speed the paper describes
(``|a nu| < w`` keeps the direction of travel).

Families: ``lemniscate`` (figure eight), ``rounded_rectangle`` (straight runs with sharp,
small-radius corners), ``sinusoid`` (sinusoidal sweep along a line) and ``spline`` (a periodic
cubic spline through random waypoints). :func:`paper_paths` is the fixed paper-like set for
K = 3 and K = 4; :func:`random_paths` draws K paths from a seeded generator, and
:func:`sample_paths` does so for many generators at once (the vector envs' resets).
:func:`evaluate_paths` evaluates many paths in a few numpy calls per family (each family's
equations are written once, over a leading path axis; ``path.evaluate`` is its one-path case).

Feasibility (MODEL.md §1, decided): a reference the AGV cannot follow makes tracking error
unavoidable. :func:`fit_envelope` slows a path down (a uniform time scaling, so the path keeps its
shape, its sharp turns and its variable speed) until, at every slot, ``|a_ref| <= f a_max`` per axis and
``|a_ref[n+1] - a_ref[n]| <= f Delta-a_max`` per axis (f = ``reference.envelope_fraction``, 0.9).
Both path sets are fitted by default; ``envelope=None`` keeps the raw paths (the named stress
variant: the paper-like set then demands up to ~4x a_max at its corners).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar, cast

import numpy as np
from scipy.interpolate import CubicSpline

if TYPE_CHECKING:
    from .config import ScenarioConfig

__all__ = [
    "TimeWarp",
    "Lemniscate",
    "RoundedRectangle",
    "Sinusoid",
    "SplinePath",
    "Curve",
    "Envelope",
    "envelope_violation",
    "fit_envelope",
    "paper_paths",
    "random_paths",
    "slowed_until",
    "reference_table",
    "evaluate_paths",
    "sample_paths",
    "FAMILIES",
]


@dataclass(frozen=True)
class TimeWarp:
    """theta(t) = theta0 + w t + a sin(nu t + phi), with derivatives."""

    w: float
    theta0: float = 0.0
    a: float = 0.0
    nu: float = 0.0
    phi: float = 0.0

    def scaled(self, factor: float) -> TimeWarp:
        """The warp run ``factor`` times as fast: theta(factor t)."""
        return TimeWarp(w=self.w * factor, theta0=self.theta0, a=self.a, nu=self.nu * factor, phi=self.phi)

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        arg = self.nu * t + self.phi
        theta = self.theta0 + self.w * t + self.a * np.sin(arg)
        dtheta = self.w + self.a * self.nu * np.cos(arg)
        ddtheta = -self.a * self.nu**2 * np.sin(arg)
        return theta, dtheta, ddtheta


def _warps(paths: Sequence[_Curve]) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """theta, theta', theta'' of the paths' warps at times ``t``: a function of t -> three (G, T)."""
    w = np.array([[p.warp.w] for p in paths])
    theta0 = np.array([[p.warp.theta0] for p in paths])
    a = np.array([[p.warp.a] for p in paths])
    nu = np.array([[p.warp.nu] for p in paths])
    phi = np.array([[p.warp.phi] for p in paths])

    # TimeWarp.__call__, the same operations over a leading path axis
    def at(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        arg = nu * t + phi
        sin = np.sin(arg)  # each sine and cosine once: they are most of the cost
        theta = theta0 + w * t + a * sin
        dtheta = w + a * nu * np.cos(arg)
        ddtheta = -a * nu**2 * sin
        return theta, dtheta, ddtheta

    return at


class _Curve:
    """A reference path: every family is a frozen dataclass with a ``warp`` (the declarations say so to
    the type checker: :func:`dataclasses.replace` takes any path)."""

    warp: TimeWarp
    __dataclass_fields__: ClassVar[dict[str, Any]]

    @classmethod
    def curves(cls, paths: Sequence[Any], theta: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - interface
        """c, c', c'' of the paths (all of this family) at their parameters ``theta`` (G, T): (G, T, 2) each."""
        raise NotImplementedError

    def curve(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """c, c', c'' at parameters ``theta`` (T,): (T, 2) each."""
        c, d1, d2 = type(self).curves([self], np.asarray(theta, dtype=float)[None])
        return c[0], d1[0], d2[0]

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        """Reference augmented states [x, y, v_x, v_y, a_x, a_y] at times ``t`` (s): (T, 6)."""
        table: np.ndarray = evaluate_paths([self], t)[0]
        return table


#: A reference path of any family: what :func:`paper_paths` and :func:`sample_paths` return.
Curve = _Curve


def evaluate_paths(paths: Sequence[_Curve], t: np.ndarray) -> np.ndarray:
    """Reference augmented states of many paths at times ``t``: (P, T, 6), row i equal to
    ``paths[i].evaluate(t)``. The paths of each family are evaluated together, a few numpy calls
    over a leading path axis (vel = c'(theta) theta', acc = c''(theta) theta'^2 + c'(theta) theta'')."""
    t = np.asarray(t, dtype=float)
    out = np.empty((len(paths), t.size, 6))
    groups: dict[type[_Curve], list[int]] = {}
    for i, p in enumerate(paths):
        groups.setdefault(type(p), []).append(i)
    for cls, idx in groups.items():
        members = [paths[i] for i in idx]
        theta, dth, ddth = _warps(members)(t)
        c, dc, ddc = cls.curves(members, theta)
        out[idx, :, 0:2] = c
        out[idx, :, 2:4] = dc * dth[..., None]
        out[idx, :, 4:6] = ddc * (dth**2)[..., None] + dc * ddth[..., None]
    return out


def _rotation(angle: float) -> np.ndarray:
    ca, sa = math.cos(angle), math.sin(angle)
    return np.array([[ca, -sa], [sa, ca]])


@dataclass(frozen=True)
class Lemniscate(_Curve):
    """Lemniscate of Gerono: c = center + R [sx cos th, (sy/2) sin 2th]."""

    center: tuple[float, float]
    sx: float
    sy: float
    warp: TimeWarp
    rotation: float = 0.0

    @classmethod
    def curves(cls, paths: Sequence[Lemniscate], theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sx = np.array([[p.sx] for p in paths])
        sy = np.array([[p.sy] for p in paths])
        rot_t = np.stack([_rotation(p.rotation).T for p in paths])
        center = np.array([[p.center] for p in paths], dtype=float)
        cos, sin2 = np.cos(theta), np.sin(2 * theta)
        local = np.stack([sx * cos, 0.5 * sy * sin2], axis=-1)
        d1 = np.stack([-sx * np.sin(theta), sy * np.cos(2 * theta)], axis=-1)
        d2 = np.stack([-sx * cos, -2 * sy * sin2], axis=-1)
        return center + _rotate(local, rot_t), _rotate(d1, rot_t), _rotate(d2, rot_t)


def _rotate(v: np.ndarray, rot_t: np.ndarray) -> np.ndarray:
    """``v @ rot_t`` per path for (P, N, 2) points and (P, 2, 2) rotations, as two products and one sum
    (numpy's ``@`` hands it to BLAS, whose rounding depends on the CPU; :mod:`lawn_env.products`)."""
    out: np.ndarray = v[..., 0:1] * rot_t[:, None, 0, :] + v[..., 1:2] * rot_t[:, None, 1, :]
    return out


@dataclass(frozen=True)
class RoundedRectangle(_Curve):
    """Rectangle with corner radius ``radius`` (sharp turns), parametrized by arc length (m),
    counter-clockwise from the start of the bottom side; negative warp speed runs clockwise."""

    center: tuple[float, float]
    half_width: float
    half_height: float
    radius: float
    warp: TimeWarp

    def _segments(self) -> list[tuple[str, float, tuple[float, float], tuple[float, float] | float]]:
        cx, cy = self.center
        hx, hy, r = self.half_width, self.half_height, self.radius
        lx, ly, arc = 2 * (hx - r), 2 * (hy - r), 0.5 * math.pi * r
        # (kind, length, start point or arc center, direction or start angle)
        return [
            ("line", lx, (cx - hx + r, cy - hy), (1.0, 0.0)),
            ("arc", arc, (cx + hx - r, cy - hy + r), -0.5 * math.pi),
            ("line", ly, (cx + hx, cy - hy + r), (0.0, 1.0)),
            ("arc", arc, (cx + hx - r, cy + hy - r), 0.0),
            ("line", lx, (cx + hx - r, cy + hy), (-1.0, 0.0)),
            ("arc", arc, (cx - hx + r, cy + hy - r), 0.5 * math.pi),
            ("line", ly, (cx - hx, cy + hy - r), (0.0, -1.0)),
            ("arc", arc, (cx - hx + r, cy - hy + r), math.pi),
        ]

    @classmethod
    def curves(cls, paths: Sequence[RoundedRectangle], theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        segs = [p._segments() for p in paths]
        lengths = np.array([[s[1] for s in seg] for seg in segs])
        starts = np.stack([np.concatenate([[0.0], np.cumsum(row)[:-1]]) for row in lengths])
        perimeter = np.array([[row.sum()] for row in lengths])
        radius = np.array([[p.radius] for p in paths])
        s = np.mod(theta, perimeter)
        # the segment of each point: searchsorted(starts, s, side="right") - 1 over a leading path axis
        idx = np.clip((starts[:, None, :] <= s[..., None]).sum(axis=-1) - 1, 0, starts.shape[1] - 1)
        c = np.empty((*s.shape, 2))
        d1 = np.empty_like(c)
        d2 = np.zeros_like(c)
        for i in range(starts.shape[1]):
            sel = idx == i
            if not sel.any():
                continue
            rows = np.nonzero(sel)[0]
            ds = s[sel] - starts[rows, i]
            kind, _, _, orient = segs[0][i]  # the kinds and orientations are the same for every rectangle
            anchor = np.array([seg[i][2] for seg in segs], dtype=float)[rows]
            if kind == "line":
                c[sel] = anchor + ds[:, None] * np.asarray(orient)
                d1[sel] = orient
            else:
                r = radius[rows, 0]
                ang = orient + ds / r
                cos, sin = np.cos(ang), np.sin(ang)
                u = np.stack([cos, sin], axis=-1)
                c[sel] = anchor + r[:, None] * u
                d1[sel] = np.stack([-sin, cos], axis=-1)
                d2[sel] = -u / r[:, None]
        return c, d1, d2


@dataclass(frozen=True)
class Sinusoid(_Curve):
    """Sinusoidal sweep: c = start + u th + n A sin(kappa th + phase), th the along-track distance (m)."""

    start: tuple[float, float]
    heading: float
    amplitude: float
    wavenumber: float
    warp: TimeWarp
    phase: float = 0.0

    @classmethod
    def curves(cls, paths: Sequence[Sinusoid], theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        u = np.array([[[math.cos(p.heading), math.sin(p.heading)]] for p in paths])  # (G, 1, 2)
        n = np.stack([-u[..., 1], u[..., 0]], axis=-1)
        k = np.array([[p.wavenumber] for p in paths])
        a = np.array([[p.amplitude] for p in paths])
        arg = k * theta + np.array([[p.phase] for p in paths])
        start = np.array([[p.start] for p in paths], dtype=float)
        sin = np.sin(arg)
        c = start + theta[..., None] * u + (a * sin)[..., None] * n
        d1 = u + (a * k * np.cos(arg))[..., None] * n
        d2 = (-a * k * k * sin)[..., None] * n
        return c, d1, d2


@functools.lru_cache(maxsize=4096)
def _periodic_spline(waypoints: tuple[tuple[float, float], ...]) -> tuple[CubicSpline, float]:
    """The periodic cubic spline through ``waypoints`` by chord length, and its period (cached:
    a path is evaluated many times while it is fitted, and time scaling keeps its waypoints)."""
    pts = np.asarray((*waypoints, waypoints[0]), dtype=float)
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    return CubicSpline(chord, pts, bc_type="periodic"), chord[-1]


@dataclass(frozen=True)
class SplinePath(_Curve):
    """Periodic cubic spline through ``waypoints`` (M, 2), parametrized by cumulative chord length (m)."""

    waypoints: tuple[tuple[float, float], ...]
    warp: TimeWarp

    def _spline(self) -> tuple[CubicSpline, float]:
        return _periodic_spline(self.waypoints)

    @classmethod
    def curves(cls, paths: Sequence[SplinePath], theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        out = [np.empty((*theta.shape, 2)) for _ in range(3)]
        for i, p in enumerate(paths):  # one spline per path (waypoint counts differ)
            spline, period = p._spline()
            s = np.mod(theta[i], period)
            out[0][i], out[1][i], out[2][i] = spline(s), spline(s, 1), spline(s, 2)
        return out[0], out[1], out[2]


FAMILIES = {
    "lemniscate": Lemniscate,
    "rounded_rectangle": RoundedRectangle,
    "sinusoid": Sinusoid,
    "spline": SplinePath,
}


@dataclass(frozen=True)
class Envelope:
    """What the AGV can follow, sampled on the slot grid: per-axis bounds on the reference
    acceleration and on its change over one slot, and the slots ``num_steps`` at ``slot_s``."""

    accel_max: float  # m/s^2, per axis (already multiplied by the envelope fraction)
    increment_max: float  # m/s^2 per slot, per axis
    slot_s: float
    num_steps: int

    @classmethod
    def from_config(cls, config: ScenarioConfig, num_steps: int) -> Envelope | None:
        """The envelope of ``config`` (None when ``reference.envelope_fraction`` is None)."""
        f = config.reference.envelope_fraction
        if f is None:
            return None
        ctl = config.control
        return cls(f * ctl.accel_max_mps2, f * ctl.accel_increment_max_mps2, config.slot_s, int(num_steps))


def envelope_violation(table: np.ndarray, accel_max: float, increment_max: float) -> float:
    """max over slots and axes of ``|a_ref| / accel_max`` and ``|a_ref[n+1] - a_ref[n]| / increment_max`` for a
    reference table (..., T, 6); <= 1 means the reference is inside the envelope."""
    acc = np.asarray(table)[..., 4:6]
    ratio = np.abs(acc).max() / accel_max
    if acc.shape[-2] > 1:
        ratio = max(ratio, np.abs(np.diff(acc, axis=-2)).max() / increment_max)
    return float(ratio)


def _violations(tables: np.ndarray, accel_max: float, increment_max: float) -> np.ndarray:
    """:func:`envelope_violation` of each table of a stack (P, T, 6): (P,)."""
    acc = tables[..., 4:6]
    ratio: np.ndarray = np.abs(acc).max(axis=(1, 2)) / accel_max
    if acc.shape[-2] > 1:
        ratio = np.maximum(ratio, np.abs(np.diff(acc, axis=-2)).max(axis=(1, 2)) / increment_max)
    return ratio


def fit_envelopes(paths: Sequence[_Curve], envelope: Envelope, max_rounds: int = 60) -> list[_Curve]:
    """:func:`fit_envelope` of many paths at once (each round evaluates every path still outside
    the envelope in one :func:`evaluate_paths` call)."""
    t = np.arange(envelope.num_steps) * envelope.slot_s

    def fits(candidate: _Curve) -> bool:
        return envelope_violation(candidate.evaluate(t), envelope.accel_max, envelope.increment_max) <= 1.0

    out = list(paths)
    violation = _violations(evaluate_paths(paths, t), envelope.accel_max, envelope.increment_max)
    todo = [i for i in range(len(paths)) if violation[i] > 1.0]
    factor = {i: float(violation[i]) ** (-1.0 / 2.0) for i in todo}
    for _ in range(max_rounds):
        if not todo:
            return out
        candidates = [replace(paths[i], warp=paths[i].warp.scaled(factor[i])) for i in todo]
        fits_now = _violations(evaluate_paths(candidates, t), envelope.accel_max, envelope.increment_max) <= 1.0
        for i, cand, ok in zip(todo, candidates, fits_now.tolist(), strict=True):
            if ok:
                out[i] = cand
            else:
                factor[i] *= 0.98
        todo = [i for i, ok in zip(todo, fits_now.tolist(), strict=True) if not ok]
    for i in todo:  # extreme configs: halvings from the last factor
        out[i] = slowed_until(paths[i], fits, factor[i])
    return out


def fit_envelope(path: _Curve, envelope: Envelope, max_rounds: int = 60) -> _Curve:
    """``path`` slowed down by the largest uniform time scaling in (0, 1] that keeps it inside
    ``envelope`` at every slot (the path itself when it already is).

    Accelerations scale with the square of the factor, so the first guess is the inverse square
    root of the worst ratio; the factor is then shrunk by 2 % until every slot passes (per-slot
    changes of the acceleration scale faster than the square at curvature breaks). After
    ``max_rounds`` shrinks (an envelope many orders of magnitude below the path's demand) the
    factor is halved instead, which always ends: a standing path demands nothing.
    """
    return fit_envelopes([path], envelope, max_rounds)[0]


def slowed_until(path: _Curve, accept: Callable[[_Curve], bool], first: float = 1.0, refine: int = 30) -> _Curve:
    """``path`` slowed by a uniform time scaling in (0, ``first``] that ``accept`` takes: halvings
    until one is accepted (a path slowed to a standstill demands nothing and stays where it
    starts), then ``refine`` bisection steps back up towards the largest accepted factor."""
    low, high = first, first
    candidate = replace(path, warp=path.warp.scaled(low))
    for _ in range(2000):
        if accept(candidate):
            break
        high, low = low, low / 2.0
        candidate = replace(path, warp=path.warp.scaled(low))
    else:  # pragma: no cover - 2000 halvings pass 1e-600: below any float
        raise RuntimeError(f"no time scaling of {type(path).__name__} is accepted")
    if high == low:
        return candidate
    for _ in range(refine):
        mid = 0.5 * (low + high)
        trial = replace(path, warp=path.warp.scaled(mid))
        if accept(trial):
            low, candidate = mid, trial
        else:
            high = mid
    return candidate


def _scaled(area_m: Sequence[float], x: float, y: float) -> tuple[float, float]:
    """Map a point of the nominal 200 m x 200 m area onto ``area_m``."""
    x0, x1, y0, y1 = area_m
    return (x0 + (x1 - x0) * x / 200.0, y0 + (y1 - y0) * y / 200.0)


def paper_paths(num_agvs: int, area_m: Sequence[float] = (0.0, 200.0, 0.0, 200.0),
                envelope: Envelope | None = None) -> list[_Curve]:
    """The fixed paper-like set (MODEL.md §1): K = 4 puts two AGVs with the more complex paths
    (sinusoidal sweep, spline with tight bends) in the lower region, as in the paper's Fig. 6;
    K = 3 keeps the first three. Defined on the nominal 200 m area and scaled to ``area_m``;
    with ``envelope`` each path is slowed into it (:func:`fit_envelope`)."""
    if num_agvs not in (3, 4):
        raise ValueError(f"num_agvs={num_agvs}: the paper-like path set is defined for 3 or 4 AGVs")
    sx = (area_m[1] - area_m[0]) / 200.0
    sy = (area_m[3] - area_m[2]) / 200.0
    s = min(sx, sy)
    paths: list[_Curve] = [
        Lemniscate(center=_scaled(area_m, 55, 150), sx=40 * sx, sy=44 * sy,
                   warp=TimeWarp(w=0.1, a=0.25, nu=0.21, phi=0.3)),
        RoundedRectangle(center=_scaled(area_m, 145, 148), half_width=38 * sx, half_height=30 * sy,
                         radius=9.0 * s, warp=TimeWarp(w=4.0 * s, theta0=10 * s, a=3.0 * s, nu=0.35, phi=1.0)),
        Sinusoid(start=_scaled(area_m, 15, 55), heading=0.08, amplitude=18 * sy, wavenumber=2 * math.pi / (55 * sx),
                 warp=TimeWarp(w=2.7 * sx, a=4.0 * sx, nu=0.3)),
        SplinePath(waypoints=(_scaled(area_m, 120, 20), _scaled(area_m, 185, 30), _scaled(area_m, 170, 85),
                              _scaled(area_m, 140, 60), _scaled(area_m, 115, 95), _scaled(area_m, 105, 50)),
                   warp=TimeWarp(w=4.0 * s, a=5.0 * s, nu=0.4, phi=2.0)),
    ]
    paths = paths[:num_agvs]
    return paths if envelope is None else [fit_envelope(p, envelope) for p in paths]


def _random_path(rng: np.random.Generator, family: str, area_m: Sequence[float], margin: float = 2.0) -> _Curve:
    x0, x1, y0, y1 = area_m
    width, height = x1 - x0, y1 - y0
    s = min(width, height) / 200.0
    speed = rng.uniform(2.5, 5.0) * s
    var = rng.uniform(0.2, 0.5)
    nu = rng.uniform(0.2, 0.5)
    if family == "lemniscate":
        ax_, ay_ = rng.uniform(0.12, 0.22) * width, rng.uniform(0.15, 0.3) * height
        ext = max(ax_, ay_) * 1.05
        center = (rng.uniform(x0 + ext, x1 - ext), rng.uniform(y0 + ext, y1 - ext))
        w = speed / (0.75 * max(ax_, ay_))  # mean |c'| of a Gerono lemniscate ~ 0.75 of its size
        return Lemniscate(center=center, sx=ax_, sy=ay_, rotation=rng.uniform(-math.pi, math.pi),
                          warp=TimeWarp(w=w, theta0=rng.uniform(0, 2 * math.pi), a=var * w / nu, nu=nu,
                                        phi=rng.uniform(0, 2 * math.pi)))
    if family == "rounded_rectangle":
        hx, hy = rng.uniform(0.1, 0.2) * width, rng.uniform(0.1, 0.2) * height
        center = (rng.uniform(x0 + hx + margin, x1 - hx - margin), rng.uniform(y0 + hy + margin, y1 - hy - margin))
        sign = rng.choice([-1.0, 1.0])
        return RoundedRectangle(center=center, half_width=hx, half_height=hy, radius=rng.uniform(6, 12) * s,
                                warp=TimeWarp(w=sign * speed, theta0=rng.uniform(0, 100), a=sign * var * speed / nu,
                                              nu=nu, phi=rng.uniform(0, 2 * math.pi)))
    if family == "sinusoid":
        amp = rng.uniform(0.05, 0.1) * min(width, height)
        # along-track extent of one episode stays below 0.8 of the box side
        heading = rng.choice([0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi]) + rng.uniform(-0.15, 0.15)
        u = np.array([math.cos(heading), math.sin(heading)])
        span = 0.85 * (width if abs(u[0]) > abs(u[1]) else height)
        start_c = np.array([(x0 + x1) / 2, (y0 + y1) / 2]) - u * span / 2
        start = start_c + rng.uniform(-0.3, 0.3, 2) * np.array([width, height]) * np.abs(u[::-1])
        return Sinusoid(start=(float(start[0]), float(start[1])), heading=heading, amplitude=amp,
                        wavenumber=2 * math.pi / rng.uniform(0.2, 0.35) / min(width, height),
                        phase=rng.uniform(0, 2 * math.pi),
                        warp=TimeWarp(w=0.7 * speed, a=0.3 * speed / nu, nu=nu, phi=rng.uniform(0, 2 * math.pi)))
    if family == "spline":
        n = int(rng.integers(5, 8))
        cx, cy = rng.uniform(x0 + 0.3 * width, x1 - 0.3 * width), rng.uniform(y0 + 0.3 * height, y1 - 0.3 * height)
        angles = np.sort(rng.uniform(0, 2 * math.pi, n))
        radii = rng.uniform(0.08, 0.25, n) * min(width, height)
        pts = tuple((float(cx + r * math.cos(a)), float(cy + r * math.sin(a)))
                    for a, r in zip(angles, radii, strict=True))
        return SplinePath(waypoints=pts, warp=TimeWarp(w=speed, theta0=rng.uniform(0, 50), a=var * speed / nu,
                                                       nu=nu, phi=rng.uniform(0, 2 * math.pi)))
    raise ValueError(f"unknown reference family {family!r}; valid: {', '.join(FAMILIES)}")


def _inside(table: np.ndarray, area_m: Sequence[float], margin: float) -> bool:
    x0, x1, y0, y1 = area_m
    return bool(
        (table[:, 0] >= x0 + margin).all() and (table[:, 0] <= x1 - margin).all()
        and (table[:, 1] >= y0 + margin).all() and (table[:, 1] <= y1 - margin).all()
    )


def _inside_many(tables: np.ndarray, area_m: Sequence[float], margin: float) -> np.ndarray:
    """:func:`_inside` of each table of a stack (P, T, 6): (P,) bool."""
    x0, x1, y0, y1 = area_m
    x, y = tables[..., 0], tables[..., 1]
    # all(axis=1) of a (P, T) stack is a (P,) array (numpy's stubs also allow a scalar)
    return cast(np.ndarray, (x >= x0 + margin).all(axis=1) & (x <= x1 - margin).all(axis=1)
                & (y >= y0 + margin).all(axis=1) & (y <= y1 - margin).all(axis=1))


def sample_paths(rngs: Sequence[np.random.Generator], num_agvs: int, families: Sequence[str], area_m: Sequence[float],
                 duration_s: float, margin_m: float = 2.0,
                 max_tries: int = 20, envelope: Envelope | None = None) -> list[list[_Curve]]:
    """:func:`random_paths` for many generators at once: ``[random_paths(rng, ...) for rng in
    rngs]``, the same draws from each generator and the same paths, with the envelope fits and
    area checks of all scenarios' candidates evaluated together (one candidate per scenario and
    round: a scenario's next draw depends on whether its last one was accepted)."""
    t = np.linspace(0.0, duration_s, max(2, int(min(duration_s, 1e5) * 4) + 1))
    margin = min(margin_m, 0.05 * min(area_m[1] - area_m[0], area_m[3] - area_m[2]))
    paths: list[list[_Curve]] = [[] for _ in rngs]
    family = [""] * len(rngs)  # each scenario's family, drawn at its first try
    tries = [0] * len(rngs)
    live = [i for i in range(len(rngs)) if num_agvs > 0]
    while live:
        candidates = []
        for i in live:
            if tries[i] == 0:
                family[i] = families[int(rngs[i].integers(len(families)))]
            candidates.append(_random_path(rngs[i], family[i], area_m, margin))
        if envelope is not None:
            candidates = fit_envelopes(candidates, envelope)
        inside = _inside_many(evaluate_paths(candidates, t), area_m, margin).tolist()
        for i, path, ok in zip(live, candidates, inside, strict=True):
            tries[i] += 1
            if ok or tries[i] == max_tries:
                # if every draw left the area: the last one, slowed until it stays inside
                paths[i].append(path if ok else slowed_until(path, lambda p: _inside(p.evaluate(t), area_m, margin)))
                tries[i] = 0
        live = [i for i in live if len(paths[i]) < num_agvs]
    return paths


def random_paths(rng: np.random.Generator, num_agvs: int, families: Sequence[str], area_m: Sequence[float],
                 duration_s: float,
                 margin_m: float = 2.0, max_tries: int = 20, envelope: Envelope | None = None) -> list[_Curve]:
    """Draw ``num_agvs`` paths from ``families`` (seeded by ``rng``), each inside the area
    (with ``margin_m``, at most 5 % of the shorter side) over ``[0, duration_s]``; draws that leave
    the area are redrawn. With ``envelope`` each draw is slowed into it (:func:`fit_envelope`)
    before the area check. The families are sized to fit a 60 s episode (a draw needs at most one
    retry there); when ``max_tries`` draws all leave the area (long episodes, where an open
    sinusoid walks out), the last draw is slowed down until it stays inside."""
    return sample_paths([rng], num_agvs, families, area_m, duration_s, margin_m, max_tries, envelope)[0]


def reference_table(paths: Sequence[_Curve], num_steps: int, slot_s: float) -> np.ndarray:
    """Reference augmented states at slots 0..num_steps-1: (K, num_steps, 6) (any number of paths)."""
    return evaluate_paths(paths, np.arange(num_steps) * slot_s)
