import numpy as np
import pytest

from lawn_env import drone, spaces


def test_power_map_respects_budget_and_inverts(rng):
    for k in (1, 2, 4, 32):
        for _ in range(200):
            a = rng.uniform(-1, 1, k)
            p = spaces.decode_power(a, 2.0)
            assert np.all(p >= 0) and p.sum() <= 2.0 * (1 + 1e-12)
        # every feasible split is reachable, exactly
        target = rng.dirichlet(np.ones(k)) * rng.uniform(0.2, 2.0)
        assert np.allclose(spaces.decode_power(spaces.encode_power(target, 2.0), 2.0), target)
    assert np.allclose(spaces.decode_power(np.zeros(4), 1.0), 0.25)  # zero action: equal split
    assert np.allclose(spaces.decode_power(-np.ones(3), 1.0), 0.0)
    with pytest.raises(ValueError, match="not a feasible split"):
        spaces.encode_power(np.array([0.8, 0.8]), 1.0)


def test_drone_move_is_feasible_and_inverts(rng):
    area = (0.0, 200.0, 0.0, 200.0)
    for _ in range(500):
        q = rng.uniform(0, 200, 2)
        v = spaces.decode_drone(rng.uniform(-1, 1, 2), 15.0)
        q2 = drone.move_drone(q, v, 15.0, 0.5, area)
        assert np.linalg.norm(q2 - q) <= 7.5 + 1e-9 and np.all((q2 >= 0) & (q2 <= 200))
        a = spaces.encode_drone(q2, q, 15.0, 0.5)
        assert np.allclose(drone.move_drone(q, spaces.decode_drone(a, 15.0), 15.0, 0.5, area), q2)


def test_increment_maps():
    a = np.array([0.5, -1.0, 1.0, 0.0])
    du = spaces.decode_increments(a, 1.0)
    assert du.shape == (2, 2) and np.allclose(spaces.encode_increments(du, 1.0), a)


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
    obs = layout.encode(sim, bound)
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
    untabled = ObservationLayout(cfg)
    untabled.batch_window_table_bytes = 0  # no table: every feature from the compiled loop
    assert untabled._slot_table(sim.params.fixed_reference) is None
    assert np.array_equal(untabled.encode(sim, bound), obs)
