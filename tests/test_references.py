import numpy as np
import pytest

from lawn_env import ScenarioConfig, presets, references


def _in_area(table, area=(0, 200, 0, 200)):
    return (table[..., 0].min() >= area[0] and table[..., 0].max() <= area[1]
            and table[..., 1].min() >= area[2] and table[..., 1].max() <= area[3])


@pytest.mark.parametrize("k", [3, 4])
def test_paper_paths_inside_area_and_distinct(k):
    table = references.reference_table(references.paper_paths(k), 131, 0.5)
    assert table.shape == (k, 131, 6) and _in_area(table)
    speeds = np.linalg.norm(table[..., 2:4], axis=-1)
    assert speeds.min() > 0.5 and speeds.max() < 10.0
    assert len({tuple(np.round(table[i, 0, :2], 3)) for i in range(k)}) == k
    # the raw (stress) set: its corners demand more than the AGV can follow (a_max = 2)
    assert np.abs(table[..., 4:6]).max() > 2.0


CFG = ScenarioConfig()
ENVELOPE = references.Envelope.from_config(CFG, CFG.num_slots + CFG.control.horizon + 1)


def _feasible(table, cfg=CFG):
    f, ctl = cfg.reference.envelope_fraction, cfg.control
    acc = table[..., 4:6]
    return (np.abs(acc).max() <= f * ctl.accel_max_mps2 + 1e-12
            and np.abs(np.diff(acc, axis=-2)).max() <= f * ctl.accel_increment_max_mps2 + 1e-12)


@pytest.mark.parametrize("k", [3, 4])
def test_paper_paths_respect_the_envelope_and_keep_sharp_turns_and_variable_speed(k):
    """MODEL.md §1: |a_ref| <= 0.9 a_max and |a_ref[n+1] - a_ref[n]| <= 0.9 Delta-a_max per axis at
    every slot the env uses (slots 0 .. N + N_p), through the env's own config path."""
    from lawn_env.core import Simulation

    sim = Simulation(ScenarioConfig(num_agvs=k))
    sim.reset([np.random.default_rng(0)])
    table = sim.row(0).reference
    assert table.shape == (k, CFG.num_slots + CFG.control.horizon + 1, 6) and _in_area(table)
    assert _feasible(table)
    speed = np.linalg.norm(table[..., 2:4], axis=-1)
    assert (speed.max(axis=1) / speed.min(axis=1)).min() > 1.3  # variable speed on every path
    rect = references.paper_paths(4, envelope=ENVELOPE)[1]
    assert rect.radius <= 10.0  # a tight corner, taken slowly enough
    assert not _feasible(references.reference_table(references.paper_paths(k), table.shape[1], CFG.slot_s))


@pytest.mark.parametrize("family", list(references.FAMILIES))
def test_every_random_family_respects_the_envelope_over_many_seeds(family):
    steps = CFG.num_slots + CFG.control.horizon + 1
    for seed in range(60):
        paths = references.random_paths(np.random.default_rng(seed), 2, (family,), (0, 200, 0, 200),
                                        (steps - 1) * CFG.slot_s, envelope=ENVELOPE)
        table = references.reference_table(paths, steps, CFG.slot_s)
        assert _feasible(table), (family, seed)
        assert _in_area(table)


def test_envelope_follows_the_control_config_and_can_be_switched_off():
    tight = ScenarioConfig(control={"accel_max_mps2": 1.0, "accel_increment_max_mps2": 0.5})
    env = references.Envelope.from_config(tight, 131)
    table = references.reference_table(references.paper_paths(4, envelope=env), 131, 0.5)
    assert _feasible(table, tight)
    assert references.Envelope.from_config(presets.get("stress-paths"), 131) is None
    with pytest.raises(ValueError, match="envelope_fraction"):
        ScenarioConfig(reference={"envelope_fraction": 1.5})


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


@pytest.mark.parametrize("num_slots, envelope_on", [(120, True), (2000, True), (120, False)],
                         ids=["default", "long-episodes-retry", "no-envelope"])
def test_sample_paths_draws_what_random_paths_draws_from_each_generator(num_slots, envelope_on):
    """The batched sampler (vector envs) gives each generator the paths random_paths gives it, and
    leaves each generator in the same state (the initial offsets are drawn next)."""
    cfg = ScenarioConfig(num_agvs=6, num_slots=num_slots)
    steps = num_slots + cfg.control.horizon + 1
    envelope = references.Envelope.from_config(cfg, steps) if envelope_on else None
    kwargs = dict(num_agvs=6, families=cfg.reference.families, area_m=(0.0, 200.0, 0.0, 200.0),
                  duration_s=(steps - 1) * cfg.slot_s, envelope=envelope)
    batched_rngs = [np.random.default_rng(s) for s in range(5)]
    batched = references.sample_paths(batched_rngs, **kwargs)
    for s in range(5):
        rng = np.random.default_rng(s)
        assert references.random_paths(rng, **kwargs) == batched[s]
        assert rng.random() == batched_rngs[s].random()
    flat = [p for row in batched for p in row]
    t = np.arange(steps) * cfg.slot_s
    table = references.evaluate_paths(flat, t)
    for i in (0, 7, 13, 29):
        np.testing.assert_array_equal(table[i], flat[i].evaluate(t))
