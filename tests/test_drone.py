"""The drone's move (lawn_env.drone): one compiled rule for one drone and for a batch, equal to the
scalar rule written with Python's math (the oracle) to the last bit."""

import math

import numpy as np
import pytest

from lawn_env.drone import hypot, move_drone, toward

AREA = (0.0, 200.0, 0.0, 200.0)


def _scalar_move(p, v, vmax, dt, area):
    """The rule in plain Python: the speed by math.hypot, the radial clip, the area box."""
    vx, vy = float(v[0]), float(v[1])
    speed = math.hypot(vx, vy)
    if speed > vmax:
        vx, vy = vx * vmax / speed, vy * vmax / speed
    x0, x1, y0, y1 = area
    return [min(max(float(p[0]) + vx * dt, x0), x1), min(max(float(p[1]) + vy * dt, y0), y1)]


def _scalar_toward(p, t, vmax, dt, area):
    sx, sy = float(t[0]) - float(p[0]), float(t[1]) - float(p[1])
    dist = math.hypot(sx, sy)
    v = (sx / dt, sy / dt) if dist <= vmax * dt else (sx * (vmax / dist), sy * (vmax / dist))
    return _scalar_move(p, v, vmax, dt, area)


def test_hypot_is_pythons_to_the_last_bit():
    rng = np.random.default_rng(0)
    scale = 10.0 ** rng.integers(-300, 305, (20_000, 1))
    pairs = np.concatenate([rng.normal(size=(20_000, 2)) * scale, rng.uniform(-40, 40, (20_000, 2)),
                            [[0.0, -0.0], [3.0, 4.0], [2.3e-308, 1e-310], [1e308, 1e308], [np.inf, np.nan],
                             [np.nan, 1.0], [-np.inf, 2.0]]])
    for a, b in pairs.tolist():
        want, got = math.hypot(a, b), hypot(a, b)
        assert got == want or (math.isnan(got) and math.isnan(want)), (a, b, got, want)
    for a, b in ((5e-324, 5e-324), (6.0e-310, -9.5e-310)):  # both subnormal: to a subnormal's last place
        assert abs(hypot(a, b) - math.hypot(a, b)) <= 2 * 5e-324


@pytest.mark.parametrize("batch", [1, 500])
def test_one_rule_for_one_drone_and_for_a_batch(batch):
    rng = np.random.default_rng(batch)
    pos = rng.uniform(-20, 220, (batch, 2)).clip(0, 200)
    vel = rng.uniform(-40, 40, (batch, 2))
    vel[::3] *= 15.0 / np.hypot(vel[::3, 0], vel[::3, 1])[:, None]  # at the speed limit, up to rounding
    want = np.array([_scalar_move(p, v, 15.0, 0.5, AREA) for p, v in zip(pos, vel)])
    np.testing.assert_array_equal(move_drone(pos, vel, 15.0, 0.5, AREA), want)
    np.testing.assert_array_equal(move_drone(pos[0], vel[0], 15.0, 0.5, AREA), want[0])  # one drone, shape (2,)
    target = pos + rng.uniform(-12, 12, (batch, 2))
    want = np.array([_scalar_toward(p, t, 15.0, 0.5, AREA) for p, t in zip(pos, target)])
    np.testing.assert_array_equal(toward(pos, target, 15.0, 0.5, AREA), want)
    step = np.hypot(*(move_drone(pos, vel, 15.0, 0.5, AREA) - pos).T)
    assert np.all(step <= 7.5 + 1e-12)  # the speed limit, up to the rounding of positions near 200 m


def test_mismatched_shapes_are_refused():
    with pytest.raises(ValueError, match=r"position \(3, 2\) and velocity \(2, 2\)"):
        move_drone(np.zeros((3, 2)), np.zeros((2, 2)), 15.0, 0.5, AREA)
    with pytest.raises(ValueError, match=r"target \(3,\)"):
        toward(np.zeros(2), np.zeros(3), 15.0, 0.5, AREA)
