"""The loss-aware tail (MODEL.md §4, "Planning under loss"): the modified Riccati equation, the
mean-square stability of its gain, the values V^del and V^lost it prices, and ``dv-mpc`` with it."""

import gymnasium as gym
import numpy as np
import pytest
from scipy import linalg, optimize
from test_agents import _snapshots

from agents import make_policy, rollout
from agents.dv_mpc import DeliverySettings
from lawn_env import ScenarioConfig, presets
from lawn_env.dynamics import PredictionModel, augmented_matrices, loss_aware_gain, mean_square_radius, modified_riccati
from lawn_env.errors import ConfigError
from lawn_env.mpc import OutageAwareMPC
from lawn_env.tail import PSI_GRID, LossAwareTail, expected_delivery, first_delivery, tail_model

CFG = ScenarioConfig()
A, B = augmented_matrices(CFG.slot_s)
Q, R = np.eye(6), np.eye(2)
#: The psi grid of the stability claims (MODEL.md §4, docs/experts.md).
STABILITY_GRID = np.round(np.arange(1, 21) * 0.05, 2)


def _fixed_point(psi, iterations=200_000):
    """The modified Riccati equation by plain value iteration from zero (independent of the module's
    start at the DARE's solution)."""
    s = np.zeros((6, 6))
    for _ in range(iterations):
        nxt = A.T @ s @ A + Q - psi * A.T @ s @ B @ np.linalg.inv(R + B.T @ s @ B) @ B.T @ s @ A
        if np.abs(nxt - s).max() <= 1e-13 * np.abs(nxt).max():
            return nxt
        s = nxt
    raise AssertionError("no convergence")


def test_the_modified_riccati_solution_is_the_fixed_point_and_the_dare_at_one():
    assert np.allclose(modified_riccati(A, B, Q, R, 1.0), linalg.solve_discrete_are(A, B, Q, R), rtol=1e-12)
    for psi in (0.9, 0.5, 0.2):
        s = modified_riccati(A, B, Q, R, psi)
        assert np.allclose(s, _fixed_point(psi), rtol=1e-8)
        residual = A.T @ s @ A + Q - psi * A.T @ s @ B @ np.linalg.solve(R + B.T @ s @ B, B.T @ s @ A) - s
        assert np.abs(residual).max() <= 1e-9 * np.abs(s).max()


def test_the_loss_aware_gain_is_mean_square_stable_down_to_five_percent():
    """Every psi on the grid: the second-moment map of the loss-aware closed loop contracts; at psi = 1
    the gain is the DARE's (the LQR's); the certainty-equivalent gain does not contract below psi_c."""
    dare_gain = PredictionModel.from_config(CFG).lqr_gain
    certainty = loss_aware_gain(A, B, R, modified_riccati(A, B, Q, R, 1.0))
    assert np.allclose(certainty, dare_gain, rtol=1e-12)
    for psi in STABILITY_GRID:
        gain = loss_aware_gain(A, B, R, modified_riccati(A, B, Q, R, float(psi)))
        assert mean_square_radius(A, B, gain, float(psi)) < 1.0, psi
    assert mean_square_radius(A, B, certainty, 0.3) > 1.0  # the certainty-equivalent gain diverges there
    assert mean_square_radius(A, B, certainty, 0.9) < 1.0


def test_below_the_critical_probability_there_is_no_solution():
    unstable = 1.2 * A  # eigenvalues 1.2: no solution for psi <= 1 - 1/1.2^2
    with pytest.raises(ValueError, match="does not converge"):
        modified_riccati(unstable, B, Q, R, 0.2)
    with pytest.raises(ValueError, match=r"success=0\.0"):
        modified_riccati(A, B, Q, R, 0.0)


def _brute_force_values(config, z, ref, psi):
    """V^del and V^lost of one AGV under loss by nested numerical minimization of the Bellman equation
    over a short horizon (each later command delivered with probability psi, unbounded; the first
    bounded; the terminal weight the stationary solution): independent of the tail's recursion."""
    n = config.control.horizon
    terminal = modified_riccati(A, B, Q, R, psi)
    ctl = config.control

    def value(x, i):
        e = x - ref[i]
        if i == n:
            return e @ terminal @ e
        held = value(A @ x, i + 1)
        best = optimize.minimize(lambda d: d @ R @ d + value(A @ x + B @ d, i + 1), np.zeros(2), method="BFGS",
                                 options={"gtol": 1e-10})
        return e @ Q @ e + psi * best.fun + (1 - psi) * held

    e0 = z - ref[0]
    u = z[4:6]
    lo = np.maximum(-ctl.accel_increment_max_mps2, -ctl.accel_max_mps2 - u)
    hi = np.minimum(ctl.accel_increment_max_mps2, ctl.accel_max_mps2 - u)
    first = optimize.minimize(lambda d: d @ R @ d + value(A @ z + B @ d, 1), np.zeros(2), method="L-BFGS-B",
                              bounds=list(zip(lo, hi, strict=True)), options={"ftol": 1e-14, "gtol": 1e-10})
    return e0 @ Q @ e0 + first.fun, e0 @ Q @ e0 + value(A @ z, 1), first.x


def test_the_worth_of_a_command_is_the_bellman_equations():
    """Where no later bound is kept (bounds_probability 1), V^lost - V^del and the command are those
    of the expected cost under loss by brute force; the values differ from it by a term that does not
    depend on the command."""
    config = CFG.override({"control.horizon": 2})
    tail = LossAwareTail.from_config(config, bounds_probability=1.0)
    for snap in _snapshots(1, seed=31, config=config):
        for psi in (0.9, 0.4):
            index = int(np.argmin(np.abs(PSI_GRID - psi)))
            solution, lost = tail.delivery_values(snap.x_aug, snap.reference, PSI_GRID[index], snap.slot)
            for k in range(1):
                v_del, v_lost, command = _brute_force_values(config, snap.x_aug[k], snap.reference[k],
                                                             float(PSI_GRID[index]))
                worth = lost[k] - solution.value[k]
                assert worth == pytest.approx(v_lost - v_del, rel=1e-5, abs=1e-7)
                assert np.allclose(solution.increments[k, 0], command, atol=1e-5)


def test_the_tail_qp_matches_cvxpy_with_its_weights():
    """The QP the tail solves (stage weights Q~, terminal P_N, linear terms h, the kept bounds) against
    cvxpy's solve of the same problem written out: V^del, V^lost and the first increment."""
    cp = pytest.importorskip("cvxpy")
    tail = LossAwareTail.from_config(CFG)
    ctl = CFG.control
    for snap in _snapshots(2, seed=32):
        for psi in (1.0, 0.6):
            solution, lost = tail.delivery_values(snap.x_aug, snap.reference, psi, snap.slot)
            index = int(tail.model.grid_index(psi))
            model, _ = tail.model.qp(index, 0)
            maps = tail.model.maps(index, 0)
            released = tail._released(index, 0, tail.model.stages(index, 0))
            n = ctl.horizon
            kept = np.ones(n, dtype=bool) if released is None else ~released[2 * n::2]
            for k in range(4):
                z0, ref = snap.x_aug[k], snap.reference[k].reshape(-1)
                values = []
                for hold in (False, True):
                    d = cp.Variable(2 * n)
                    x = model.c @ z0 + model.f @ d
                    cost = cp.quad_form(x, model.q4) - 2 * (ref @ maps.rf) @ d + cp.quad_form(d, model.q5)
                    u = np.tile(z0[4:6], n) + model.increment_sum @ d
                    cons = [cp.abs(d[:2]) <= ctl.accel_increment_max_mps2, cp.abs(u[:2]) <= ctl.accel_max_mps2]
                    for i in range(1, n):
                        if kept[i]:
                            cons += [cp.abs(d[2 * i:2 * i + 2]) <= ctl.accel_increment_max_mps2,
                                     cp.abs(u[2 * i:2 * i + 2]) <= ctl.accel_max_mps2]
                    if hold:
                        cons.append(d[:2] == 0)
                    problem = cp.Problem(cp.Minimize(cost), cons)
                    problem.solve(solver=cp.CLARABEL, tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
                    values.append(problem.value)
                    if not hold:
                        assert np.allclose(solution.increments[k, 0], d.value[:2], atol=1e-6)
                assert lost[k] - solution.value[k] == pytest.approx(values[1] - values[0], rel=1e-6, abs=1e-7)


def test_at_full_delivery_the_tail_is_the_certainty_equivalent_mpc():
    tail = LossAwareTail.from_config(CFG)
    mpc = OutageAwareMPC.from_config(CFG)
    for snap in _snapshots(3, seed=33):
        delivered, lost = mpc.delivery_values(mpc.prepare(snap.x_aug, snap.reference, snap.slot))
        solution, tail_lost = tail.delivery_values(snap.x_aug, snap.reference, 1.0, snap.slot)
        assert np.allclose(solution.value, delivered.value, rtol=1e-9, atol=1e-9)
        assert np.allclose(tail_lost, lost, rtol=1e-9, atol=1e-9)
        assert np.allclose(solution.increments, delivered.increments, atol=1e-8)


def test_with_a_period_and_a_lag_the_tail_holds_between_commands():
    config = presets.get("disturbed")
    tail = LossAwareTail.from_config(config, lag=True)
    assert tail.state_dim == 8 and tail.model.period == 2
    for snap in _snapshots(2, seed=34, config=config):
        state = np.concatenate([snap.x_aug, snap.x_aug[:, 4:6]], axis=1)
        for slot in (snap.slot, snap.slot + 1):
            solution, lost = tail.delivery_values(state, snap.reference, 0.5, slot)
            held = (slot + np.arange(tail.model.horizon)) % 2 != 0
            assert np.all(solution.increments[:, held] == 0.0)
            assert np.all(lost >= solution.value - 1e-9)


def test_the_expected_delivery_is_the_worth_weighted_success():
    psi = np.array([[0.2, 0.8, 0.5], [0.1, 0.1, 0.1]])
    worth = np.array([[1.0, 3.0, 0.0], [0.0, 0.0, 0.0]])
    nxt = expected_delivery(np.array([1.0, 0.4]), psi, worth, 0.5)
    assert nxt[0] == pytest.approx(0.5 + 0.5 * (0.2 + 2.4) / 4.0)
    assert nxt[1] == pytest.approx(0.4)  # no worth: psi-bar stays
    steps = []
    assert first_delivery(lambda p: (steps.append(p), (np.full(3, 0.3), np.ones(3)))[1], 3) == pytest.approx(0.3)
    assert steps == [1.0, pytest.approx(0.3), pytest.approx(0.3)]
    # one psi-bar per scenario (the AGVs' law of a batch): each row its own fixed point
    decided = np.array([[0.2, 0.6], [0.9, 0.9]])
    start = first_delivery(lambda p: (decided, np.array([[1.0, 1.0], [2.0, 0.0]])), 2, (2,))
    assert start.shape == (2,) and np.allclose(start, [0.4, 0.9])


def test_a_fleet_that_loses_most_commands_stays_on_its_paths():
    """K = 32 on the default budget loses about 80 % of the commands: the certainty-equivalent tail's
    AGVs run away (RMSE tens of metres on this seed), the loss-aware tail's stay within a few metres."""
    config = CFG.override({"num_agvs": 32})
    env = gym.make("lawn/Joint-v1", config=config)
    metrics = {}
    for tail in ("loss-aware", "certainty-equivalent"):
        episode = rollout(env, make_policy("dv-mpc", config, tail=tail), 700)
        metrics[tail] = episode.metrics
    assert metrics["loss-aware"]["outage_rate"] > 0.7
    assert metrics["loss-aware"]["rmse_m"] < 5.0
    assert metrics["certainty-equivalent"]["rmse_m"] > 20.0


def test_the_tail_models_are_shared_and_read_only():
    a = LossAwareTail.from_config(CFG)
    b = LossAwareTail.from_config(CFG.override({"num_agvs": 3}))
    assert a.model is b.model is tail_model(CFG.slot_s, 10, tuple(CFG.control.q1_diag), tuple(CFG.control.q2_diag), 1,
                                           -1.0)
    stages = a.model.stages(50, 0)
    with pytest.raises(ValueError):
        stages.quad[0, 0, 0] = 1.0


def test_bad_tail_settings_name_them():
    with pytest.raises(ConfigError, match=r"tail.*'optimistic'.*loss-aware.*certainty-equivalent"):
        DeliverySettings(tail="optimistic")
    with pytest.raises(ConfigError, match="bounds_probability"):
        DeliverySettings(bounds_probability=0.0)
    with pytest.raises(ConfigError, match="delivery_memory"):
        DeliverySettings(delivery_memory=1.0)
    with pytest.raises(ConfigError, match=r"delivery_weights.*'fleet'.*worth.*uniform"):
        DeliverySettings(delivery_weights="fleet")
    with pytest.raises(ConfigError, match="delivery_start_iterations"):
        DeliverySettings(delivery_start_iterations=-1)
    with pytest.raises(ValueError, match=r"terminal_success.*tail='certainty-equivalent'"):
        make_policy("dv-mpc", CFG, terminal_success=0.5)
    make_policy("dv-mpc", CFG, terminal_success=0.5, tail="certainty-equivalent")
    with pytest.raises(ValueError, match=r"bounds_probability=1\.5"):
        LossAwareTail.from_config(CFG, bounds_probability=1.5)
    tail = LossAwareTail.from_config(CFG)
    with pytest.raises(ValueError, match=r"state has shape \(3, 6\)"):
        tail.delivery_values(np.zeros((3, 6)), np.zeros((3, 11, 6)), 0.5)


# ---------------------------------------------------------------------- the AGVs' delivery law
def test_the_comm_agvs_delivery_law_holds_where_links_fail():
    """``control.law="delivery"`` is the loss-aware tail's command at the fleet's psi-bar: at K = 32 the
    AGVs of lawn/Comm-v1 stay near their paths under dv-mpc; under the certainty-equivalent law they
    run away (the same drone decisions' planner, its tail matching each law)."""
    config = CFG.override({"num_agvs": 32, "num_slots": 60})
    rmse = {}
    for law in ("delivery", "delivery-certainty-equivalent"):
        law_config = config.override({"control.law": law})
        env = gym.make("lawn/Comm-v1", config=law_config)
        rmse[law] = rollout(env, make_policy("dv-mpc", law_config, env_id="lawn/Comm-v1"), 700).metrics["rmse_m"]
    assert rmse["delivery"] < 5.0 < 4 * rmse["delivery"] < rmse["delivery-certainty-equivalent"]


def test_dv_mpc_on_comm_plans_with_the_tail_of_the_agvs_law():
    delivery = CFG.override({"control.law": "delivery"})
    assert make_policy("dv-mpc", delivery, env_id="lawn/Comm-v1").solver.tail is not None
    ce = make_policy("dv-mpc", CFG.override({"control.law": "delivery-certainty-equivalent"}), env_id="lawn/Comm-v1")
    assert ce.solver.tail is None
    with pytest.raises(ValueError, match=r"tail='certainty-equivalent'.*control.law='delivery'"):
        make_policy("dv-mpc", delivery, env_id="lawn/Comm-v1", tail="certainty-equivalent")
    with pytest.raises(ValueError, match="dv-mpc-ce is dv-mpc with tail='certainty-equivalent'"):
        make_policy("dv-mpc-ce", CFG, tail="loss-aware")
    assert make_policy("dv-mpc-ce", CFG).solver.tail is None


def test_the_delivery_law_of_a_vector_env_is_each_scenarios_own():
    """Env i of the Comm vector env under the delivery law equals the single env reset with s + i, bit
    for bit: psi-bar is per scenario and every solve starts cold."""
    from test_vector import _lockstep

    config = ScenarioConfig(num_slots=25).override({"control.law": "delivery"})
    rng = np.random.default_rng(1)
    _lockstep("lawn/Comm-v1", config, rng.uniform(-1, 1, (25, 4, config.num_agvs + 2)).astype(np.float32), 10)


def test_the_anchored_joint_increments_follow_the_delivery_law():
    """Under control.law="delivery" the RL interface's MPC anchor plans as the Comm AGVs do: the zero
    action of lawn/JointRL-v1 with increment_anchor="mpc" decodes to the delivery law's command at the
    anchored powers."""
    from lawn_env.channel import LinkParams
    from lawn_env.interface import action_codec
    from lawn_env.tail import DeliveryLaw

    config = CFG.override({"control.law": "delivery"})
    env = gym.make("lawn/JointRL-v1", config=config, interface={"base": "rl", "increment_anchor": "mpc"}).unwrapped
    env.reset(seed=3)
    law, link = DeliveryLaw(config), LinkParams.from_config(config, planning=True)
    codec = action_codec(config, "joint", env.interface)  # the env's own, a copy: decoding advances psi-bar
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    for _ in range(3):
        snap = env.snapshot()
        decision = codec.decode(zero, snap.x_aug, snap.reference, snap.drone_position, snap.slot)
        psi = link.success_sq(decision.power_w, link.distance_sq(decision.drone_next, snap.x_aug[:, :2]))
        expected = law.solve(snap.x_aug, snap.reference, psi, snap.slot).increments[:, 0]
        assert np.allclose(decision.increment, expected, atol=1e-12)
        env.step(zero)


def test_the_episode_metrics_flag_a_diverged_episode():
    """``max_tracking_error_m`` is the largest position error of any AGV after any slot (the simulator's
    state against its reference), and ``diverged`` flags it past 25 m: equal power at K = 32 runs AGVs
    off their paths, dv-mpc keeps them within a few metres on the same seed."""
    from lawn_env.core import DIVERGENCE_DISTANCE_M

    config = CFG.override({"num_agvs": 32, "num_slots": 60})
    for name, diverged in (("epa", 1), ("dv-mpc", 0)):
        env = gym.make("lawn/Joint-v1", config=config).unwrapped
        largest = []

        def on_step(step, env=env, largest=largest):
            sim = env.sim  # one scenario's view: (K, ...) arrays, the slot after the step
            ref = sim.reference[:, int(sim.slot), :2]
            largest.append(np.linalg.norm(sim.x_aug[:, :2] - ref, axis=1).max())

        metrics = rollout(env, make_policy(name, config), 700, on_step=on_step).metrics
        assert metrics["max_tracking_error_m"] == pytest.approx(max(largest), rel=1e-9)
        assert metrics["diverged"] == diverged == int(max(largest) > DIVERGENCE_DISTANCE_M)
