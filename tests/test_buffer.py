"""The buffered actuator (``control.actuator="buffer"``, MODEL.md §3): the buffer replaced on delivery
and played on loss, against a hand-written sequence and against an emulation on perfect links; V^lost
under the buffer against an independent rollout; the envs, the vector env and the planners under it."""

import gymnasium as gym
import numpy as np
import pytest
from test_vector import _lockstep

import lawn_env
from agents import make_policy
from lawn_env import ScenarioConfig, presets
from lawn_env.core import Decisions, Simulation, SlotDraws, buffer_queue, later_increments
from lawn_env.errors import ConfigError
from lawn_env.mpc import OutageAwareMPC

BUFFER = {"control.actuator": "buffer"}
CFG = ScenarioConfig(num_slots=30).override(BUFFER)
DELIVERED, LOST = 1e12, 0.0  # fading draws that deliver every command, and that lose it


def _sim(config=CFG, seed=0):
    sim = Simulation(config, 1)
    sim.reset([np.random.default_rng(seed)])
    return sim


def _decide(sim, increment, plan):
    k = sim.num_agvs
    return Decisions(np.asarray(increment, float).reshape(1, k, 2), np.full((1, k), 0.25),
                     sim.drone_position.copy(), np.asarray(plan, float).reshape(1, k, -1, 2))


def test_the_buffer_is_replaced_on_delivery_and_played_on_loss_slot_by_slot():
    """A hand-written delivery pattern: AGV 0's applied increments are its command where it arrives and
    its last delivered plan's next element where it does not; a spent buffer holds (zero), and a new
    episode starts spent."""
    sim = _sim()
    k, length = sim.num_agvs, sim.params.buffer_length
    assert length == CFG.control.horizon - 1
    np.testing.assert_array_equal(sim.state.buffer_age, length)  # spent at the start
    rng = np.random.default_rng(1)
    pattern = [LOST, DELIVERED, LOST, LOST, DELIVERED, LOST] + [LOST] * (length + 2)
    expected, buffer, played = [], np.zeros((length, 2)), length
    for fading in pattern:
        increment = rng.uniform(-0.05, 0.05, (k, 2))
        plan = rng.uniform(-0.05, 0.05, (k, length, 2))
        if fading == DELIVERED:
            expected.append(increment[0])
            buffer, played = plan[0], 0
        else:
            expected.append(buffer[played] if played < length else np.zeros(2))
            played = min(played + 1, length)
        record = sim.step(_decide(sim, increment, plan), SlotDraws(np.full((1, k), fading)))
        np.testing.assert_allclose(record.applied_increment[0, 0], expected[-1], rtol=0, atol=1e-15)
        assert sim.state.buffer_age[0, 0] == played
        np.testing.assert_array_equal(buffer_queue(sim.state.buffer, sim.state.buffer_age)[0, 0, : length - played],
                                      buffer[played:])
    assert np.abs(expected[-1]).max() == 0.0  # the buffer ran out: a hold
    sim.reset([np.random.default_rng(0)])
    np.testing.assert_array_equal(sim.state.buffer_age, length)


def test_the_buffer_equals_its_emulation_on_perfect_links():
    """The issue's emulation: on perfect links (every command arrives) feed the increments the buffer would
    play, with delivery drawn outside; the buffered simulator with those deliveries moves the AGVs, and
    costs, the same."""
    config = presets.get("steady").override({"num_slots": 40, **BUFFER})
    buffered = _sim(config, seed=3)
    emulated = _sim(config.override({"control.actuator": "hold", "channel.perfect_links": True}), seed=3)
    k, length = buffered.num_agvs, buffered.params.buffer_length
    rng = np.random.default_rng(5)
    buffer, played = np.zeros((k, length, 2)), np.full(k, length)
    for _ in range(config.num_slots):
        increment, plan = rng.uniform(-0.3, 0.3, (k, 2)), rng.uniform(-0.3, 0.3, (k, length, 2))
        arrives = rng.random(k) < 0.4
        applied = np.where(arrives[:, None], increment,
                           [buffer[i, played[i]] if played[i] < length else np.zeros(2) for i in range(k)])
        buffer[arrives], played = plan[arrives], np.where(arrives, 0, np.minimum(played + 1, length))
        buffered.step(_decide(buffered, increment, plan), SlotDraws(np.where(arrives, DELIVERED, LOST)[None]))
        emulated.step(Decisions(applied[None], np.full((1, k), 0.25), emulated.drone_position.copy()),
                      SlotDraws(np.full((1, k), DELIVERED)))
        np.testing.assert_allclose(buffered.x_aug, emulated.x_aug, rtol=0, atol=1e-12)
    b, e = buffered.episode_metrics()[0], emulated.episode_metrics()[0]
    assert b.control_cost == pytest.approx(e.control_cost, rel=1e-12)


def _rollout_value(cp, model, ctl, z0, ref, first, pinned, blocked):
    """V of one AGV by an explicit rollout x_{i+1} = A~ x_i + B~ d_i (not the MPC's condensed matrices):
    sum_{i < N} e_i'Q1 e_i + d_i'Q2 d_i + e_N'Q3 e_N, the increment of horizon index ``first`` pinned,
    the ``blocked`` ones zero, the others within the bounds."""
    n = ctl.horizon
    d = cp.Variable((n, 2))
    x, cost, u, cons = z0, 0, z0[4:6], []
    for i in range(n):
        cost += cp.quad_form(x - ref[i], model.q1) + cp.quad_form(d[i], model.q2)
        u = u + d[i]
        cons += [cp.abs(d[i]) <= ctl.accel_increment_max_mps2, cp.abs(u) <= ctl.accel_max_mps2]
        if i == first:
            cons.append(d[i] == pinned)
        elif blocked[i]:
            cons.append(d[i] == 0)
        x = model.a_aug @ x + model.b_aug @ d[i]
    cost += cp.quad_form(x - ref[n], model.q3)
    problem = cp.Problem(cp.Minimize(cost), cons)
    problem.solve(solver=cp.CLARABEL, tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
    return problem.value


@pytest.mark.parametrize("preset", ["default", "disturbed"])
def test_v_lost_under_the_buffer_plays_its_next_increment(preset):
    """V^lost with the buffer's queue is the MPC's optimum with the next command's increment the one the
    buffer plays then (the queue's element at the next command's horizon index, saturated), against cvxpy
    on an explicit rollout; a spent queue gives the hold's V^lost."""
    cp = pytest.importorskip("cvxpy")
    config = presets.get(preset).override(BUFFER)
    mpc = OutageAwareMPC.from_config(config, backend="compiled")
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    env.reset(seed=4)
    rng = np.random.default_rng(2)
    period, ctl = mpc.control_period, config.control
    for _ in range(3):
        env.step(env.action_space.sample())
    for _slot_step in range(2):  # with a control period: a command slot, then one without
        snap = env.snapshot()
        x = snap.x_aug.copy()
        x[:, 4:6] = rng.uniform(-1.9, 1.9, x[:, 4:6].shape)  # some pinned increments saturate
        queue = rng.uniform(-1.0, 1.0, snap.buffer.shape)
        data = mpc.prepare(x, snap.reference, snap.slot)
        _, lost = mpc.delivery_values(data, queue)
        _, held = mpc.delivery_values(data)
        _, spent = mpc.delivery_values(data, np.zeros_like(queue))
        np.testing.assert_allclose(spent, held, rtol=1e-9)
        first = (-snap.slot) % period
        blocked = (snap.slot + np.arange(ctl.horizon)) % period != 0
        for k in range(config.num_agvs):
            u = x[k, 4:6]
            pinned = np.clip(u + queue[k, first], -ctl.accel_max_mps2, ctl.accel_max_mps2) - u
            want = _rollout_value(cp, mpc.model, ctl, x[k], snap.reference[k], first, pinned, blocked)
            assert lost[k] == pytest.approx(want, rel=1e-6, abs=1e-6)
        env.step(env.action_space.sample())


def test_a_bad_actuator_and_a_packet_that_cannot_hold_the_plan_are_named():
    with pytest.raises(ConfigError, match=r"control\.actuator.*'hold'.*'buffer'"):
        ScenarioConfig().override({"control.actuator": "smart"})
    with pytest.raises(ConfigError, match=r"control.actuator='buffer' with control.horizon=40: .*1280 bits.*"
                                          r"1 x 1024 = 1024 bits"):
        ScenarioConfig().override({**BUFFER, "control.horizon": 40, "channel.rate_threshold_bps_hz": 1.0})
    ScenarioConfig().override({"control.horizon": 40, "channel.rate_threshold_bps_hz": 1.0})  # hold: no packet check
    sim = _sim()
    with pytest.raises(ValueError, match=r"decisions.plan has shape \(1, 4, 3, 2\).*\(1, 4, 9, 2\)"):
        sim.step(_decide(sim, np.zeros((4, 2)), np.zeros((4, 3, 2))), SlotDraws(np.ones((1, 4))))


def test_the_joint_action_carries_the_plan_and_the_observation_the_queue():
    """Joint's direct action ends with the AGVs' plans (x Delta-a_max), which the env's buffer holds after a
    delivery; the observation's buffer features decode to the queue (float32-exact); encode inverts the
    decode of the increments and plans."""
    env = gym.make("lawn/Joint-v1", config=CFG).unwrapped
    k, length = CFG.num_agvs, CFG.control.horizon - 1
    assert env.action_space.shape == (3 * k + 2 + 2 * k * length,)
    assert env.observation_space.shape == (env.layout.size,)
    assert env.layout.feature_names()[-3 - 2 * length :][:2] == ["buffer1_ax", "buffer1_ay"]
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(6):
        action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        obs, *_, info = env.step(action)
        sim = env.engine.sim
        plans = action[3 * k + 2 :].reshape(k, length, 2).astype(float) * CFG.control.accel_increment_max_mps2
        delivered = info["delivered"]
        np.testing.assert_allclose(sim.state.buffer[0][delivered], plans[delivered], rtol=1e-7)
        queue = buffer_queue(sim.state.buffer, sim.state.buffer_age)[0]
        np.testing.assert_allclose(env.layout.decode(obs)["buffer"], queue, atol=1e-6)
        np.testing.assert_array_equal(env.snapshot().buffer, queue)
        snap = env.snapshot()
        decision = env.actions.decode(action, snap.x_aug, None, snap.drone_position)
        encoded = env.actions.encode(decision, snap.x_aug, None, snap.drone_position)
        np.testing.assert_allclose(encoded[3 * k + 2 :], action[3 * k + 2 :], atol=1e-6)  # the plans'
        np.testing.assert_allclose(encoded[: 2 * k], action[: 2 * k], atol=1e-6)  # the increments'
        np.testing.assert_allclose(decision.plan, plans, rtol=1e-7)


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_vector_env_and_single_env_agree_under_the_buffer(env_id):
    config = ScenarioConfig(num_agvs=3, num_slots=25).override(BUFFER)
    size = gym.make(env_id, config=config).action_space.shape[0]
    rng = np.random.default_rng(1)
    _lockstep(env_id, config, rng.uniform(-1, 1, (25, 3, size)).astype(np.float32), 10)


@pytest.mark.parametrize("interface", [None, "rl", {"layout": "entities"}, {"base": "rl", "layout": "entities"}])
@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_gymnasiums_checker_passes_under_the_buffer(env_id, interface):
    from gymnasium.utils.env_checker import check_env

    check_env(gym.make(env_id, config=CFG, interface=interface).unwrapped, skip_render_check=True)


@pytest.mark.parametrize("interface", [None, {"layout": "entities"}])
def test_pettingzoo_agvs_send_their_plans(interface):
    """Each AGV agent's action is its increment then its plan (the flat layout) or its entity row with the
    plan after the power weight; PettingZoo's own API test passes."""
    from pettingzoo.test import parallel_api_test

    env = lawn_env.parallel_env(CFG, interface=interface)
    k, length = CFG.num_agvs, CFG.control.horizon - 1
    assert env.action_space("agv_0").shape == ((2 + 2 * length,) if interface is None else (3 + 2 * length,))
    parallel_api_test(lawn_env.parallel_env(CFG, interface=interface, max_cycles=15), num_cycles=10)
    env.reset(seed=0)
    actions = {a: env.action_space(a).sample() for a in env.agents}
    _, _, _, _, infos = env.step(actions)
    plan_at = 2 if interface is None else 3
    for i in range(k):
        if infos["drone"]["delivered"][i]:
            want = actions[f"agv_{i}"][plan_at:].reshape(length, 2) * CFG.control.accel_increment_max_mps2
            np.testing.assert_allclose(env.engine.sim.state.buffer[0, i], want, rtol=1e-6)


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_the_experts_send_their_planned_sequences(env_id):
    """dv-mpc under the buffer: the AGVs whose command arrived hold the rest of its plan (Comm: the env's
    MPC's), and the planner plans with the certainty-equivalent tail (the buffer plays the plan)."""
    config = CFG.override({"control.law": "delivery-certainty-equivalent"}) if env_id == "lawn/Comm-v1" else CFG
    env = gym.make(env_id, config=config).unwrapped
    policy = make_policy("dv-mpc", config, env_id=env_id)
    assert policy.solver.tail is None
    obs, _ = env.reset(seed=2)
    policy.reset(seed=2)
    for _ in range(4):
        action, _ = policy.predict(obs)
        obs, *_, info = env.step(action)
        delivered = info["delivered"]
        if env_id == "lawn/Joint-v1":
            want = later_increments(policy.last_plan.increments, config.control.horizon - 1)
            np.testing.assert_allclose(env.engine.sim.state.buffer[0][delivered], want[delivered], atol=1e-6)
        else:
            assert np.abs(env.engine.sim.state.buffer[0][delivered]).max() > 0


def test_the_buffer_beats_the_hold_on_a_poor_link_seed():
    """A regression bound on the measured result (docs/experts.md, ``python benchmarks/buffer.py``): at
    K = 16 the buffered actuator with its expert costs well under the hold actuator with the best hold
    expert on the same seed."""
    config = presets.get("k16").override({"num_slots": 40})
    costs = {}
    for actuator in ("hold", "buffer"):
        cfg = config.override({"control.actuator": actuator})
        env = gym.make("lawn/Joint-v1", config=cfg)
        policy = make_policy("dv-mpc", cfg)
        obs, _ = env.reset(seed=701)
        policy.reset(seed=701)
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(policy.predict(obs)[0])
            done = terminated or truncated
        costs[actuator] = info["episode_metrics"]["control_cost"]
    assert costs["buffer"] < 0.85 * costs["hold"]


def test_a_plan_outside_the_increment_bound_is_clipped_into_the_packet():
    """The packet carries the plan inside the control set: a planner that left later increments unbounded
    (the loss-aware tail releases their bounds) does not make an AGV play more than Delta-a_max."""
    sim = _sim()
    k, length, bound = sim.num_agvs, sim.params.buffer_length, CFG.control.accel_increment_max_mps2
    plan = np.full((k, length, 2), 5.0 * bound)
    sim.step(_decide(sim, np.zeros((k, 2)), plan), SlotDraws(np.full((1, k), DELIVERED)))
    np.testing.assert_array_equal(sim.state.buffer[0], bound)


def test_the_entity_rows_carry_the_plans_of_the_direct_actions_only():
    """The entity layout's Joint row is (increment, power weight, plan) under the direct actions of the
    buffered actuator and (increment, power weight) under the anchored ones; its gather is a bijection
    between the present entries and the flat action."""
    from lawn_env.entities import MAX_AGVS, EntityLayout

    length = CFG.control.horizon - 1
    direct, anchored = EntityLayout(CFG, "joint", 10.0, "direct"), EntityLayout(CFG, "joint", 10.0, "anchored")
    assert (direct.per_agv, anchored.per_agv) == (3 + 2 * length, 3)
    flat_size = gym.make("lawn/Joint-v1", config=CFG).action_space.shape[0]
    assert sorted(direct.gather.tolist()) == sorted(set(direct.gather.tolist())) and direct.gather.size == flat_size
    flat = np.random.default_rng(0).uniform(-1, 1, flat_size)
    np.testing.assert_array_equal(direct.to_flat_actions(direct.to_entity_actions(flat)), flat.astype(np.float32))
    assert direct.action_space.shape == (MAX_AGVS * (3 + 2 * length) + 2,)
