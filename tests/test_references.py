import numpy as np
import pytest

from lawn_env import references


def _in_area(table, area=(0, 200, 0, 200)):
    return (table[..., 0].min() >= area[0] and table[..., 0].max() <= area[1]
            and table[..., 1].min() >= area[2] and table[..., 1].max() <= area[3])


@pytest.mark.parametrize("k", [3, 4])
def test_paper_paths_inside_area_and_distinct(k):
    table = references.reference_table(references.paper_paths(k), 131, 0.5)
    assert table.shape == (k, 131, 6) and _in_area(table)
    speeds = np.linalg.norm(table[..., 2:4], axis=-1)
    assert 0.5 < speeds.min() and speeds.max() < 10.0
    assert len({tuple(np.round(table[i, 0, :2], 3)) for i in range(k)}) == k
    # sharp turns: some reference accelerations exceed what the AGV can follow (a_max = 2)
    assert np.abs(table[..., 4:6]).max() > 2.0


def test_paper_paths_reject_other_k():
    with pytest.raises(ValueError, match="3 or 4"):
        references.paper_paths(5)


def _smooth_paths(rng):
    paths = list(references.paper_paths(4))
    for fam in ("lemniscate", "sinusoid", "spline"):
        paths += references.random_paths(rng, 2, (fam,), (0, 200, 0, 200), 60.0)
    return [p for p in paths if not isinstance(p, references.RoundedRectangle)]


def test_velocity_and_acceleration_are_exact_derivatives(rng):
    t = np.linspace(0, 60, 60001)
    dt = t[1] - t[0]
    for path in _smooth_paths(rng):
        tab = path.evaluate(t)
        vel_fd = np.gradient(tab[:, 0:2], dt, axis=0)[2:-2]
        acc_fd = np.gradient(tab[:, 2:4], dt, axis=0)[2:-2]
        assert np.abs(vel_fd - tab[2:-2, 2:4]).max() < 1e-4
        assert np.abs(acc_fd - tab[2:-2, 4:6]).max() < 5e-3


def test_rounded_rectangle_derivatives_away_from_corner_switches():
    path = references.paper_paths(4)[1]
    t = np.linspace(0, 60, 60001)
    dt = t[1] - t[0]
    tab = path.evaluate(t)
    vel_fd = np.gradient(tab[:, 0:2], dt, axis=0)
    assert np.abs(vel_fd - tab[:, 2:4])[2:-2].max() < 5e-3  # position is C1 (FD error ~ dt x curvature jump)
    acc_fd = np.gradient(tab[:, 2:4], dt, axis=0)
    jump = np.abs(acc_fd - tab[:, 4:6]).max(axis=1)
    assert np.mean(jump < 1e-2) > 0.99  # exact except at the few samples where curvature jumps


def test_random_paths_seeded_and_inside(rng):
    area = (0.0, 300.0, 50.0, 250.0)
    a = references.random_paths(np.random.default_rng(3), 8, tuple(references.FAMILIES), area, 65.0)
    b = references.random_paths(np.random.default_rng(3), 8, tuple(references.FAMILIES), area, 65.0)
    ta, tb = references.reference_table(a, 131, 0.5), references.reference_table(b, 131, 0.5)
    assert np.array_equal(ta, tb)
    assert _in_area(ta, area)
    c = references.reference_table(references.random_paths(np.random.default_rng(4), 8, tuple(references.FAMILIES), area, 65.0), 131, 0.5)
    assert not np.allclose(ta, c)


def test_unknown_family():
    with pytest.raises(ValueError, match="unknown reference family"):
        references.random_paths(np.random.default_rng(0), 1, ("zigzag",), (0, 200, 0, 200), 10.0)
