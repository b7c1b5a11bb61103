import numpy as np
import pytest

from lawn_env import ScenarioConfig, references
from lawn_env.mpc import OutageAwareMPC

CFG = ScenarioConfig()


def _problems(rng, count, k=4):
    table = references.reference_table(references.paper_paths(4), 131, 0.5)
    for _ in range(count):
        n = int(rng.integers(0, 110))
        x = table[:k, n].copy()
        x[:, 0:2] += rng.normal(0, 4, (k, 2))
        x[:, 2:4] += rng.normal(0, 1, (k, 2))
        x[:, 4:6] = rng.uniform(-2, 2, (k, 2))
        yield x, table[:k, n : n + 11], rng.uniform(0.05, 1.0, k)


@pytest.mark.parametrize("backend", ["compiled", "daqp", "osqp"])
def test_qp_solution_matches_independent_solve(backend, rng, independent_qp):
    mpc = OutageAwareMPC.from_config(CFG, backend=backend)
    for x, ref, psi in _problems(rng, 4):
        sol = mpc.solve(x, ref, psi)
        assert sol.num_fallbacks == 0
        for k in range(4):
            value, z = independent_qp(CFG, x[k], ref[k], psi[k])
            assert sol.value[k] == pytest.approx(value, rel=1e-6)
            assert np.allclose(sol.increments[k], z, atol=1e-4)


def test_solution_respects_control_set(rng):
    mpc = OutageAwareMPC.from_config(CFG)
    for x, ref, psi in _problems(rng, 20):
        sol = mpc.solve(x, ref, psi)
        dmu = sol.increments
        assert np.all(np.abs(dmu) <= 1.0 + 1e-9)
        u = x[:, None, 4:6] + np.cumsum(dmu, axis=1)
        assert np.all(np.abs(u) <= 2.0 + 1e-9)


def test_warm_start_gives_the_cold_answer(rng):
    warm = OutageAwareMPC.from_config(CFG)
    problems = list(_problems(rng, 10))
    warm_vals = [warm.solve(*p).value for p in problems]
    for p, v in zip(problems, warm_vals):
        cold = OutageAwareMPC.from_config(CFG)
        assert np.allclose(cold.solve(*p).value, v, rtol=1e-9)


def test_value_is_the_expected_cost(rng):
    from lawn_env.dynamics import cost_coefficients

    mpc = OutageAwareMPC.from_config(CFG)
    x, ref, psi = next(_problems(rng, 1))
    sol = mpc.solve(x, ref, psi)
    data = mpc.prepare(x, ref)
    l, s, w = cost_coefficients(mpc.model, data.linear, data.constant, sol.increments)
    assert np.allclose(sol.value, l * psi**2 + 2 * s * psi + w)


def test_zero_success_means_no_control_effort(rng):
    mpc = OutageAwareMPC.from_config(CFG)
    x, ref, _ = next(_problems(rng, 1))
    sol = mpc.solve(x, ref, np.zeros(4))
    assert np.allclose(sol.increments, 0.0)


def test_infeasible_data_falls_back_without_raising(rng):
    mpc = OutageAwareMPC.from_config(CFG)
    x, ref, psi = next(_problems(rng, 1))
    x[0, 4] = 5.0  # |u[n-1]| > a_max and more than one increment away: the QP is infeasible
    sol = mpc.solve(x, ref, psi)
    assert sol.status[0] == 2 and np.allclose(sol.increments[0], 0.0)
    assert np.all(sol.status[1:] == 0) and sol.num_fallbacks == 1


def test_unknown_backend_lists_valid_ones():
    with pytest.raises(ValueError, match="valid: compiled, daqp, osqp"):
        OutageAwareMPC.from_config(CFG, backend="gurobi")
    with pytest.raises(ValueError, match="not installed"):
        OutageAwareMPC.from_config(CFG, backend="qpsolvers:nonexistent")


def test_qpsolvers_backend(rng):
    pytest.importorskip("clarabel")
    mpc = OutageAwareMPC.from_config(CFG, backend="qpsolvers:clarabel")
    ref_mpc = OutageAwareMPC.from_config(CFG)
    x, ref, psi = next(_problems(rng, 1))
    assert np.allclose(mpc.solve(x, ref, psi).value, ref_mpc.solve(x, ref, psi).value, rtol=1e-5)


def test_shape_errors_name_the_shapes(rng):
    mpc = OutageAwareMPC.from_config(CFG)
    x, ref, psi = next(_problems(rng, 1))
    with pytest.raises(ValueError, match=r"chi_ref \(4, 10, 6\).*needs \(4, 6\) and \(4, 11, 6\)"):
        mpc.solve(x, ref[:, :10], psi)
    with pytest.raises(ValueError, match="num_agvs=4"):
        mpc.solve(x[:3], ref[:3], psi[:3])


@pytest.mark.parametrize("slot", [0, 1, 2])
def test_move_blocking_holds_the_acceleration_between_commands(slot, rng, independent_qp):
    """MODEL.md §7: with commands every P = 3 slots the MPC plans increments only at the slots
    n + i with (n + i) % 3 == 0; the others are exactly zero, and the solution is the optimum of
    the independent QP with those increments fixed to zero."""
    cfg = CFG.override(**{"disturbance.control_period_slots": 3})
    mpc = OutageAwareMPC.from_config(cfg)
    assert mpc.control_period == 3
    blocked = (slot + np.arange(CFG.control.horizon)) % 3 != 0
    for x, ref, psi in _problems(rng, 2):
        sol = mpc.solve(x, ref, psi, slot=slot)
        assert sol.num_fallbacks == 0
        assert np.all(sol.increments[:, blocked] == 0.0)
        assert np.abs(sol.increments[:, ~blocked]).max() > 0
        free = OutageAwareMPC.from_config(CFG).solve(x, ref, psi)
        assert np.all(sol.value >= free.value - 1e-9)  # a restriction of the every-slot QP
        for k in range(2):
            value, _ = independent_qp(cfg, x[k], ref[k], psi[k], blocked=blocked)
            assert sol.value[k] == pytest.approx(value, rel=1e-6)


def test_period_needs_the_slot_and_the_unaware_ablation_plans_every_slot(rng):
    cfg = CFG.override(**{"disturbance.control_period_slots": 2})
    x, ref, psi = next(_problems(rng, 1))
    with pytest.raises(ValueError, match="control_period=2: pass slot="):
        OutageAwareMPC.from_config(cfg).solve(x, ref, psi)
    unaware = cfg.override(**{"disturbance.period_aware_planning": False})
    assert OutageAwareMPC.from_config(unaware).control_period == 1
    assert np.array_equal(OutageAwareMPC.from_config(unaware).solve(x, ref, psi).increments,
                          OutageAwareMPC.from_config(CFG).solve(x, ref, psi).increments)


def test_batch_shape_errors_name_the_argument(rng):
    """A batch's slots must be one per scenario and a psi stack one per AGV: errors name them."""
    cfg = CFG.override(**{"disturbance.control_period_slots": 2})
    mpc = OutageAwareMPC.from_config(cfg)
    x, ref, psi = next(_problems(rng, 1))
    xs, refs = np.stack([x, x, x]), np.stack([ref, ref, ref])
    with pytest.raises(ValueError, match=r"slot has shape \(2,\); expected a scalar or one per scenario \(3,\)"):
        mpc.prepare(xs, refs, slot=np.array([0, 1]))
    data = mpc.prepare(xs, refs, slot=np.array([0, 1, 2]))
    with pytest.raises(ValueError, match=r"psi has shape \(3, 3\); expected one per problem of the prepared data \(3, 4\)"):
        mpc.solve_prepared(data, np.full((3, 3), 0.5))
    sol = mpc.solve_prepared(data, np.full((5, 3, 4), 0.5))  # a psi stack over the batch: one call
    assert sol.value.shape == (5, 3, 4) and not sol.status.any()
