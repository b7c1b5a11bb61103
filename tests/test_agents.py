import math

import gymnasium as gym
import numpy as np
import pytest

from agents import PAPER_POLICIES, AOSettings, AOSolver, expected_cost, make_policy, policy_names
from agents.optim import linear_argmin_disc_box, project_budget
from agents.policies import snapshot_from_observation
from agents.problem import SlotProblem
from lawn_env import ScenarioConfig
from lawn_env.core import Snapshot
from lawn_env.mpc import OutageAwareMPC

CFG = ScenarioConfig()


def _slot_problem(solver, snap):
    return SlotProblem(solver.mpc, solver.link, snap, solver.config)


def _snapshots(count, seed=0, config=CFG):
    """Snapshots along random-action episodes, with extra random offsets and accelerations."""
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    env.action_space.seed(seed)
    rng = np.random.default_rng(seed)
    out = []
    env.reset(seed=seed)
    while len(out) < count:
        for _ in range(int(rng.integers(1, 6))):
            a = env.action_space.sample() * 0.3
            _, _, _, done, _ = env.step(a)
            if done:
                env.reset(seed=int(rng.integers(1000)))
        snap = env.snapshot()
        x = snap.x_aug.copy()
        x[:, 0:2] += rng.normal(0, 2, (config.num_agvs, 2))
        x[:, 4:6] = np.clip(x[:, 4:6] + rng.normal(0, 0.5, (config.num_agvs, 2)), -2, 2)
        q = np.clip(snap.drone_position + rng.normal(0, 40, 2), 0, 200)
        out.append(Snapshot(x, snap.reference, q, snap.slot, config, snap.last_power_w))
    return out


def _flat_trace(plan):
    t = plan.objective_trace.ravel()
    return t[~np.isnan(t)]


def test_objective_trace_is_non_increasing():
    solver = AOSolver(CFG, AOSettings(max_iterations=15, tolerance=0.0))
    for snap in _snapshots(40, seed=1):
        plan = solver.solve(snap)
        trace = _flat_trace(plan)
        assert np.all(np.diff(trace) <= 1e-12 * abs(trace[0])), trace
        # the final control block at the returned (p, q) can only lower J^ further
        assert plan.info["objective_before_final_qp"] == trace[-1]
        assert plan.objective <= trace[-1] * (1 + 1e-12)
        assert plan.objective_trace.shape == (plan.iterations, 3)


def test_expected_cost_equals_the_reported_cost():
    for name in ("rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr"):
        policy = make_policy(name, CFG, seed=3)
        policy.reset(3)
        for snap in _snapshots(5, seed=2):
            plan = policy.plan(snap)
            value = expected_cost(snap, plan.increments, plan.power_w, plan.drone_position)
            assert value == pytest.approx(plan.objective, rel=1e-10), name


def test_control_block_matches_an_independent_qp_solve():
    solver = AOSolver(CFG)
    reference = OutageAwareMPC.from_config(CFG, backend="osqp")
    for snap in _snapshots(6, seed=4):
        prob = _slot_problem(solver, snap)
        p = np.array([0.1, 0.2, 0.3, 0.4])
        q = snap.drone_position
        dmu, value, _ = solver.control_block(prob, p, q, None, math.inf)
        psi = prob.success(p, q)
        independent = reference.solve(snap.x_aug, snap.reference, psi)
        assert value == pytest.approx(independent.value.sum(), rel=1e-6)
        assert np.allclose(dmu, independent.increments, atol=1e-5)


def test_power_gradient_matches_finite_differences(rng):
    solver = AOSolver(CFG)
    for snap in _snapshots(5, seed=5):
        prob = _slot_problem(solver, snap)
        dmu, _, _ = solver.control_block(prob, solver.equal_power(), snap.drone_position, None, math.inf)
        obj = solver.power_objective(prob.coefficients(dmu), prob.distance_sq(snap.drone_position))
        p = rng.uniform(0.05, 0.4, 4)
        value, state = obj.value(p)
        grad = obj.gradient(state)
        for k in range(4):
            h = 1e-7 * max(1.0, p[k])
            e = np.zeros(4)
            e[k] = h
            fd = (obj.value(p + e)[0] - obj.value(p - e)[0]) / (2 * h)
            assert grad[k] == pytest.approx(fd, rel=1e-5, abs=1e-6 * abs(value))
        assert value == pytest.approx(expected_cost(snap, dmu, p, snap.drone_position), rel=1e-12)


def test_drone_gradient_matches_finite_differences():
    solver = AOSolver(CFG)
    for snap in _snapshots(5, seed=6):
        prob = _slot_problem(solver, snap)
        p = solver.equal_power()
        dmu, _, _ = solver.control_block(prob, p, snap.drone_position, None, math.inf)
        obj = solver.drone_objective(prob, prob.coefficients(dmu), p)
        q = snap.drone_position
        grad = obj.gradient(q)
        for axis in range(2):
            e = np.zeros(2)
            e[axis] = 1e-4
            fd = (obj.value(q + e) - obj.value(q - e)) / 2e-4
            assert grad[axis] == pytest.approx(fd, rel=1e-5, abs=1e-8 * abs(obj.value(q)))


@pytest.mark.parametrize("name", ("rg-mpc", *PAPER_POLICIES))
def test_plans_satisfy_every_constraint(name):
    policy = make_policy(name, CFG, seed=0)
    policy.reset(0)
    step = CFG.drone.max_speed_mps * CFG.slot_s
    for snap in _snapshots(12, seed=7):
        plan = policy.plan(snap)
        dmu = plan.increments
        assert dmu.shape == (4, CFG.control.horizon, 2)
        assert np.all(np.abs(dmu) <= CFG.control.accel_increment_max_mps2 + 1e-9)
        u = snap.x_aug[:, None, 4:6] + np.cumsum(dmu, axis=1)
        assert np.all(np.abs(u) <= CFG.control.accel_max_mps2 + 1e-9)
        assert np.all(plan.power_w >= 0) and plan.power_w.sum() <= CFG.power_budget_w * (1 + 1e-12)
        assert np.linalg.norm(plan.drone_position - snap.drone_position) <= step + 1e-9
        assert np.all((plan.drone_position >= 0) & (plan.drone_position <= 200))
        assert plan.info["qp_fallbacks"] == 0


FAST_POLICIES = [n for n in policy_names() if n != "global-mpc"]


@pytest.mark.parametrize("name", FAST_POLICIES)
def test_every_policy_runs_a_full_episode(name):
    env = gym.make("lawn/Joint-v1")
    policy = make_policy(name, env.unwrapped.config, seed=1)
    obs, _ = env.reset(seed=1)
    policy.reset(1)
    done, steps = False, 0
    while not done:
        action = policy.act(obs)
        assert env.action_space.contains(action)
        obs, _, _, done, info = env.step(action)
        steps += 1
    assert steps == 120 and np.isfinite(info["episode_metrics"]["control_cost"])


@pytest.mark.parametrize("name", ["rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr"])
def test_comm_variant_runs(name):
    env = gym.make("lawn/Comm-v1", num_slots=15)
    policy = make_policy(name, env.unwrapped.config, env_id="lawn/Comm-v1")
    obs, _ = env.reset(seed=0)
    policy.reset(0)
    done = False
    while not done:
        action = policy.act(obs)
        assert action.shape == (6,) and env.action_space.contains(action)
        obs, _, _, done, info = env.step(action)
    assert info["mpc_fallbacks"] == 0


def test_act_from_observation_equals_plan_from_snapshot():
    env = gym.make("lawn/Joint-v1").unwrapped
    obs, _ = env.reset(seed=2)
    env.action_space.seed(2)
    for _ in range(5):
        obs, *_ = env.step(env.action_space.sample() * 0.2)
    policy = make_policy("ao-mpc", env.config)
    decoded = snapshot_from_observation(policy.layout, env.config, obs)
    exact = env.snapshot()
    assert np.allclose(decoded.x_aug, exact.x_aug, atol=1e-4)
    a_obs = policy.act(obs)
    plan = AOSolver(env.config).solve(exact)
    assert np.allclose(policy.last_plan.power_w, plan.power_w, atol=1e-3)
    assert np.allclose(a_obs[:8], np.clip(plan.increments[:, 0].ravel(), -1, 1), atol=1e-3)


def test_sb3_evaluate_policy_accepts_our_policies():
    sb3 = pytest.importorskip("stable_baselines3.common.evaluation")
    env = gym.make("lawn/Joint-v1", num_slots=10)
    policy = make_policy("epa", env.unwrapped.config)
    mean, std = sb3.evaluate_policy(policy, env, n_eval_episodes=2, deterministic=True)
    assert np.isfinite(mean) and mean < 0


def test_sf_speed_is_seeded():
    a, b = make_policy("sf", CFG), make_policy("sf", CFG)
    a.reset(5)
    b.reset(5)
    assert a.speed_mps == b.speed_mps and 0 < a.speed_mps <= CFG.drone.max_speed_mps
    b.reset(6)
    assert a.speed_mps != b.speed_mps


def test_infeasible_state_falls_back_without_crashing():
    snap = _snapshots(1, seed=8)[0]
    x = snap.x_aug.copy()
    x[0, 4] = 4.0  # |u[n-1]| beyond a_max by more than one increment: QP of AGV 0 infeasible
    bad = Snapshot(x, snap.reference, snap.drone_position, snap.slot, CFG, snap.last_power_w)
    plan = AOSolver(CFG).solve(bad)
    assert plan.info["qp_fallbacks"] > 0 and np.isfinite(plan.objective)


def test_registry_errors():
    with pytest.raises(ValueError, match="valid policies: dv-mpc, dv-mpc-ce, rg-mpc, ao-mpc, epa, sf, pid, lqr, heuristic, global-mpc"):
        make_policy("mpc-ao", CFG)
    with pytest.raises(ValueError, match="tolerance"):
        make_policy("ao-mpc", CFG, tolerance=-1.0)
    with pytest.raises(ValueError, match="bogus"):
        make_policy("epa", CFG, bogus=1)
    with pytest.raises(ValueError, match="drives lawn/Joint-v1"):
        make_policy("heuristic", CFG, env_id="lawn/Comm-v1")
    with pytest.raises(ValueError, match="env_id"):
        make_policy("ao-mpc", CFG, env_id="CartPole-v1")
    with pytest.raises(ValueError, match="kp"):
        make_policy("pid", CFG, gains={"kp": float("nan")})
    with pytest.raises(ValueError, match="accel_increments has shape"):
        snap = _snapshots(1)[0]
        expected_cost(snap, np.zeros((4, 3, 2)), np.ones(4) / 4, snap.drone_position)


def test_tracking_laws_converge_on_a_straight_reference():
    """With every command delivered, PID and LQR bring a 3 m offset down on a straight line."""
    from agents.policies import PIDGains
    from agents.tracking import lqr_gain, lqr_rollout, pid_rollout
    from lawn_env.dynamics import PredictionModel, step_augmented

    model = PredictionModel.from_config(CFG)
    gains = PIDGains(kp=0.3, ki=0.02, kd=0.6, integral_limit=10.0)
    t = np.arange(200) * CFG.slot_s
    ref = np.zeros((1, 200, 6))
    ref[0, :, 0] = 10 + 3.0 * t
    ref[0, :, 1] = 50
    ref[0, :, 2] = 3.0
    for law in ("pid", "lqr"):
        x = ref[:, 0].copy()
        x[:, 1] += 3.0
        integral = np.zeros((1, 2))
        for n in range(150):
            window = ref[:, n : n + 11]
            if law == "pid":
                du, integral = pid_rollout(x, window, integral, model, gains, 2.0, 1.0)
            else:
                du = lqr_rollout(x, window, model, lqr_gain(model), 2.0, 1.0)
            x = step_augmented(x, du[:, 0], model.a_aug, model.b_aug)
        assert np.abs(x[0, 0:2] - ref[0, 150, 0:2]).max() < 0.05, law


def test_project_budget_is_the_euclidean_projection(rng):
    """KKT of min ||p - v||^2 s.t. p >= 0, sum p <= T: p = max(v - theta, 0) with theta >= 0 and
    theta > 0 only on the face sum p = T; and no worse than an interior-point solve."""
    cp = pytest.importorskip("cvxpy")
    for k in (1, 3, 8, 32):
        for _ in range(20):
            v = rng.normal(0.2, 0.6, k)
            total = rng.uniform(0.1, 2.0)
            p = project_budget(v, total)
            assert np.all(p >= 0) and p.sum() <= total * (1 + 1e-12)
            pos = p > 0
            theta = (v - p)[pos]
            if pos.any():  # one threshold for every positive entry
                assert np.allclose(theta, theta[0], atol=1e-12)
            else:  # all zero: only when no entry is positive (else the budget buys some of it)
                assert v.max() <= 1e-12
            theta = theta[0] if pos.any() else max(v.max(), 0.0)
            assert theta >= -1e-12
            assert np.allclose(p, np.maximum(v - theta, 0), atol=1e-12)
            if theta > 1e-12:
                assert p.sum() == pytest.approx(total, rel=1e-12)
            x = cp.Variable(k)
            cp.Problem(cp.Minimize(cp.sum_squares(x - v)), [x >= 0, cp.sum(x) <= total]).solve(solver=cp.CLARABEL)
            assert np.sum((p - v) ** 2) <= np.sum((x.value - v) ** 2) + 1e-9


def test_linear_argmin_disc_box_beats_a_dense_sample(rng):
    area = (0.0, 200.0, 0.0, 200.0)
    for _ in range(200):
        # half of the centers near an edge or a corner, where the box cuts the disc
        center = rng.uniform(0, 200, 2) if rng.random() < 0.5 else rng.choice([0.0, 200.0], 2) + rng.uniform(-5, 5, 2)
        center = np.clip(center, 0, 200)
        g = rng.normal(size=2)
        radius = 7.5
        q = linear_argmin_disc_box(g, center, radius, area)
        assert np.linalg.norm(q - center) <= radius + 1e-9 and np.all((q >= -1e-9) & (q <= 200 + 1e-9))
        ang = np.linspace(0, 2 * np.pi, 721)
        rad = np.linspace(0, radius, 40)
        pts = center + (rad[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], -1)[None]).reshape(-1, 2)
        pts = pts[(pts >= 0).all(1) & (pts <= 200).all(1)]
        assert g @ q <= (pts @ g).min() + 1e-9


@pytest.mark.parametrize("name", ["ao-mpc", "rg-mpc", "epa", "sf"])
def test_returned_increments_are_the_exact_qp_optimum_at_the_returned_point(name, independent_qp):
    """Every planner that fixes control by the QP returns the QP's optimum at its own returned
    (p, q): checked per AGV against an independent solver (MODEL.md §4).
    Snapshots come from an episode the policy drives itself (seed 5, default scenario)."""
    env = gym.make("lawn/Joint-v1", config=CFG).unwrapped
    policy = make_policy(name, CFG, seed=5)
    obs, _ = env.reset(seed=5)
    policy.reset(5)
    checked = 0
    for slot in range(12):
        snap = env.snapshot()
        action = policy.act(obs)
        plan = policy.last_plan
        if slot % 3 == 0:
            psi = _slot_problem(policy.solver if name != "rg-mpc" else AOSolver(CFG), snap).success(
                plan.power_w, plan.drone_position)
            mine = expected_cost(snap, plan.increments, plan.power_w, plan.drone_position, per_agv=True)
            for k in range(CFG.num_agvs):
                value, _ = independent_qp(CFG, snap.x_aug[k], snap.reference[k], psi[k])
                assert mine[k] <= value * (1 + 1e-6) + 1e-9, (name, slot, k, mine[k], value)
                checked += 1
        obs, _, _, _, _ = env.step(action)
    assert checked == 4 * CFG.num_agvs


@pytest.mark.parametrize("name", ["pid", "lqr"])
def test_tracking_rollouts_hold_between_commands(name):
    cfg = CFG.override(**{"disturbance.control_period_slots": 2})
    policy = make_policy(name, cfg)
    policy.reset(0)
    for snap in _snapshots(3, seed=6, config=cfg):
        plan = policy.plan(snap)
        held = (snap.slot + np.arange(cfg.control.horizon)) % 2 != 0
        assert np.all(plan.increments[:, held] == 0.0)
        assert np.abs(plan.increments[:, ~held]).max() > 0


def test_period_aware_planning_keeps_tracking_where_the_unaware_ablation_collapses():
    """Commands every 3 slots, perfect links (paper-nominal): EPA's MPC that plans with move
    blocking tracks; the ablation that plans as if it commanded every slot does not."""
    from evaluation.run import run_episode
    from lawn_env import presets

    base = presets.get("paper-nominal").override(num_slots=60, **{"disturbance.control_period_slots": 3})
    aware = run_episode("epa", "lawn/Joint-v1", base, 0)
    unaware = run_episode("epa", "lawn/Joint-v1", base.override(**{"disturbance.period_aware_planning": False}), 0)
    assert aware.rmse_m < 1.0 < 5 * aware.rmse_m < unaware.rmse_m



def test_rollout_hooks_stop_and_cap_the_episode_and_see_the_state_acted_in():
    from agents import rollout

    cfg = ScenarioConfig(num_slots=12)
    env = gym.make("lawn/Joint-v1", config=cfg)
    policy = make_policy("heuristic", cfg)
    costs = []
    full = rollout(env, policy, 3, on_step=lambda step: costs.append(step.info["stage_cost"]))
    assert full.ended and full.truncated and full.length == 12 and full.decision_s.shape == (12,)
    assert rollout(env, policy, 3).metrics == full.metrics  # a seed fixes the episode
    seen = []

    def on_step(step):
        assert step.snapshot.slot == step.slot and env.unwrapped.sim.slot == step.slot + 1
        assert step.reward == pytest.approx(-step.info["stage_cost"])
        seen.append(step.info["stage_cost"])
        return step.slot == 4

    early = rollout(env, policy, 3, on_step=on_step, snapshots=True)
    assert early.length == 5 and not early.ended and seen == costs[:5]
    with pytest.raises(ValueError, match="no episode metrics"):
        early.metrics
    capped = rollout(env, policy, 3, max_steps=2, on_step=lambda step: seen.append(step.snapshot))
    assert capped.length == 2 and not capped.ended and seen[-2:] == [None, None]
    with pytest.raises(ValueError, match="max_steps"):
        rollout(env, policy, 3, max_steps=0)
