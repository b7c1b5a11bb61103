"""Reference paths of the AGVs (MODEL.md §1, decided).

Each path is a parametric curve c(theta) with analytic c' and c'' and a time warp theta(t)
with analytic theta' and theta'', so position, velocity and acceleration are exact:
vel = c'(theta) theta', acc = c''(theta) theta'^2 + c'(theta) theta''. The warp
``theta(t) = theta0 + w t + a sin(nu t + phi)`` gives the variable speed the paper describes
(``|a nu| < w`` keeps the direction of travel).

Families: ``lemniscate`` (figure eight), ``rounded_rectangle`` (straight runs with sharp,
small-radius corners), ``sinusoid`` (sinusoidal sweep along a line) and ``spline`` (a periodic
cubic spline through random waypoints). :func:`paper_paths` is the fixed paper-like set for
K = 3 and K = 4; :func:`random_paths` draws K paths from a seeded generator.

Feasibility (MODEL.md §1, decided): a reference the AGV cannot follow makes tracking error
unavoidable. :func:`fit_envelope` slows a path down (a uniform time scaling, so the path keeps its
shape, its sharp turns and its variable speed) until, at every slot, |a_ref| <= f a_max per axis and
|a_ref[n+1] - a_ref[n]| <= f Delta-a_max per axis (f = ``reference.envelope_fraction``, 0.9).
Both path sets are fitted by default; ``envelope=None`` keeps the raw paths (the named stress
variant: the paper-like set then demands up to ~4x a_max at its corners).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import CubicSpline

__all__ = [
    "TimeWarp",
    "Lemniscate",
    "RoundedRectangle",
    "Sinusoid",
    "SplinePath",
    "Envelope",
    "envelope_violation",
    "fit_envelope",
    "paper_paths",
    "random_paths",
    "slowed_until",
    "reference_table",
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

    def scaled(self, factor: float) -> "TimeWarp":
        """The warp run ``factor`` times as fast: theta(factor t)."""
        return TimeWarp(w=self.w * factor, theta0=self.theta0, a=self.a, nu=self.nu * factor, phi=self.phi)

    def __call__(self, t: np.ndarray):
        arg = self.nu * t + self.phi
        theta = self.theta0 + self.w * t + self.a * np.sin(arg)
        dtheta = self.w + self.a * self.nu * np.cos(arg)
        ddtheta = -self.a * self.nu**2 * np.sin(arg)
        return theta, dtheta, ddtheta


class _Curve:
    warp: TimeWarp

    def curve(self, theta: np.ndarray):  # pragma: no cover - interface
        raise NotImplementedError

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        """Reference augmented states [x, y, v_x, v_y, a_x, a_y] at times ``t`` (s): (T, 6)."""
        theta, dth, ddth = self.warp(np.asarray(t, dtype=float))
        c, dc, ddc = self.curve(theta)
        vel = dc * dth[:, None]
        acc = ddc * (dth**2)[:, None] + dc * ddth[:, None]
        return np.hstack([c, vel, acc])


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

    def curve(self, theta):
        rot = _rotation(self.rotation)
        local = np.stack([self.sx * np.cos(theta), 0.5 * self.sy * np.sin(2 * theta)], axis=-1)
        d1 = np.stack([-self.sx * np.sin(theta), self.sy * np.cos(2 * theta)], axis=-1)
        d2 = np.stack([-self.sx * np.cos(theta), -2 * self.sy * np.sin(2 * theta)], axis=-1)
        return np.asarray(self.center) + local @ rot.T, d1 @ rot.T, d2 @ rot.T


@dataclass(frozen=True)
class RoundedRectangle(_Curve):
    """Rectangle with corner radius ``radius`` (sharp turns), parametrized by arc length (m),
    counter-clockwise from the start of the bottom side; negative warp speed runs clockwise."""

    center: tuple[float, float]
    half_width: float
    half_height: float
    radius: float
    warp: TimeWarp

    def _segments(self):
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

    def curve(self, theta):
        segs = self._segments()
        lengths = np.array([s[1] for s in segs])
        starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        perimeter = lengths.sum()
        s = np.mod(theta, perimeter)
        idx = np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(segs) - 1)
        c = np.empty((s.size, 2))
        d1 = np.empty_like(c)
        d2 = np.zeros_like(c)
        for i, (kind, _, anchor, orient) in enumerate(segs):
            sel = idx == i
            if not sel.any():
                continue
            ds = s[sel] - starts[i]
            if kind == "line":
                c[sel] = np.asarray(anchor) + ds[:, None] * np.asarray(orient)
                d1[sel] = orient
            else:
                ang = orient + ds / self.radius
                u = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
                c[sel] = np.asarray(anchor) + self.radius * u
                d1[sel] = np.stack([-np.sin(ang), np.cos(ang)], axis=-1)
                d2[sel] = -u / self.radius
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

    def curve(self, theta):
        u = np.array([math.cos(self.heading), math.sin(self.heading)])
        n = np.array([-u[1], u[0]])
        arg = self.wavenumber * theta + self.phase
        a, k = self.amplitude, self.wavenumber
        c = np.asarray(self.start) + theta[:, None] * u + (a * np.sin(arg))[:, None] * n
        d1 = u + (a * k * np.cos(arg))[:, None] * n
        d2 = (-a * k * k * np.sin(arg))[:, None] * n
        return c, d1, d2


@functools.lru_cache(maxsize=4096)
def _periodic_spline(waypoints: tuple[tuple[float, float], ...]) -> tuple[CubicSpline, float]:
    """The periodic cubic spline through ``waypoints`` by chord length, and its period (cached:
    a path is evaluated many times while it is fitted, and time scaling keeps its waypoints)."""
    pts = np.asarray(waypoints + (waypoints[0],), dtype=float)
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    return CubicSpline(chord, pts, bc_type="periodic"), chord[-1]


@dataclass(frozen=True)
class SplinePath(_Curve):
    """Periodic cubic spline through ``waypoints`` (M, 2), parametrized by cumulative chord length (m)."""

    waypoints: tuple[tuple[float, float], ...]
    warp: TimeWarp

    def _spline(self) -> tuple[CubicSpline, float]:
        return _periodic_spline(self.waypoints)

    def curve(self, theta):
        spline, period = self._spline()
        s = np.mod(theta, period)
        return spline(s), spline(s, 1), spline(s, 2)


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
    def from_config(cls, config, num_steps: int) -> "Envelope | None":
        """The envelope of ``config`` (None when ``reference.envelope_fraction`` is None)."""
        f = config.reference.envelope_fraction
        if f is None:
            return None
        ctl = config.control
        return cls(f * ctl.accel_max_mps2, f * ctl.accel_increment_max_mps2, config.slot_s, int(num_steps))


def envelope_violation(table: np.ndarray, accel_max: float, increment_max: float) -> float:
    """max over slots and axes of |a_ref| / accel_max and |a_ref[n+1] - a_ref[n]| / increment_max for a
    reference table (..., T, 6); <= 1 means the reference is inside the envelope."""
    acc = np.asarray(table)[..., 4:6]
    ratio = np.abs(acc).max() / accel_max
    if acc.shape[-2] > 1:
        ratio = max(ratio, np.abs(np.diff(acc, axis=-2)).max() / increment_max)
    return float(ratio)


def fit_envelope(path: "_Curve", envelope: Envelope, max_rounds: int = 60):
    """``path`` slowed down by the largest uniform time scaling in (0, 1] that keeps it inside
    ``envelope`` at every slot (the path itself when it already is).

    Accelerations scale with the square of the factor and their per-slot changes with its square
    (jumps at curvature breaks) to cube (smooth paths), so the first guess is the cube root of the
    worst ratio; the factor is then shrunk by 2 % until every slot passes. Extreme configs (an
    envelope many orders of magnitude below the path's demand) fall back to halving the factor,
    which always ends: a standing path demands nothing.
    """
    t = np.arange(envelope.num_steps) * envelope.slot_s

    def fits(candidate) -> bool:
        return envelope_violation(candidate.evaluate(t), envelope.accel_max, envelope.increment_max) <= 1.0

    violation = envelope_violation(path.evaluate(t), envelope.accel_max, envelope.increment_max)
    if violation <= 1.0:  # fits(path), evaluated once
        return path
    factor = violation ** (-1.0 / 2.0)
    for _ in range(max_rounds):
        candidate = replace(path, warp=path.warp.scaled(factor))
        if fits(candidate):
            return candidate
        factor *= 0.98
    return slowed_until(path, fits, factor)


def slowed_until(path: "_Curve", accept, first: float = 1.0, refine: int = 30):
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


def _scaled(area_m, x: float, y: float) -> tuple[float, float]:
    """Map a point of the nominal 200 m x 200 m area onto ``area_m``."""
    x0, x1, y0, y1 = area_m
    return (x0 + (x1 - x0) * x / 200.0, y0 + (y1 - y0) * y / 200.0)


def paper_paths(num_agvs: int, area_m=(0.0, 200.0, 0.0, 200.0), envelope: Envelope | None = None) -> list[_Curve]:
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


def _random_path(rng: np.random.Generator, family: str, area_m, margin: float = 2.0) -> _Curve:
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
        pts = tuple((float(cx + r * math.cos(a)), float(cy + r * math.sin(a))) for a, r in zip(angles, radii))
        return SplinePath(waypoints=pts, warp=TimeWarp(w=speed, theta0=rng.uniform(0, 50), a=var * speed / nu,
                                                       nu=nu, phi=rng.uniform(0, 2 * math.pi)))
    raise ValueError(f"unknown reference family {family!r}; valid: {', '.join(FAMILIES)}")


def _inside(table: np.ndarray, area_m, margin: float) -> bool:
    x0, x1, y0, y1 = area_m
    return bool(
        (table[:, 0] >= x0 + margin).all() and (table[:, 0] <= x1 - margin).all()
        and (table[:, 1] >= y0 + margin).all() and (table[:, 1] <= y1 - margin).all()
    )


def random_paths(rng: np.random.Generator, num_agvs: int, families, area_m, duration_s: float,
                 margin_m: float = 2.0, max_tries: int = 20, envelope: Envelope | None = None) -> list[_Curve]:
    """Draw ``num_agvs`` paths from ``families`` (seeded by ``rng``), each inside the area
    (with ``margin_m``, at most 5 % of the shorter side) over ``[0, duration_s]``; draws that leave
    the area are redrawn. With ``envelope`` each draw is slowed into it (:func:`fit_envelope`)
    before the area check. The families are sized to fit a 60 s episode (a draw needs at most one
    retry there); when ``max_tries`` draws all leave the area (long episodes, where an open
    sinusoid walks out), the last draw is slowed down until it stays inside."""
    t = np.linspace(0.0, duration_s, max(2, int(min(duration_s, 1e5) * 4) + 1))
    margin = min(margin_m, 0.05 * min(area_m[1] - area_m[0], area_m[3] - area_m[2]))
    paths = []
    for _ in range(num_agvs):
        family = families[int(rng.integers(len(families)))]
        for _ in range(max_tries):
            path = _random_path(rng, family, area_m, margin)
            if envelope is not None:
                path = fit_envelope(path, envelope)
            if _inside(path.evaluate(t), area_m, margin):
                break
        else:
            path = slowed_until(path, lambda p: _inside(p.evaluate(t), area_m, margin))
        paths.append(path)
    return paths


def reference_table(paths, num_steps: int, slot_s: float) -> np.ndarray:
    """Reference augmented states at slots 0..num_steps-1: (K, num_steps, 6)."""
    t = np.arange(num_steps) * slot_s
    return np.stack([p.evaluate(t) for p in paths])
