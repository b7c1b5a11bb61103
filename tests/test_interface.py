"""The opt-in RL interface (lawn_env.interface): reward, termination, action schemes, checkers."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test, parallel_seed_test

import lawn_env
from agents import make_policy
from lawn_env import ScenarioConfig
from lawn_env.core import Decisions
from lawn_env.dynamics import PredictionModel
from lawn_env.interface import RL_INTERFACE, STAKE_FLOOR, RLInterface, action_codec, resolve_interface

RL_IDS = list(lawn_env.RL_ENV_IDS)
SHORT = ScenarioConfig(num_slots=30)


@pytest.mark.parametrize("env_id", RL_IDS)
def test_gymnasium_and_sb3_checkers(env_id):
    check_env(gym.make(env_id).unwrapped)
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3_checker.check_env(gym.make(env_id), warn=True)


def test_pettingzoo_checkers_with_the_interface():
    parallel_api_test(lawn_env.parallel_env(interface="rl"), num_cycles=150)
    parallel_seed_test(lambda: lawn_env.parallel_env(num_agvs=3, interface="rl"))


def test_registered_ids_are_the_v0_envs_with_the_rl_interface():
    for rl_id, base in lawn_env.RL_ENV_IDS.items():
        env = gym.make(rl_id).unwrapped
        assert env.interface == RL_INTERFACE and type(env) is type(gym.make(base).unwrapped)
        assert env.observation_space.high[0] == RL_INTERFACE.obs_clip
    assert gym.make("lawn/Joint-v1").unwrapped.interface == RLInterface()


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_reward_is_the_scaled_clipped_cost(env_id):
    iface = RLInterface(action_scheme="anchored", reward="scaled", cost_scale=7.0, cost_clip=30.0)
    env = gym.make(env_id, config=SHORT, interface=iface)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    clipped = 0
    for _ in range(30):
        _, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        cost = info["stage_cost"]
        assert cost == pytest.approx(-(info["reward_tracking"] + info["reward_effort"]))
        assert reward == pytest.approx(-min(cost, 30.0) / 7.0)
        assert -30.0 / 7.0 <= reward <= 0.0
        clipped += cost > 30.0
        if terminated or truncated:
            break
    assert clipped > 0  # random residuals on Joint / drone targets on Comm: some slots exceed the clip


def test_termination_fires_exactly_past_the_bound_and_never_pays():
    bound = 4.0
    iface = RLInterface(reward="scaled", termination_distance_m=bound)
    env = gym.make("lawn/Joint-v1", interface=iface).unwrapped
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, np.float32)
    action[0] = 1.0  # AGV 0 keeps accelerating away from its track
    total = 0.0
    while True:
        _, reward, terminated, truncated, info = env.step(action)
        total += reward
        err = np.linalg.norm(env.sim.tracking_error[:, 0:2], axis=1).max()
        assert terminated == (err > bound)
        if terminated:
            break
        assert not truncated
    remaining = env.sim.num_slots - env.sim.slot
    assert remaining > 0 and "episode_metrics" in info
    floor = -iface.cost_clip / iface.cost_scale
    own = float(iface.rewards_from_costs(info["stage_cost"]))
    assert reward == pytest.approx(own + remaining * floor)
    # continuing would have earned at least the floor on every remaining slot: ending never pays
    assert reward <= own + remaining * floor + 1e-12
    with pytest.raises(RuntimeError, match="reset"):
        env.step(action)


def test_termination_needs_the_bounded_reward():
    with pytest.raises(ValueError, match="termination_distance_m=10.0 needs reward='scaled'"):
        RLInterface(termination_distance_m=10.0)
    with pytest.raises(ValueError, match="cost_clip"):
        RLInterface(cost_clip=-1)
    with pytest.raises(ValueError, match="valid names: v0, rl"):
        resolve_interface("fancy")
    with pytest.raises(ValueError, match="obs_clip"):
        gym.make("lawn/Comm-v1", interface={"obs_clip": 0})


def test_observations_are_clipped():
    env = gym.make("lawn/Joint-v1", interface={"obs_clip": 0.5})
    obs, _ = env.reset(seed=0)
    for _ in range(10):
        obs, *_ = env.step(np.ones(env.action_space.shape, np.float32))
        assert np.abs(obs).max() <= 0.5 and env.observation_space.contains(obs)


def _zero_action_cost(env_id, seed, interface):
    env = gym.make(env_id, interface=interface)
    env.reset(seed=seed)
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(env.action_space.shape, np.float32))
        done = terminated or truncated
    assert truncated and not terminated  # full episodes
    return info["episode_metrics"]["control_cost"]


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_zero_action_of_the_anchored_scheme_is_a_sound_policy(env_id):
    from evaluation.run import run_episode

    seeds = range(5)
    zero = np.mean([_zero_action_cost(env_id, s, "rl") for s in seeds])
    epa = np.mean([run_episode("epa", env_id, ScenarioConfig(), s).control_cost for s in seeds])
    plain_zero = _zero_action_cost("lawn/Comm-v1", 0, None)
    assert np.isfinite(zero) and zero < 3 * epa  # a small factor of EPA ...
    assert plain_zero > 100 * epa  # ... where the v0 zero action (hover at the start) is a catastrophe
    by_distance = np.mean([_zero_action_cost(env_id, s, {"base": "rl", "power_anchor": "distance"}) for s in seeds])
    assert zero < by_distance  # the stake prior is the better anchor (benchmarks/anchors.py measures by how much)


def test_stake_prior_is_the_linearized_slot_problems_power_split():
    """The stakes are V_k(0) - V_k(1) of the slot's QPs; the zero action's powers are P_max
    (w d^2m)^(1/(m+1)) normalized; a worthless command keeps a floor, and with no stake at all the
    split goes by distance alone."""
    cfg = ScenarioConfig()
    env = gym.make("lawn/Comm-v1").unwrapped
    env.reset(seed=3)
    env.action_space.seed(3)
    for _ in range(3):
        env.step(env.action_space.sample())
    sim = env.sim
    layout = action_codec(cfg, "comm", "rl")
    mpc = layout.mpc
    data = mpc.prepare(sim.x_obs, sim.reference_window(), sim.slot)
    stakes = mpc.command_stakes(data)
    lost, sure = mpc.solve_prepared(data, np.zeros(4)).value, mpc.solve_prepared(data, np.ones(4)).value
    np.testing.assert_allclose(stakes, lost - sure, rtol=1e-9)
    assert np.all(stakes > 0)
    decision = layout.decode(np.zeros(layout.size), sim.x_obs, sim.reference_window(), sim.drone_position, sim.slot)
    d2 = layout._link.distance_sq(decision.drone_next, sim.x_obs[:, :2])
    m = cfg.channel.nakagami_m
    floored = np.maximum(stakes, STAKE_FLOOR * stakes.mean())  # a nearly worthless command keeps the floor
    weights = (floored * d2**m) ** (1 / (m + 1))
    np.testing.assert_allclose(decision.power_w, cfg.power_budget_w * weights / weights.sum(), rtol=1e-9)
    # the AGV whose command is worth most per unit of distance gets the most power
    assert np.argmax(decision.power_w / d2 ** (m / (m + 1))) == np.argmax(stakes)
    env.reset(seed=3)  # actions that leave AGV 1 a command worth less than the floor
    env.action_space.seed(49)
    for _ in range(3):
        env.step(env.action_space.sample())
    sim = env.sim
    data = mpc.prepare(sim.x_obs, sim.reference_window(), sim.slot)
    stakes = mpc.command_stakes(data)
    assert stakes.min() < STAKE_FLOOR * stakes.mean()
    decision = layout.decode(np.zeros(layout.size), sim.x_obs, sim.reference_window(), sim.drone_position, sim.slot)
    d2 = layout._link.distance_sq(decision.drone_next, sim.x_obs[:, :2])
    weights = (np.maximum(stakes, STAKE_FLOOR * stakes.mean()) * d2**m) ** (1 / (m + 1))
    np.testing.assert_allclose(decision.power_w, cfg.power_budget_w * weights / weights.sum(), rtol=1e-9)

    class Fixed:  # stand-in for the MPC's stakes
        def __init__(self, w):
            self.w = np.asarray(w, dtype=float)

        def command_stakes(self, data):
            return self.w

    def split(w):  # the weights' shares (the prior is scale-free)
        return np.asarray(w) / np.sum(w)

    layout.mpc = Fixed([5.0, 0.0, 5.0, 5.0])
    prior = layout.power_prior(sim.x_obs, decision.drone_next, data)
    floored = np.array([5.0, STAKE_FLOOR * 15.0 / 4, 5.0, 5.0])
    np.testing.assert_allclose(split(prior), split((floored * d2**m) ** (1 / (m + 1))), rtol=1e-12)
    layout.mpc = Fixed(np.zeros(4))
    np.testing.assert_allclose(split(layout.power_prior(sim.x_obs, decision.drone_next, data)),
                               split(d2 ** (m / (m + 1))), rtol=1e-12)
    # a large Nakagami m (d^(2m) would overflow) still gives a finite split that spends the budget
    deep = action_codec(ScenarioConfig(channel={"nakagami_m": 71}), "comm", "rl")
    far = deep.decode(np.zeros(deep.size), sim.x_obs, sim.reference_window(), sim.drone_position, sim.slot)
    assert np.all(np.isfinite(far.power_w)) and far.power_w.min() > 0
    assert far.power_w.sum() == pytest.approx(cfg.power_budget_w)
    with pytest.raises(ValueError, match="pass the reference window"):
        layout.decode(np.zeros(layout.size), sim.x_obs, None, sim.drone_position)


def test_lqr_increment_anchor_is_the_lqr_baselines_first_increment_and_solves_no_qp():
    from agents.tracking import lqr_rollout

    cfg = ScenarioConfig()
    layout = action_codec(cfg, "joint", {"base": "rl", "power_anchor": "distance", "increment_anchor": "lqr"})
    assert layout.mpc is None and layout.needs_reference  # the distance prior and the LQR: no MPC, the reference
    env = gym.make("lawn/Joint-v1").unwrapped
    env.reset(seed=3)
    rng = np.random.default_rng(2)
    model = PredictionModel.from_config(cfg)
    ctl = cfg.control
    for _ in range(15):
        env.step(rng.uniform(-0.3, 0.3, env.action_space.shape).astype(np.float32))
        sim = env.sim
        window = sim.reference_window()
        zero = layout.decode(np.zeros(layout.size), sim.x_obs, window, sim.drone_position)
        lqr = lqr_rollout(sim.x_obs, window, model, model.lqr_gain, ctl.accel_max_mps2, ctl.accel_increment_max_mps2)
        np.testing.assert_allclose(zero.increment, lqr[:, 0], rtol=1e-12, atol=1e-12)
        batch = layout.decode(np.zeros((1, layout.size)), sim.x_obs[None], window[None],
                                    sim.drone_position[None])
        np.testing.assert_array_equal(batch.increment[0], zero.increment)
    with pytest.raises(ValueError, match="increment_anchor='lqr'.*pass the reference window"):
        layout.decode(np.zeros(layout.size), sim.x_obs, None, sim.drone_position)
    with pytest.raises(ValueError, match="increment_anchor"):
        action_codec(cfg, "joint", {"base": "rl", "increment_anchor": "pid"})


@pytest.mark.parametrize("role", ["joint", "comm"])
@pytest.mark.parametrize("scheme", ["direct", "anchored", "anchored-lqr"])
def test_encode_decode_round_trip(role, scheme):
    cfg = ScenarioConfig()
    fields = {"action_scheme": "anchored", "increment_anchor": "lqr"} if scheme == "anchored-lqr" else \
        {"action_scheme": scheme}
    layout = action_codec(cfg, role, fields)
    env = gym.make("lawn/Joint-v1").unwrapped
    env.reset(seed=2)
    rng = np.random.default_rng(1)
    for _ in range(20):
        env.step(rng.uniform(-0.2, 0.2, env.action_space.shape).astype(np.float32))
        sim = env.sim
        args = (sim.x_obs, sim.reference_window(), sim.drone_position)
        action = rng.uniform(-0.9, 0.9, layout.size)
        first = layout.decode(action, *args)
        again = layout.decode(layout.encode(first, *args).astype(np.float64), *args)
        np.testing.assert_allclose(again.power_w, first.power_w, rtol=1e-5)
        assert first.power_w.min() > 0 and (scheme == "direct" or first.power_w.sum() == pytest.approx(cfg.power_budget_w))
        np.testing.assert_allclose(again.drone_next, first.drone_next, atol=1e-4)
        if role == "joint":
            np.testing.assert_allclose(again.increment, first.increment, atol=1e-5)
        else:
            assert first.increment is None


def test_encode_keeps_the_strongest_links_when_the_split_spans_more_than_the_range():
    """An expert that leaves links (nearly) unpowered spans more log-weight than the action's range:
    the encoded action keeps the split of the links that carry the budget (the strongest at the
    top of the range) and saturates the weakest, instead of centring the span and clipping both."""
    cfg = ScenarioConfig(num_agvs=6)
    codec = action_codec(cfg, "comm", {"base": "rl", "power_anchor": "distance"})
    env = gym.make("lawn/Comm-v1", config=cfg).unwrapped
    env.reset(seed=3)
    sim = env.sim
    args = (sim.x_obs, sim.reference_window(), sim.drone_position)
    zero = codec.decode(np.zeros(codec.size), *args)
    prior = zero.power_w / zero.power_w.max()
    wanted = prior * np.array([1.0, 0.5, 0.25, 1e-9, 1e-12, 0.0])  # three links off
    power = wanted / wanted.sum() * cfg.power_budget_w
    action = codec.encode(Decisions(None, power, zero.drone_next), *args)
    a = action[: cfg.num_agvs]
    assert a[0] == pytest.approx(1.0) and np.all(a[3:] == -1.0)
    np.testing.assert_allclose(a[:3] - a[0], np.log([1.0, 0.5, 0.25]) / codec.interface.power_log_range, atol=1e-6)
    out = codec.decode(action.astype(np.float64), *args)
    top = power[:3] / power[:3].sum()
    np.testing.assert_allclose(out.power_w[:3] / out.power_w[:3].sum(), top, rtol=1e-5)
    off = np.exp(-2 * codec.interface.power_log_range) * prior[3:] / prior[0]  # the bottom of the range
    np.testing.assert_allclose(out.power_w[3:] / out.power_w[0], off, rtol=1e-5)


def test_planner_decisions_survive_both_schemes():
    """What behaviour cloning does: the expert's plan encoded in the anchored scheme decodes to
    the same physical decision, wherever the scheme can express it (a drone target within
    drone_offset_m of the AGVs' centroid per axis; early slots, with the drone far from the AGVs
    and moving slowly, cannot be, and get the nearest action)."""
    cfg = ScenarioConfig()
    env = gym.make("lawn/Joint-v1").unwrapped
    obs, _ = env.reset(seed=4)
    expert = make_policy("rg-mpc", cfg)
    expert.reset(4)
    anchored = action_codec(cfg, "joint", "rl")
    checked = 0
    for _ in range(30):
        expert.act(obs)
        plan, snap = expert.last_plan, env.snapshot()
        decision = Decisions(plan.increments[:, 0], plan.power_w, plan.drone_position)
        args = (snap.x_aug, snap.reference, snap.drone_position)
        out = anchored.decode(anchored.encode(decision, *args).astype(np.float64), *args)
        centroid = snap.x_aug[:, 0:2].mean(axis=0)
        if np.abs(plan.drone_position - centroid).max() < RL_INTERFACE.drone_offset_m:
            checked += 1
            np.testing.assert_allclose(out.power_w, plan.power_w, rtol=1e-4, atol=1e-7)
            np.testing.assert_allclose(out.drone_next, plan.drone_position, atol=1e-4)
            np.testing.assert_allclose(out.increment, plan.increments[:, 0], atol=1e-4)
        obs, *_ = env.step(expert.action(plan, snap))
    assert checked >= 10


def test_rl_interface_determinism_and_parallel_lockstep():
    par = lawn_env.parallel_env(interface="rl")
    joint = gym.make("lawn/Joint-v1", interface="rl").unwrapped
    obs, _ = par.reset(seed=9)
    jobs, _ = joint.reset(seed=9)
    rng = np.random.default_rng(3)
    k = 4
    while par.agents:
        a = rng.uniform(-1, 1, 3 * k + 2).astype(np.float32)
        obs, rewards, terms, truncs, infos = par.step({"drone": a[2 * k:], **{f"agv_{i}": a[2 * i: 2 * i + 2]
                                                                              for i in range(k)}})
        jobs, jr, jterm, jtrunc, _ = joint.step(a)
        assert np.array_equal(obs["drone"], jobs) and rewards["drone"] == pytest.approx(jr)
        assert terms["drone"] == jterm and truncs["drone"] == jtrunc
        assert all(-RL_INTERFACE.cost_clip / RL_INTERFACE.cost_scale - 1e-12 <= rewards[f"agv_{i}"] <= 0 or terms["drone"]
                   for i in range(k))


def test_the_stake_split_minimizes_the_expected_loss_it_claims_to():
    """The stake prior's split (the RL interface's zero action) is the exact minimizer of
    sum_k w_k (d_k^2 / p_k)^m over splits of P_max (the high-SNR outage its docstring derives it from),
    checked against a numerical minimization; on the true outage gammainc its loss lies between the
    numerical optimum and the equal split's."""
    from scipy import optimize, special

    env = gym.make("lawn/CommRL-v1").unwrapped
    budget = env.config.power_budget_w
    for seed in range(3):
        env.reset(seed=seed)
        for _ in range(5):
            env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        sim, layout = env.sim, env.actions
        window = sim.reference_window()
        decision = layout.decode(np.zeros(layout.size), sim.x_obs, window, sim.drone_position, sim.slot)
        w = layout.mpc.command_stakes(layout.mpc.prepare(sim.x_obs, window, sim.slot))
        w = np.maximum(w, STAKE_FLOOR * w.mean())
        link, k = sim.link, w.size
        d2 = link.distance_sq(decision.drone_next, sim.x_obs[:, 0:2])

        def split(z):
            return budget * np.exp(z) / np.exp(z).sum()

        def best(loss):
            res = optimize.minimize(lambda z: loss(split(z)), np.zeros(k), method="Nelder-Mead",
                                    options={"xatol": 1e-10, "fatol": 1e-16, "maxiter": 20000})
            return loss(split(res.x))

        def surrogate(p):
            return np.sum(w * (d2 / p) ** link.m)

        def expected_loss(p):
            return np.sum(w * special.gammainc(link.m, link.outage_argument_sq(p, d2)))

        assert decision.power_w.sum() == pytest.approx(budget, rel=1e-12)
        assert surrogate(decision.power_w) <= best(surrogate) * (1 + 1e-9)
        optimum, equal = best(expected_loss), expected_loss(np.full(k, budget / k))
        assert optimum * (1 - 1e-9) <= expected_loss(decision.power_w) < equal
