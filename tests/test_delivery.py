"""``dv-mpc``, the delivery-value expert (MODEL.md §4, "Planning under delivery"), and the AGVs' law
``control.law``."""

import gymnasium as gym
import numpy as np
import pytest
from test_agents import _snapshots

from agents import make_policy, rollout
from agents.dv_mpc import DeliveryValuePlanner
from agents.dv_mpc import DeliveryProblem, DeliverySettings
from lawn_env import ScenarioConfig, channel, presets
from lawn_env.dynamics import command_mask
from lawn_env.errors import ConfigError
from lawn_env.mpc import OutageAwareMPC
from lawn_env.tail import LossAwareTail

CFG = ScenarioConfig()
DISTURBED = presets.get("disturbed")


def _problem(snap, config=CFG, backend="compiled"):
    return DeliveryProblem(OutageAwareMPC.from_config(config, backend=backend),
                           channel.LinkParams.from_config(config, planning=True), snap, config)


def test_the_lost_command_values_match_an_independent_qp(independent_qp):
    """V^del is the QP at psi = 1; V^lost the same with the next command held at zero (with commands
    every second slot, on a slot without one, the horizon's second increment), each checked against
    cvxpy's solve of the QP written from the paper."""
    for config in (CFG, DISTURBED):
        for snap in _snapshots(2, seed=21, config=config):
            problem = _problem(snap, config)
            period = config.disturbance.control_period_slots
            mask = command_mask(snap.slot, config.control.horizon, period)
            first = int(np.flatnonzero(mask)[0])
            for k in range(config.num_agvs):
                blocked = ~mask
                v_del, _ = independent_qp(config, snap.x_aug[k], snap.reference[k], 1.0, blocked)
                lost_blocked = blocked.copy()
                lost_blocked[first] = True
                v_lost, _ = independent_qp(config, snap.x_aug[k], snap.reference[k], 1.0, lost_blocked)
                assert problem.delivered.value[k] == pytest.approx(v_del, rel=1e-6, abs=1e-6)
                assert problem.lost[k] == pytest.approx(v_lost, rel=1e-6, abs=1e-6)
            assert np.all(problem.worth >= 0)


def test_the_compiled_lost_command_matches_the_reference_backend():
    for config in (CFG, DISTURBED):
        for snap in _snapshots(3, seed=22, config=config):
            compiled, reference = _problem(snap, config), _problem(snap, config, backend="daqp")
            assert np.allclose(compiled.lost, reference.lost, rtol=1e-9, atol=1e-9)
            assert np.allclose(compiled.delivered.increments, reference.delivered.increments, atol=1e-7)


def test_the_objective_is_the_expected_cost_of_delivery(rng):
    """Phi(p, q) = sum_k psi_k V^del_k + (1 - psi_k) V^lost_k, its slope in psi -w, at any (p, q)."""
    for snap in _snapshots(3, seed=23):
        problem = _problem(snap)
        for _ in range(4):
            p = rng.uniform(0.0, problem.budget / 4, 4)
            q = snap.drone_position + rng.normal(0, 3, 2)
            ev = problem.evaluate(p, q)
            psi = problem.success(p, q)
            expected = psi * problem.delivered.value + (1 - psi) * problem.lost
            assert ev.phi == pytest.approx(expected.sum(), rel=1e-12)
            assert np.allclose(ev.slopes, -(problem.lost - problem.delivered.value))
            assert np.array_equal(ev.increments, problem.delivered.increments)


@pytest.mark.parametrize("tail", ["certainty-equivalent", "loss-aware"])
def test_dv_mpc_sends_the_delivered_plan_whatever_the_links(tail):
    """The certainty-equivalent tail sends the psi = 1 MPC's increments; the loss-aware tail its QP's at
    the planner's psi-bar (lawn_env.tail); whatever the links, the plan's power and drone are feasible."""
    policy = make_policy("dv-mpc", CFG, tail=tail)
    policy.reset(seed=0)
    mpc = OutageAwareMPC.from_config(CFG, backend="daqp")
    lossy = LossAwareTail.from_config(CFG, backend="daqp")
    for snap in _snapshots(4, seed=24):
        plan = policy.plan(snap)
        if tail == "certainty-equivalent":
            expected = mpc.solve(snap.x_aug, snap.reference, np.ones(4), snap.slot).increments
        else:
            expected = lossy.delivery_values(snap.x_aug, snap.reference, plan.info["expected_delivery"],
                                             snap.slot)[0].increments
        assert np.allclose(plan.increments, expected, atol=1e-7)
        assert plan.power_w.sum() <= CFG.power_budget_w * (1 + 1e-9) and np.all(plan.power_w >= 0)
        assert np.linalg.norm(plan.drone_position - snap.drone_position) <= CFG.drone_reach_m + 1e-9
        assert np.allclose(plan.info["success_probability"], channel.LinkParams.from_config(CFG, planning=True)
                           .success_sq(plan.power_w, np.sum((plan.drone_position - snap.x_aug[:, :2]) ** 2, axis=1)
                                       + CFG.drone.altitude_m ** 2))


def test_dv_mpc_does_not_lose_to_its_own_start():
    """The refinement only accepts improvements: the returned objective is at most every start's."""
    planner = DeliveryValuePlanner(CFG)
    for snap in _snapshots(4, seed=25):
        plan = planner.plan(snap)
        assert plan.objective <= min(plan.info["start_values"].values()) + 1e-9


def test_with_perfect_links_dv_mpc_decides_as_rg_mpc():
    """Every command arrives: both plan the psi = 1 increments, and the episodes are the same."""
    config = CFG.override({"channel.perfect_links": True})
    costs = {}
    for name in ("dv-mpc", "rg-mpc"):
        env = gym.make("lawn/Joint-v1", config=config).unwrapped
        slots = []
        rollout(env, make_policy(name, config), 3, max_steps=15, on_step=lambda step: slots.append(step.info["stage_cost"]))
        costs[name] = np.array(slots)
    assert np.allclose(costs["dv-mpc"], costs["rg-mpc"], rtol=1e-9, atol=1e-9)


def test_under_a_control_period_the_command_is_the_next_command_slots_increment():
    config = DISTURBED  # from the snapshots as observed: the tracker (tested below) off
    policy = make_policy("dv-mpc", config, model_lag=False, filter_measurements=False, tail="certainty-equivalent")
    policy.reset(seed=0)
    reach = config.drone_reach_m
    mpc = OutageAwareMPC.from_config(config, backend="daqp")
    for snap in _snapshots(6, seed=26, config=config):
        plan = policy.plan(snap)
        mask = command_mask(snap.slot, config.control.horizon, 2)
        expected = mpc.solve(snap.x_aug, snap.reference, np.ones(4), snap.slot).increments
        assert np.allclose(plan.increments, expected, atol=1e-7)
        assert np.all(plan.increments[:, ~mask] == 0.0)
        step = np.linalg.norm(plan.drone_position - snap.drone_position)
        assert step <= reach + 1e-9
        if snap.slot % 2:  # no command this slot: the drone heads for where the next one goes out
            target = plan.info["command_position"]
            assert np.linalg.norm(target - snap.drone_position) <= 2 * reach + 1e-9
            direction = (plan.drone_position - snap.drone_position) @ (target - snap.drone_position)
            assert direction >= 0
        else:
            assert "command_position" not in plan.info


def test_dv_mpc_plans_for_the_law_the_comm_agvs_apply():
    """On lawn/Comm-v1 under the paper's law the AGVs apply the psi-scaled QP: dv-mpc's problem is
    then the paper's, which rg-mpc solves; under the delivery law it is the delivery value's."""
    paper = make_policy("dv-mpc", CFG, env_id="lawn/Comm-v1")
    delivery = make_policy("dv-mpc", CFG.override({"control.law": "delivery"}), env_id="lawn/Comm-v1")
    rg = make_policy("rg-mpc", CFG, env_id="lawn/Comm-v1")
    for policy in (paper, delivery, rg):
        policy.reset(seed=0)
    for snap in _snapshots(3, seed=27):
        a, b = paper.plan(snap), rg.plan(snap)
        assert np.array_equal(a.power_w, b.power_w) and np.array_equal(a.drone_position, b.drone_position)
        assert isinstance(delivery.solver, DeliveryValuePlanner)


def test_the_default_law_is_the_papers_and_comm_v0_is_unchanged():
    assert ScenarioConfig().control.law == "paper"
    for preset in presets.names():
        assert presets.get(preset).control.law == "paper"


def test_bad_values_of_the_new_settings_name_them():
    with pytest.raises(ConfigError, match=r"control\.law.*'carrier-pigeon'.*paper.*delivery"):
        ScenarioConfig().override({"control.law": "carrier-pigeon"})
    with pytest.raises(ValueError, match=r"refine_iterations"):
        make_policy("dv-mpc", CFG, refine_iterations=-1)
    with pytest.raises(ValueError, match=r"psi_points"):  # rg-mpc's table: dv-mpc has none
        make_policy("dv-mpc", CFG, psi_points=9)
    with pytest.raises(ValueError, match=r"power_levels"):
        DeliverySettings(power_levels=1)


def test_dv_mpc_is_a_registered_policy_name():
    from agents import policy_names
    from agents.policies import is_policy_name

    assert "dv-mpc" in policy_names() and is_policy_name("dv-mpc")


def test_the_lag_aware_model_predicts_the_simulators_lagged_step():
    """With the actuator lag (and nothing else) on, the lag-aware MPC's prediction of the next slot
    is the simulator's state to rounding; the loss-free model's is not."""
    from lawn_env.dynamics import PredictionModel

    config = CFG.override({"disturbance.actuator_lag_s": 0.3})
    model = PredictionModel.from_config(config, lag=True)
    assert model.state_dim == 8 and PredictionModel.from_config(config).state_dim == 6
    env = gym.make("lawn/Joint-v1", config=config.override({"channel.perfect_links": True})).unwrapped
    env.reset(seed=4)
    rng = np.random.default_rng(4)
    for _ in range(12):
        x8 = np.concatenate([env.sim.x_aug.copy(), env.sim.applied.copy()], axis=1)
        u_prev = env.sim.x_aug[:, 4:6]  # increments that keep |u| inside the bound (no saturation)
        du = np.clip(u_prev + rng.uniform(-0.5, 0.5, (4, 2)), -1.5, 1.5) - u_prev
        dmu = np.zeros((4, config.control.horizon, 2))
        dmu[:, 0] = du
        predicted = (x8 @ model.c.T + dmu.reshape(4, -1) @ model.f.T).reshape(4, -1, 6)[:, 1]
        action = env.actions.encode(lawn_env_decisions(du, env), env.sim.x_aug, None, env.sim.drone_position)
        env.step(action)
        assert np.allclose(predicted, env.sim.x_aug, atol=1e-5)


def lawn_env_decisions(du, env):
    from lawn_env.core import Decisions

    return Decisions(du, np.full(4, env.config.power_budget_w / 4), env.sim.drone_position.copy())


def test_the_tracker_follows_the_applied_acceleration_and_filters_the_measurements():
    """Under `disturbed` the tracker's applied acceleration is the simulator's (to the observation's
    float32 rounding) and its filtered positions are closer to the true ones than the measurements."""
    config = DISTURBED
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    policy = make_policy("dv-mpc", config)
    obs, _ = env.reset(seed=5)
    policy.reset(seed=5)
    assert policy.solver.tracker.lag_alpha is not None and policy.solver.tracker.filtering
    measured, filtered = [], []
    for slot in range(40):
        action = policy.act(obs)
        tracker = policy.solver.tracker  # the episode's, once it has planned
        assert np.allclose(tracker.applied, env.sim.applied, atol=1e-6)
        truth = env.sim.x_aug[:, 0:2]
        measured.append(np.abs(env.snapshot().x_aug[:, 0:2] - truth).mean())
        filtered.append(np.abs(tracker.estimate[:, 0:2] - truth).mean())
        obs, *_ = env.step(action)
    assert np.mean(filtered[5:]) < 0.7 * np.mean(measured[5:])


def test_without_a_lag_or_measurement_noise_the_tracker_changes_nothing():
    planner = DeliveryValuePlanner(presets.get("steady-gusty"))
    assert planner.tracker.lag_alpha is None and not planner.tracker.filtering
    assert planner.mpc.model.state_dim == 6
    off = DeliveryValuePlanner(DISTURBED, DeliverySettings(model_lag=False, filter_measurements=False))
    assert off.mpc.model.state_dim == 6 and off._state(off._first(), _snapshots(1, seed=1, config=DISTURBED)[0]) is None


def test_a_control_period_longer_than_the_horizon_holds_nothing_it_cannot_see():
    """With commands every 11 slots and a 10-slot horizon, some slots see no command in the horizon:
    the lost and delivered values are then equal (nothing to lose), and dv-mpc still plans."""
    config = CFG.override({"disturbance.control_period_slots": 11})
    mpc = OutageAwareMPC.from_config(config)
    for snap in _snapshots(2, seed=28, config=config):
        for slot in (0, 1, 5):
            data = mpc.prepare(snap.x_aug, snap.reference, slot)
            delivered, lost = mpc.delivery_values(data)
            if slot == 1:  # the next command at slot 11: horizon index 10, beyond it
                assert np.allclose(lost, delivered.value)
            else:
                assert np.all(lost >= delivered.value - 1e-9)
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    rollout(env, make_policy("dv-mpc", config), 0, max_steps=13)
