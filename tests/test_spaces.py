import numpy as np
import pytest

from lawn_env import drone, spaces
from lawn_env.core import Decisions


def _codec(k=4, role="comm", budget_dbw=None):
    from lawn_env import ScenarioConfig

    cfg = ScenarioConfig(num_agvs=k, **({} if budget_dbw is None else {"power_budget_dbw": budget_dbw}))
    return spaces.DirectActions(cfg, role), cfg


def test_power_map_respects_budget_and_inverts(rng):
    q = np.array([100.0, 100.0])
    for k in (1, 2, 4, 32):
        codec, cfg = _codec(k, budget_dbw=3.0)
        budget = cfg.power_budget_w
        for _ in range(200):
            a = np.concatenate([rng.uniform(-1, 1, k), [0.0, 0.0]])
            p = codec.decode(a, None, None, q).power_w
            assert np.all(p >= 0) and p.sum() <= budget * (1 + 1e-12)
        # every feasible split is reachable, exactly
        target = rng.dirichlet(np.ones(k)) * rng.uniform(0.1, 1.0) * budget
        action = codec.encode(Decisions(None, target, q), None, None, q)
        assert np.allclose(codec.decode(action, None, None, q).power_w, target, rtol=0, atol=1e-6 * budget)  # float32
    codec, cfg = _codec(4)
    zero = codec.decode(np.zeros(6), None, None, q).power_w
    assert np.allclose(zero, cfg.power_budget_w / 4)  # zero action: equal split
    assert np.allclose(codec.decode(-np.ones(6), None, None, q).power_w, 0.0)
    with pytest.raises(ValueError, match="not a feasible split"):
        codec.encode(Decisions(None, np.full(4, cfg.power_budget_w / 2), q), None, None, q)


def test_drone_move_is_feasible_and_inverts(rng):
    codec, cfg = _codec(2)
    reach = cfg.drone_reach_m
    for _ in range(500):
        q = rng.uniform(0, 200, 2)
        a = np.concatenate([np.zeros(2), rng.uniform(-1, 1, 2)])
        q2 = codec.decode(a, None, None, q).drone_next
        assert np.linalg.norm(q2 - q) <= reach + 1e-9 and np.all((q2 >= 0) & (q2 <= 200))
        assert np.allclose(q2, drone.move_drone(q, a[2:] * cfg.drone.max_speed_mps, cfg.drone.max_speed_mps,
                                                cfg.slot_s, cfg.area_m))
        back = codec.encode(Decisions(None, np.zeros(2), q2), None, None, q)
        assert np.allclose(codec.decode(back, None, None, q).drone_next, q2, rtol=0, atol=1e-5)  # float32 actions


def test_increment_maps():
    codec, cfg = _codec(2, "joint")
    a = np.array([0.5, -1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    q = np.array([100.0, 100.0])
    d = codec.decode(a, None, None, q)
    assert d.increment.shape == (2, 2)
    np.testing.assert_allclose(d.increment.reshape(-1), a[:4] * cfg.control.accel_increment_max_mps2)
    np.testing.assert_allclose(codec.encode(d, None, None, q), a, atol=1e-7)


def test_check_action_messages():
    with pytest.raises(ValueError, match=r"entries \[1\]"):
        spaces.check_action([0.0, 2.0, 0.0], 3)
    with pytest.raises(ValueError, match="shape"):
        spaces.check_action(np.zeros((2, 2)), 3)
    with pytest.raises(ValueError, match=r"shape \(1, 3\); expected \(3,\)"):
        spaces.check_action(np.zeros((1, 3)), 3)  # no silent reshape


@pytest.mark.parametrize("num_agvs", [4, 6])  # the fixed path set (a precomputed table) and random paths
@pytest.mark.parametrize("bound", [None, 0.5])
def test_encode_equals_its_numpy_oracle_bit_for_bit(num_agvs, bound):
    """The compiled encode (a table row for a fixed path set, windows computed in the loop otherwise)
    equals the observation written out with ``scaled_windows`` and float32 rounding, clipped to the
    bound, for a batch of scenarios at different slots; and with the table switched off, the same."""
    from lawn_env import ObservationLayout, ScenarioConfig
    from lawn_env.core import Decisions, Simulation

    cfg = ScenarioConfig(num_agvs=num_agvs, num_slots=30)
    sim = Simulation(cfg, 5)
    sim.reset([np.random.default_rng(s) for s in range(5)])
    draws = np.random.default_rng(0)
    for t in range(7):
        decisions = Decisions(draws.uniform(-1, 1, (5, num_agvs, 2)), np.full((5, num_agvs), 0.2),
                              sim.state.drone_position + draws.uniform(-3, 3, (5, 2)))
        sim.step(decisions, sim.draw(draws))
        sim.state.slot[:] = np.arange(5) + t  # scenarios at different slots
    layout = ObservationLayout(cfg)
    table = layout.slot_table(sim.params.fixed_reference)  # None for random paths
    obs = layout.encode(sim, bound, table)
    k, f, win = num_agvs, layout.agv_features, layout.slices["reference"]
    expected = np.empty_like(obs)
    expected[:, : k * f].reshape(5, k, f)[..., win] = layout.scaled_windows(sim.reference_windows())
    expected[:, -1] = sim.state.slot / cfg.num_slots
    if bound is not None:
        expected = np.clip(expected, np.float32(-bound), np.float32(bound))
        assert (np.abs(obs) == np.float32(bound)).any()  # the bound bites
    windows = np.zeros(obs.shape, bool)
    windows[:, : k * f].reshape(5, k, f)[..., win] = True
    windows[:, -1] = True
    assert np.array_equal(obs[windows], expected[windows])
    assert (table is None) == (num_agvs > 4)
    assert np.array_equal(layout.encode(sim, bound), obs)  # no table: every feature from the compiled loop
    small = ObservationLayout(cfg)
    small.batch_window_table_bytes = 0
    assert small.slot_table(sim.params.fixed_reference) is None
