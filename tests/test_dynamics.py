import numpy as np
import pytest
from scipy import linalg

from lawn_env import ScenarioConfig, dynamics
from lawn_env.dynamics import PredictionModel


def _paper_matrices(dt):
    """A~, B~ typed in from the paper, independently of the module."""
    a = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)
    b = np.array([[dt**2 / 2, 0], [0, dt**2 / 2], [dt, 0], [0, dt]])
    a_aug = np.zeros((6, 6))
    a_aug[:4, :4] = a
    a_aug[:4, 4:] = b
    a_aug[4:, 4:] = np.eye(2)
    b_aug = np.vstack([b, np.eye(2)])
    return a_aug, b_aug


@pytest.mark.parametrize("dt", [0.5, 0.1])
def test_augmented_matrices_match_paper(dt):
    a_aug, b_aug = dynamics.augmented_matrices(dt)
    pa, pb = _paper_matrices(dt)
    assert np.array_equal(a_aug, pa) and np.array_equal(b_aug, pb)


@pytest.mark.parametrize("q1, q2", [((1,) * 6, (1, 1)), ((2, 2, 0.5, 0.5, 0.1, 0.1), (0.3, 3.0))])
def test_dare_solution_against_scipy(q1, q2):
    cfg = ScenarioConfig(control=dict(q1_diag=q1, q2_diag=q2))
    model = PredictionModel.from_config(cfg)
    pa, pb = _paper_matrices(cfg.slot_s)
    ref = linalg.solve_discrete_are(pa, pb, np.diag(q1), np.diag(q2))
    assert np.allclose(model.q3, ref, rtol=1e-10, atol=1e-10)
    # and it satisfies the paper's Riccati equation for Q3
    q3 = model.q3
    rhs = (np.diag(q1) + pa.T @ q3 @ pa
           - pa.T @ q3 @ pb @ np.linalg.solve(np.diag(q2) + pb.T @ q3 @ pb, pb.T @ q3 @ pa))
    assert np.allclose(q3, rhs, rtol=1e-9, atol=1e-9)
    # stabilizing: closed loop with the LQR gain has spectral radius < 1
    gain = np.linalg.solve(np.diag(q2) + pb.T @ q3 @ pb, pb.T @ q3 @ pa)
    assert np.max(np.abs(np.linalg.eigvals(pa - pb @ gain))) < 1


@pytest.mark.parametrize("psi", [1.0, 0.7, 0.0])
def test_condensed_prediction_equals_rollout(psi, rng):
    cfg = ScenarioConfig()
    model = PredictionModel.from_config(cfg)
    pa, pb = _paper_matrices(cfg.slot_s)
    k, n = 3, cfg.control.horizon
    x0 = rng.normal(size=(k, 6))
    dmu = rng.normal(size=(k, n, 2))
    chi = model.predict(x0, dmu, psi)
    for j in range(k):
        x = x0[j]
        assert np.allclose(chi[j, 0], x)
        for i in range(n):
            x = pa @ x + psi * pb @ dmu[j, i]  # expected dynamics (paper eq. evolution_cs)
            assert np.allclose(chi[j, i + 1], x)
    assert model.c.shape == (6 * (n + 1), 6) and model.f.shape == (6 * (n + 1), 2 * n)


def test_step_augmented_matches_paper_dynamics(rng):
    pa, pb = _paper_matrices(0.5)
    x = rng.normal(size=(4, 6))
    du = rng.normal(size=(4, 2))
    out = dynamics.step_augmented(x, du, *dynamics.augmented_matrices(0.5))
    assert np.allclose(out, x @ pa.T + du @ pb.T)
    # the augmented state carries u[n] = u[n-1] + du
    assert np.allclose(out[:, 4:6], x[:, 4:6] + du)


def test_expected_cost_coefficients(rng):
    cfg = ScenarioConfig()
    model = PredictionModel.from_config(cfg)
    k, n = 4, cfg.control.horizon
    x0 = rng.normal(size=(k, 6))
    ref = rng.normal(size=(k, n + 1, 6))
    dmu = rng.normal(size=(k, n, 2))
    r = model.residual(x0, ref)  # the MPC's prepared slot data (OutageAwareMPC.prepare) from these
    lcoef, scoef, wcoef = dynamics.cost_coefficients(model, r @ model.ftq4.T, model.cost_to_go(r), dmu)
    q4 = linalg.block_diag(*([np.eye(6)] * n + [model.q3]))
    for psi in (0.2, 0.9):
        chi = model.predict(x0, dmu, psi)
        e = (chi - ref).reshape(k, -1)
        direct = np.einsum("ki,ij,kj->k", e, q4, e) + (dmu.reshape(k, -1) ** 2).sum(1)
        assert np.allclose(lcoef * psi**2 + 2 * scoef * psi + wcoef, direct)


def test_increment_sum_matrix():
    t = dynamics.increment_sum_matrix(3)
    dmu = np.array([1.0, -1.0, 0.5, 0.5, 0.25, 2.0])
    assert np.allclose(t @ dmu, [1.0, -1.0, 1.5, -0.5, 1.75, 1.5])


def test_packed_step_equals_step_and_stage_cost(rng):
    a_aug, b_aug = dynamics.augmented_matrices(0.5)
    q1, q2 = rng.uniform(0.1, 2, 6), rng.uniform(0.1, 2, 2)
    t, w = dynamics.packed_step_matrices(a_aug, b_aug, q1, q2)
    x, du, ref = rng.normal(size=(5, 6)), rng.normal(size=(5, 2)), rng.normal(size=(5, 6))
    packed = np.concatenate([x, du], axis=1) @ t
    x_next = dynamics.step_augmented(x, du, a_aug, b_aug)
    assert np.allclose(packed[:, :6], x_next) and np.allclose(packed[:, 6:], du)
    err = packed - np.concatenate([ref, np.zeros((5, 2))], axis=1)
    terms = (err * err) @ w
    e = x_next - ref  # e' Q1 e and du' Q2 du written out
    assert np.allclose(terms[:, 0], np.einsum("ki,i,ki->k", e, q1, e))
    assert np.allclose(terms[:, 1], np.einsum("ki,i,ki->k", du, q2, du))


def test_the_disturbed_slot_is_the_nominal_transition_plus_the_lag_and_noise():
    """The disturbance mode runs through the simulator's one step path: checked here
    against the double integrator written out with the lagged acceleration, for the true state."""
    from lawn_env import DisturbanceConfig
    from lawn_env.core import Decisions, Simulation

    cfg = ScenarioConfig(num_slots=20, disturbance=DisturbanceConfig(actuator_lag_s=0.3, wind_mps=(1.0, -2.0)))
    sim = Simulation(cfg)
    view = sim.row(0)
    draws = np.random.default_rng(4)
    sim.reset([draws])
    alpha, dt = np.exp(-cfg.slot_s / 0.3), cfg.slot_s
    applied = view.x_aug[:, 4:6].copy()
    rng = np.random.default_rng(9)
    for _ in range(cfg.num_slots):
        x, q = view.x_aug.copy(), view.drone_position.copy()
        decisions = Decisions(rng.uniform(-1, 1, (1, cfg.num_agvs, 2)), np.full((1, cfg.num_agvs), 0.25),
                              view.drone_target(np.zeros(2))[None])
        record = sim.step(decisions, sim.draw(draws))
        commanded = x[:, 4:6] + record.applied_increment[0]
        applied = alpha * applied + (1 - alpha) * commanded
        expected = np.hstack([x[:, 0:2] + x[:, 2:4] * dt + 0.5 * applied * dt * dt, x[:, 2:4] + applied * dt, commanded])
        np.testing.assert_allclose(view.x_aug, expected, rtol=1e-12, atol=1e-12)
        err = expected - view.reference[:, view.slot]
        du = record.applied_increment[0]
        np.testing.assert_allclose(record.tracking_cost[0], (err * err).sum(axis=1), rtol=1e-12)  # Q1 = Q2 = I
        np.testing.assert_allclose(record.effort_cost[0], (du * du).sum(axis=1), rtol=1e-12)
    assert np.allclose(record.drone_position[0], np.clip(q + np.array([1.0, -2.0]) * dt, 0, 200))  # the wind moved the hovering drone


def test_the_step_takes_decisions_of_any_real_dtype():
    """``Simulation.step`` converts the decisions to the kernel's float64: float32 or integer arrays
    give the slot that their float64 values give (they raised numba's no-matching-definition error)."""
    from lawn_env.core import Decisions, Simulation

    cfg = ScenarioConfig(num_slots=5)
    records = []
    for cast in (np.float64, np.float32, np.int64):
        sim = Simulation(cfg)
        sim.reset([np.random.default_rng(3)])
        view, draws = sim.row(0), np.random.default_rng(5)
        decisions = Decisions(np.ones((1, cfg.num_agvs, 2), cast), np.full((1, cfg.num_agvs), 0.25).astype(cast)
                              if cast is not np.int64 else np.zeros((1, cfg.num_agvs), cast),
                              np.round(view.drone_target(np.zeros(2)))[None].astype(cast))
        records.append(sim.step(decisions, sim.draw(draws)))
    assert np.array_equal(records[0].terms, records[1].terms)  # 1.0, 0.25 and whole metres are exact in float32
    # integer zero power: every link in outage, no command arrives, the increments applied are zero
    assert (records[2].outage_probability == 1.0).all() and not records[2].delivered.any()
    assert not records[2].applied_increment.any() and records[2].power_w.dtype == np.float64


def test_a_slot_without_a_command_transmits_nothing():
    """With commands every second slot, the powers decided for a slot without a command have no
    effect: the control cost, the outage metrics and the radiated power do not depend on them
    (outage rates count the commands sent; the mean power counts 0 W on a slot that sends none)."""
    from lawn_env import DisturbanceConfig
    from lawn_env.core import Decisions, Simulation

    cfg = ScenarioConfig(num_slots=21, disturbance=DisturbanceConfig(control_period_slots=2))
    metrics = []
    for hold_power in (0.25, 1e-9):
        sim = Simulation(cfg)
        view = sim.row(0)
        draws = np.random.default_rng(4)
        sim.reset([draws])
        rng = np.random.default_rng(9)
        for n in range(cfg.num_slots):
            power = np.full((1, cfg.num_agvs), 0.25 if n % 2 == 0 else hold_power)
            decisions = Decisions(rng.uniform(-1, 1, (1, cfg.num_agvs, 2)), power, view.drone_target(np.zeros(2))[None])
            sim.step(decisions, sim.draw(draws))
        metrics.append(sim.episode_metrics()[0].as_dict())
    low, high = metrics
    assert low == high  # every metric, the outage rates and the mean power included
    assert high["mean_power_w"] == pytest.approx([0.25 * 11 / 21] * cfg.num_agvs)  # 11 command slots of 21, 0 W between
    assert 0 < high["outage_rate"] < 1
