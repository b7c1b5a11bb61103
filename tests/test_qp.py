"""The compiled QP solver (lawn_env.qp) and the MPC's default backend against DAQP, the oracle."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lawn_env import ScenarioConfig
from lawn_env.dynamics import PredictionModel, command_mask
from lawn_env.mpc import OutageAwareMPC
from lawn_env.qp import AxisPencils


def _slot_stack(num, seed, cfg=None):
    """``num`` control QPs of a scenario: tracking errors from centimetres to hundreds of metres,
    previous accelerations anywhere in [-a_max, a_max] and exactly at it (the degenerate active sets
    of a_max = 2 Delta-a_max), psi in [0, 1] with its ends."""
    cfg = cfg or ScenarioConfig()
    model = PredictionModel.from_config(cfg)
    rng = np.random.default_rng(seed)
    a_max = cfg.control.accel_max_mps2
    x = rng.normal(size=(num, 6)) * np.array([5, 5, 2, 2, 1, 1]) * rng.choice([0.01, 1.0, 30.0], size=(num, 1))
    x[:, 4:6] = np.clip(x[:, 4:6], -a_max, a_max)
    x[rng.random(num) < 0.2, 4] = a_max
    x[rng.random(num) < 0.1, 5] = -a_max
    ref = rng.normal(size=(num, model.horizon + 1, 6))
    psi = rng.uniform(0.0, 1.0, num)
    psi[:5] = [0.0, 1.0, 1e-9, 0.5, 1.0]
    return cfg, model, x, ref, psi


def _mpc(cfg, num, backend, period=1):
    ctl = cfg.control
    return OutageAwareMPC(PredictionModel.from_config(cfg), num, ctl.accel_max_mps2, ctl.accel_increment_max_mps2,
                          backend=backend, control_period=period)


def _check_against_daqp(cfg, x, ref, psi, period=1, slot=None, fallbacks=0.0, rtol=1e-9):
    """The compiled answers: at most a share ``fallbacks`` of problems handed to the fallback (a
    cold DAQP solve, status 1), objective equal to DAQP's to ``rtol`` relative, feasible to 1e-9 for
    the original bounds, blocked increments exactly zero; a warm re-solve (every problem from its
    own previous working set) gives the same answer."""
    num, k = x.shape[0], x.shape[-2]
    fast, oracle = _mpc(cfg, k, "compiled", period), _mpc(cfg, k, "daqp", period)
    data = fast.prepare(x, ref, slot)
    got = fast.solve_prepared(data, psi)
    want = oracle.solve_prepared(oracle.prepare(x, ref, slot), psi)
    assert not want.status.any() and np.all(got.status <= 1) and got.status.mean() <= fallbacks
    scale = np.maximum(1.0, np.abs(want.value))
    assert np.max(np.abs(got.value - want.value) / scale) < rtol
    z = got.increments.reshape(num, -1)
    bounds = data.lower.reshape(num, -1)[:, : z.shape[1]], data.upper.reshape(num, -1)[:, : z.shape[1]]
    assert np.all(z >= bounds[0]) and np.all(z <= bounds[1])  # met exactly
    ctl = cfg.control
    accel = x.reshape(num, 6)[:, None, 4:6] + np.cumsum(got.increments.reshape(num, -1, 2), axis=1)
    assert np.all(np.abs(accel) <= ctl.accel_max_mps2 * (1 + 1e-9))
    warm = fast.solve_prepared(data, psi)
    assert np.max(np.abs(warm.value - got.value) / scale) < rtol
    np.testing.assert_allclose(warm.increments, got.increments, rtol=0, atol=1e-9)
    return got


def test_compiled_solver_matches_daqp_on_random_stacks():
    cfg, _, x, ref, psi = _slot_stack(800, seed=0)
    got = _check_against_daqp(cfg, x, ref, psi)
    assert np.median(got.iterations) > 2  # cold starts had constraints to add: the active-set loop ran


@pytest.mark.parametrize("period", [2, 3])
def test_move_blocking_stacks_match_daqp_in_every_phase(period):
    cfg, _, x, ref, psi = _slot_stack(300, seed=period)
    slots = np.arange(300) % period  # one slot per problem: every phase in one stack
    got = _check_against_daqp(cfg, x[:, None], ref[:, None], psi[:, None], period=period, slot=slots)
    for s in range(period):
        blocked = ~command_mask(s, cfg.control.horizon, period)
        assert np.all(got.increments[slots == s][:, 0, blocked] == 0.0)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), period=st.integers(1, 3), a_max=st.floats(0.5, 5.0),
       da_ratio=st.sampled_from([0.5, 1.0, 0.37, 2.0]), q1=st.floats(1e-3, 1e3), q2=st.floats(1e-3, 1e3),
       qv=st.floats(0.0, 1e2), scale=st.sampled_from([0.01, 1.0, 30.0]))
def test_property_compiled_equals_daqp(seed, period, a_max, da_ratio, q1, q2, qv, scale):
    """Random states, references, psi in [0, 1], bounds (a_max an integer multiple of Delta-a_max
    or not), control periods 1-3 and weights across their range: DAQP's optimum to 1e-9. At the
    extremes (Q2 1e-3 of Q1, errors of tens of metres, a_max = Delta-a_max: long, degenerate
    active-set paths) a few problems exceed the iteration cap and go to DAQP, at most 1 in 10, and
    the two optima agree to 1e-8 relative (Q1 = 728, Q2 = 0.25, Delta-a_max = 2 a_max: 1.004e-9)."""
    cfg = ScenarioConfig().override(**{"control.accel_max_mps2": a_max,
                                       "control.accel_increment_max_mps2": a_max * da_ratio,
                                       "control.q1_diag": [q1, q1 * 2, qv, qv, 0.0, 0.0],
                                       "control.q2_diag": [q2, q2 * 0.5]})
    rng = np.random.default_rng(seed)
    num = 40
    model = PredictionModel.from_config(cfg)
    x = rng.normal(size=(num, 6)) * scale
    x[:, 4:6] = np.clip(rng.normal(size=(num, 2)) * a_max, -a_max, a_max)
    ref = rng.normal(size=(num, model.horizon + 1, 6)) * scale
    psi = rng.uniform(0.0, 1.0, num)
    slots = rng.integers(0, 10, num)
    _check_against_daqp(cfg, x[:, None], ref[:, None], psi[:, None], period=period,
                        slot=slots if period > 1 else None, fallbacks=0.1, rtol=1e-8)


def test_captured_comm_rollout_stacks_match_daqp():
    """QPs as the Comm-v1 vector env poses them under random actions (many AGVs saturating),
    captured from its MPC, warm starts as in use: every answer is DAQP's optimum."""
    import gymnasium as gym

    envs = gym.make_vec("lawn/Comm-v1", num_envs=16, vectorization_mode="vector_entry_point")
    mpc = envs.unwrapped.mpc
    captured = []
    real = mpc.solve_prepared

    def capture(data, psi):
        captured.append((data, np.array(psi)))
        return real(data, psi)

    mpc.solve_prepared = capture
    envs.reset(seed=3)
    envs.action_space.seed(3)
    for _ in range(25):
        envs.step(envs.action_space.sample())
    oracle = _mpc(envs.unwrapped.config, 4, "daqp")
    cfg = envs.unwrapped.config
    for data, psi in captured[::4]:
        got = real(data, psi)
        for b in range(data.constant.shape[0]):
            one = type(data)(*(getattr(data, f)[b] for f in ("residual", "linear", "constant", "lower", "upper")))
            want = oracle.solve_prepared(one, psi[b])
            np.testing.assert_allclose(got.value[b], want.value, rtol=1e-9, atol=1e-9 * cfg.control.accel_max_mps2)


def test_per_axis_pencils_reproduce_the_full_hessian():
    """The reduced, per-axis pencils are the 20-variable problem's: W diag(1/(1 + s lambda)) W' is
    the inverse of s P1 + P0 restricted to the axis and the free increments."""
    cfg = ScenarioConfig()
    model = PredictionModel.from_config(cfg)
    p0, p1 = 2 * model.q5, 2 * model.ftq4f
    masks = [command_mask(ph, model.horizon, 2) for ph in range(2)]
    pen = AxisPencils.build(p0, p1, model.horizon, masks)
    for ph in range(2):
        idx = np.flatnonzero(masks[ph])
        nf = idx.size
        for ax in range(2):
            for s in (0.0, 0.3, 1.0):
                full = (s * p1 + p0)[ax::2, ax::2][np.ix_(idx, idx)]
                w = pen.w[ph, ax]  # padded variables are decoupled: the free block of the inverse is the free inverse
                inv = w @ np.diag(1 / (1 + s * pen.lam[ph, ax])) @ w.T
                np.testing.assert_allclose(inv[:nf, :nf], np.linalg.inv(full), rtol=1e-9, atol=1e-12)
                np.testing.assert_allclose(inv[:nf, nf:], 0.0, atol=1e-12)
            # the structure the kernel computes the constraint values from: z_j, then running sums
            a = pen.a[ph, ax]
            np.testing.assert_array_equal(a[:nf, :nf], np.eye(nf))
            np.testing.assert_array_equal(a[10 : 10 + nf, :nf], np.tril(np.ones((nf, nf))))
            np.testing.assert_allclose(pen.g[ph, ax], a @ pen.w[ph, ax], atol=1e-15)


def test_coupled_weights_are_refused_with_a_clear_error():
    model = PredictionModel.from_config(ScenarioConfig())
    p1 = np.array(2 * model.ftq4f)
    p1[0, 1] = p1[1, 0] = 0.1
    with pytest.raises(ValueError, match="x-y blocks of the Hessians are not zero"):
        AxisPencils.build(2 * model.q5, p1, model.horizon, [np.ones(model.horizon, bool)])
    with pytest.raises(ValueError, match=r"p0 \(3, 3\)"):
        AxisPencils.build(np.eye(3), np.eye(3), model.horizon, [np.ones(model.horizon, bool)])


def test_unsettled_problems_fall_back_and_are_counted():
    """An infeasible problem (|u[n-1]| beyond a_max by more than one increment) is not settled by
    the compiled solver: DAQP and OSQP fail too, so it gets the zero sequence (status 2); the
    others are untouched (status 0). A psi stack over one slot's data is one call."""
    cfg, _, x, ref, psi = _slot_stack(6, seed=4)
    mpc = _mpc(cfg, 6, "compiled")
    x[2, 4] = 5.0
    sol = mpc.solve(x, ref, psi)
    assert sol.status.tolist() == [0, 0, 2, 0, 0, 0] and np.all(sol.increments[2] == 0.0)
    data = mpc.prepare(x, ref)
    table = mpc.solve_prepared(data, np.linspace(0, 1, 5)[:, None] * np.ones(6))
    assert table.value.shape == (5, 6) and table.num_fallbacks == 5
    np.testing.assert_allclose(table.value[0], data.constant)  # psi = 0: zero increments, V = r'Q4r


def test_bad_psi_and_non_finite_data_are_refused_or_fall_back():
    """psi outside [0, 1] (or NaN) raises an error naming psi; data that is not finite is never
    returned as a solution (the fallback decides, and counts it)."""
    cfg, _, x, ref, psi = _slot_stack(6, seed=5)
    mpc = _mpc(cfg, 6, "compiled")
    for bad in (np.nan, 1.5, -0.1):
        with pytest.raises(ValueError, match=r"psi=.*must lie in \[0, 1\]"):
            mpc.solve(x, ref, np.array([0.5, bad, 0.5, 0.5, 0.5, 0.5]))
    data = mpc.prepare(x, ref)
    broken = type(data)(data.residual, data.linear.copy(), data.constant, data.lower, data.upper)
    broken.linear[1, 3] = np.inf
    sol = mpc.solve_prepared(broken, np.full(6, 0.5))
    assert sol.status[1] > 0 and not sol.status[[0, 2, 3, 4, 5]].any()


@pytest.mark.parametrize("period", [2, 3])
def test_batched_stacks_with_a_phase_per_scenario_equal_daqp_one_by_one(period):
    """A vector env's stack (N scenarios x K AGVs) where each scenario is at its own slot phase:
    the compiled answers equal DAQP's (which writes the blocked increments as equality rows, one
    problem at a time) increment by increment, and the blocked increments are zero in both."""
    cfg = ScenarioConfig()
    n_env, k = 30, 4
    _, model, x, ref, psi = _slot_stack(n_env * k, seed=10 + period)
    x, ref, psi = x.reshape(n_env, k, 6), ref.reshape(n_env, k, model.horizon + 1, 6), psi.reshape(n_env, k)
    slots = np.random.default_rng(period).integers(0, 50, n_env)
    fast = _mpc(cfg, k, "compiled", period).solve(x, ref, psi, slots)
    for i in range(n_env):
        want = _mpc(cfg, k, "daqp", period).solve(x[i], ref[i], psi[i], int(slots[i]))
        np.testing.assert_allclose(fast.increments[i], want.increments, rtol=0, atol=1e-7)
        blocked = ~command_mask(int(slots[i]) % period, cfg.control.horizon, period)
        assert np.all(fast.increments[i][:, blocked] == 0.0) and np.all(want.increments[:, blocked] == 0.0)
