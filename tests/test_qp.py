"""The batched QP solver (lawn_env.qp.PencilQP) and the MPC's "batched" backend against DAQP."""

import numpy as np
import pytest

from lawn_env import ScenarioConfig
from lawn_env.dynamics import PredictionModel
from lawn_env.mpc import OutageAwareMPC
from lawn_env.qp import PencilQP


def _slot_stack(num, seed):
    """``num`` control QPs of the default scenario: tracking errors from centimetres to hundreds of
    metres, previous accelerations anywhere in [-a_max, a_max] and exactly at it, psi in [0, 1]."""
    cfg = ScenarioConfig()
    model = PredictionModel.from_config(cfg)
    rng = np.random.default_rng(seed)
    a_max = cfg.control.accel_max_mps2
    x = rng.normal(size=(num, 6)) * np.array([5, 5, 2, 2, 1, 1]) * rng.choice([0.01, 1.0, 30.0], size=(num, 1))
    x[:, 4:6] = np.clip(x[:, 4:6], -a_max, a_max)
    x[rng.random(num) < 0.2, 4] = a_max  # saturated: the degenerate active sets of a_max = 2 Delta-a_max
    ref = rng.normal(size=(num, model.horizon + 1, 6))
    psi = rng.uniform(0.0, 1.0, num)
    psi[:5] = [0.0, 1.0, 1e-9, 0.5, 1.0]
    return cfg, model, x, ref, psi


def _mpc(cfg, model, num, backend):
    ctl = cfg.control
    return OutageAwareMPC(model, num, ctl.accel_max_mps2, ctl.accel_increment_max_mps2, backend=backend)


def test_batched_backend_matches_daqp_on_random_stacks():
    """Every problem of a 600-stack (the batched steps and the DAQP hand-over alike) to 1e-6
    relative in the optimal value, feasible for the original bounds."""
    cfg, model, x, ref, psi = _slot_stack(600, seed=0)
    batched, daqp = _mpc(cfg, model, 600, "batched"), _mpc(cfg, model, 600, "daqp")
    data = batched.prepare(x, ref)
    got = batched.solve_prepared(data, psi)
    want = daqp.solve_prepared(daqp.prepare(x, ref), psi)
    assert not got.status.any() and not want.status.any()
    np.testing.assert_allclose(got.value, want.value, rtol=1e-6, atol=1e-6)
    z = got.increments.reshape(600, -1)
    assert np.all(np.abs(z) <= cfg.control.accel_increment_max_mps2 + 1e-9)  # DAQP meets bounds to ~1e-11
    accel = x[:, None, 4:6] + np.cumsum(got.increments, axis=1)
    assert np.all(np.abs(accel) <= cfg.control.accel_max_mps2 + 1e-9)
    share = batched.backend.last_settled_share
    assert 0.2 < share < 1.0  # both paths were exercised


def test_pencil_solutions_that_settle_are_exact_and_warm_starts_settle_more():
    cfg, model, x, ref, psi = _slot_stack(400, seed=1)
    mpc = _mpc(cfg, model, 400, "daqp")
    data = mpc.prepare(x, ref)
    p0, p1 = mpc._hessians
    n = model.num_inputs
    solver = PencilQP(p0, p1, np.vstack([np.eye(n), model.increment_sum]), steps=3)
    q = (2.0 * psi)[:, None] * data.linear
    # the increment bounds tightened as the batched backend does (no degenerate active sets)
    lo, up = data.lower.copy(), data.upper.copy()
    lo[:, :n] *= 1 - 1e-9
    up[:, :n] *= 1 - 1e-9
    cold = solver.solve(psi**2, q, lo, up)
    warm = solver.solve(psi**2, q, lo, up, active=cold.active)
    assert cold.converged.mean() > 0.3
    assert warm.converged[cold.converged].all() and (warm.iterations[cold.converged] <= 2).all()  # one step at most
    reference = mpc.solve_prepared(data, psi).value - data.constant
    ok = cold.converged
    np.testing.assert_allclose(cold.objective[ok], reference[ok], rtol=1e-7, atol=1e-7)
    # a check that can fail: with no update steps, a wrong guess is reported, never returned as solved
    strict = PencilQP(p0, p1, solver.a, steps=0)
    wrong = np.zeros_like(cold.active)
    wrong[:, 0] = 1  # z_0x at its upper bound: wrong for most problems
    out = strict.solve(psi**2, q, lo, up, active=wrong)
    assert not out.converged.all()
    np.testing.assert_allclose(out.objective[out.converged], reference[out.converged], rtol=1e-7, atol=1e-7)


def test_pencil_inverse_is_the_hessian_inverse():
    rng = np.random.default_rng(2)
    b = rng.normal(size=(6, 6))
    p1 = b @ b.T
    p0 = np.diag(rng.uniform(1, 3, 6))
    solver = PencilQP(p0, p1, np.eye(6))
    s = np.array([0.0, 0.3, 7.0])
    d = solver.inverse_diagonal(s)
    for i in range(3):
        np.testing.assert_allclose(solver.w @ np.diag(d[i]) @ solver.w.T, np.linalg.inv(s[i] * p1 + p0), rtol=1e-10,
                                   atol=1e-12)


def test_bad_inputs_name_the_argument():
    with pytest.raises(ValueError, match="must be"):
        PencilQP(np.eye(3), np.eye(2), np.eye(3))
    with pytest.raises(ValueError, match="steps"):
        PencilQP(np.eye(2), np.eye(2), np.eye(2), steps=-1)
    solver = PencilQP(np.eye(2), np.eye(2), np.eye(2))
    with pytest.raises(ValueError, match="expected"):
        solver.solve(np.ones(3), np.zeros((3, 2)), np.zeros((3, 3)), np.ones((3, 2)))
    with pytest.raises(ValueError, match="batched"):
        cfg = ScenarioConfig()
        mpc = OutageAwareMPC.from_config(cfg)  # daqp: one scenario at a time
        mpc.prepare(np.zeros((2, cfg.num_agvs, 6)), np.zeros((2, cfg.num_agvs, cfg.control.horizon + 1, 6)))
