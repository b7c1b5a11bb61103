"""The episode's running sums by name (:class:`lawn_env.metrics.Totals`) against the slots' records,
and the simulation state built by keyword only."""

import numpy as np
import pytest

from lawn_env.core import Decisions, SimState, Simulation
from lawn_env.metrics import TOTALS, Totals
from lawn_env.presets import resolve_config


def test_the_running_sums_read_by_name_add_up_the_slots_records():
    config = resolve_config(None)
    k, num = config.num_agvs, 2
    sim = Simulation(config, num_envs=num)
    sim.reset([np.random.default_rng(seed) for seed in range(num)])
    rng = np.random.default_rng(7)
    costs, path = np.zeros((num, 3)), np.zeros(num)
    sq_error, lost, power, largest = np.zeros((num, k)), np.zeros((num, k)), np.zeros((num, k)), np.zeros(num)
    for _ in range(6):
        before = sim.drone_position.copy()
        decisions = Decisions(np.zeros((num, k, 2)), np.full((num, k), config.power_budget_w / k), before + 1.5)
        record = sim.step(decisions, sim.draw(rng))
        costs += record.costs
        path += np.hypot(*(sim.drone_position - before).T)
        sq = sim.tracking_error[..., 0] ** 2 + sim.tracking_error[..., 1] ** 2
        sq_error, lost, power = sq_error + sq, lost + ~record.delivered, power + record.power_w
        largest = np.maximum(largest, sq.max(axis=1))
    sums = sim.state.sums
    assert sums.num_agvs == k and sim.state.totals.shape == (num, 5 + 3 * k)
    np.testing.assert_allclose(sums.tracking, costs[:, 0], rtol=1e-12)
    np.testing.assert_allclose(sums.effort, costs[:, 1], rtol=1e-12)
    np.testing.assert_allclose(sums.control_cost, costs[:, 0] + costs[:, 1], rtol=1e-12)
    np.testing.assert_allclose(sums.path, path, rtol=1e-12)
    np.testing.assert_allclose(sums.sq_error, sq_error, rtol=1e-12)
    np.testing.assert_array_equal(sums.outages, lost)
    np.testing.assert_allclose(sums.power, power, rtol=1e-12)
    np.testing.assert_allclose(sums.max_sq_error, largest, rtol=1e-12)
    assert np.all(sums.outage_p > 0.0) and np.all(sums.outage_p <= 6 * k)
    row = Totals(sim.state.totals[1])  # one scenario's, without the batch axis
    assert row.sq_error.shape == (k,) and row.max_sq_error == sums.max_sq_error[1]
    assert len(TOTALS) == 8 and Totals(Totals.zeros(3, k)).power.shape == (3, k)


def test_the_state_is_built_by_keyword_only():
    sim = Simulation(resolve_config(None))
    fields = {name: getattr(sim.state, name) for name in SimState.__dataclass_fields__}
    assert SimState(**fields).x_aug is sim.state.x_aug
    with pytest.raises(TypeError):
        SimState(*fields.values())
