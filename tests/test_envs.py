import re
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lawn_env
from lawn_env import ScenarioConfig

ENV_IDS = list(lawn_env.ENV_IDS)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_check_env(env_id):
    check_env(gym.make(env_id).unwrapped)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_check_env(env_id):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3_checker.check_env(gym.make(env_id), warn=True)


def test_make_without_import_uses_module_prefix():
    code = ("import gymnasium as gym; e = gym.make('lawn_env:lawn/Joint-v1', num_agvs=3); "
            "o, _ = e.reset(seed=0); print(o.shape[0])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    layout = lawn_env.ObservationLayout(ScenarioConfig(num_agvs=3))
    assert int(out.stdout.strip()) == layout.size


def _rollout(env_id, seed, steps=40, **kwargs):
    env = gym.make(env_id, **kwargs)
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    rewards, delivered = [], []
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        out.append(obs)
        rewards.append(r)
        delivered.append(info["delivered"])
    return np.array(out), np.array(rewards), np.array(delivered)


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("path_set", ["paper", "random"])
def test_same_seed_same_episode(env_id, path_set):
    a = _rollout(env_id, 11, reference={"path_set": path_set})
    b = _rollout(env_id, 11, reference={"path_set": path_set})
    c = _rollout(env_id, 12, reference={"path_set": path_set})
    for x, y in zip(a, b):
        assert np.array_equal(x, y)
    assert not np.array_equal(a[0], c[0])


def test_reset_reproduces_episode_in_same_env():
    env = gym.make("lawn/Comm-v1")
    actions = [env.action_space.sample() for _ in range(30)]
    runs = []
    for _ in range(2):
        obs, _ = env.reset(seed=5)
        runs.append([obs] + [env.step(a)[0] for a in actions])
    assert np.array_equal(np.array(runs[0]), np.array(runs[1]))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_bad_actions_raise_clear_errors(env_id):
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    n = env.action_space.shape[0]
    with pytest.raises(ValueError, match="not finite"):
        env.step(np.full(n, np.nan))
    with pytest.raises(ValueError, match=r"outside \[-1, 1\]"):
        env.step(np.full(n, 1.5))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(n + 1))
    with pytest.raises(ValueError, match=f"dtype <U1.*expected real numbers of shape \\({n},\\), float32"):
        env.step(["a"] * n)
    # what Gymnasium's Box.contains rejects is rejected, never reshaped or converted
    for bad, what in ((np.zeros(n, dtype=complex), "complex128"), (np.zeros(n, dtype=bool), "bool"),
                      (np.full(n, "0.5"), "<U3"), (np.array([None] * n), "object")):
        with pytest.raises(ValueError, match=f"dtype {what}"):
            env.step(bad)
    for shape in ((1, n), (n, 1)):
        with pytest.raises(ValueError, match=re.escape(f"shape {shape}; expected ({n},)")):
            env.step(np.zeros(shape))
    env.step([0.0] * n)  # a flat list of numbers is what Gymnasium accepts too
    env.step(np.zeros(n, dtype=np.int64))


def test_step_before_reset_and_after_end():
    env = gym.make("lawn/Joint-v1", num_slots=3).unwrapped
    with pytest.raises(RuntimeError, match="reset"):
        env.step(env.action_space.sample())
    env.reset(seed=0)
    for i in range(3):
        _, _, term, trunc, info = env.step(np.zeros(env.action_space.shape))
        assert not term and trunc == (i == 2)
    assert "episode_metrics" in info
    with pytest.raises(RuntimeError, match="ended"):
        env.step(np.zeros(env.action_space.shape))


def test_bad_config_through_make():
    with pytest.raises(ValueError, match="num_agvs"):
        gym.make("lawn/Joint-v1", num_agvs=0)
    with pytest.raises(ValueError, match="unknown config key 'channel.typo'"):
        gym.make("lawn/Joint-v1", channel={"typo": 1})
    with pytest.raises(ValueError, match="unknown preset"):
        gym.make("lawn/Joint-v1", config="nope")
    with pytest.raises(ValueError, match="render_mode"):
        gym.make("lawn/Joint-v1", render_mode="ascii")


def test_episode_accounting_and_metrics():
    env = gym.make("lawn/Joint-v1")
    env.reset(seed=2)
    total, tracking, effort = 0.0, 0.0, 0.0
    trunc = False
    steps = 0
    while not trunc:
        _, r, _, trunc, info = env.step(env.action_space.sample())
        total += r
        tracking += info["reward_tracking"]
        effort += info["reward_effort"]
        assert r == pytest.approx(info["reward_tracking"] + info["reward_effort"])
        assert info["power_w"].sum() <= env.unwrapped.config.power_budget_w * (1 + 1e-12)
        assert np.all(info["power_w"] >= 0)
        steps += 1
    m = info["episode_metrics"]
    assert steps == 120 and m["slots"] == 120
    assert m["control_cost"] == pytest.approx(-total)
    assert m["tracking_cost"] == pytest.approx(-tracking) and m["effort_cost"] == pytest.approx(-effort)
    assert 0 <= m["outage_rate"] <= 1 and 0 <= m["outage_rate_predicted"] <= 1
    assert m["rmse_m"] > 0 and len(m["rmse_per_agv_m"]) == 4
    traj = env.unwrapped.trajectories()
    steps_m = np.linalg.norm(np.diff(traj["drone_position"], axis=0), axis=1)
    assert steps_m.max() <= 15.0 * 0.5 + 1e-9  # speed limit
    assert m["drone_path_length_m"] == pytest.approx(steps_m.sum())


def test_realized_dynamics_follow_model():
    """A delivered command moves the AGV by A~ x + B~ du; a lost one by A~ x (MODEL.md §3)."""
    env = gym.make("lawn/Joint-v1").unwrapped
    env.reset(seed=4)
    model = env.sim.model
    for _ in range(30):
        x = env.sim.x_aug.copy()
        a = env.action_space.sample()
        _, _, _, _, info = env.step(a)
        du = info["applied_increment"]
        assert np.allclose(env.sim.x_aug, x @ model.a_aug.T + du @ model.b_aug.T)
        requested = np.clip(x[:, 4:6] + a[:8].reshape(4, 2), -2, 2) - x[:, 4:6]
        expected = np.where(info["delivered"][:, None], requested, 0.0)
        assert np.allclose(du, expected, atol=1e-6)
        assert np.all(np.abs(env.sim.x_aug[:, 4:6]) <= 2.0 + 1e-12)


def test_realized_outage_matches_closed_form_over_episodes():
    """The env's own fading sampler against the closed form it reports, over many slots."""
    env = gym.make("lawn/Joint-v1").unwrapped
    predicted, lost = [], []
    for seed in range(15):
        env.reset(seed=seed)
        done = False
        while not done:
            a = env.action_space.sample() * 0.0
            _, _, _, done, info = env.step(a)
            predicted.append(info["outage_probability"])
            lost.append(~info["delivered"])
    predicted, lost = np.concatenate(predicted), np.concatenate(lost)
    sigma = np.sqrt((predicted * (1 - predicted)).sum())
    assert abs(lost.sum() - predicted.sum()) < 5 * sigma


def test_snapshot_contents():
    env = gym.make("lawn/Joint-v1").unwrapped
    env.reset(seed=1)
    for _ in range(7):
        env.step(env.action_space.sample())
    snap = env.snapshot()
    assert snap.x_aug.shape == (4, 6) and snap.reference.shape == (4, 11, 6) and snap.drone_position.shape == (2,)
    assert snap.slot == 7 and snap.config == env.config
    assert np.array_equal(snap.reference, env.sim.reference[:, 7:18])
    snap.x_aug[:] = 0  # a copy: the env is unaffected
    assert not np.allclose(env.sim.x_aug, 0)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_observation_decodes_to_snapshot(env_id):
    env = gym.make(env_id).unwrapped
    obs, _ = env.reset(seed=3)
    env.action_space.seed(3)
    for _ in range(9):
        obs, *_ = env.step(env.action_space.sample())
    dec = env.layout.decode(obs)
    snap = env.snapshot()
    assert np.allclose(dec["x_aug"], snap.x_aug, atol=1e-4)
    assert np.allclose(dec["reference"], snap.reference, atol=1e-4)
    assert np.allclose(dec["drone_position"], snap.drone_position, atol=1e-4)
    assert dec["slot"] == snap.slot
    assert np.allclose(dec["last_power_w"], env.sim.last_power_w, atol=1e-6)
    assert len(env.layout.feature_names()) == env.layout.agv_features + 3


def test_observation_is_order_one_under_a_reasonable_policy():
    """Normalization check: a hovering drone at the center, equal power, no increments."""
    env = gym.make("lawn/Comm-v1").unwrapped
    obs, _ = env.reset(seed=0)
    worst = np.abs(obs).max()
    for _ in range(120):
        q = env.sim.drone_position
        a = np.concatenate([np.zeros(4), np.clip((np.array([100.0, 100.0]) - q) / 7.5, -1, 1)])
        obs, *_ = env.step(a)
        worst = max(worst, np.abs(obs).max())
    assert worst < 4  # measured: 2.84 (a feature far above one would dominate a network's input)


@pytest.mark.parametrize("law", ["paper", "delivery-certainty-equivalent", "delivery"])
def test_comm_env_applies_the_mpc_first_increment(law):
    """control.law="paper": the QP at each link's planned psi; "delivery-certainty-equivalent": the same QP
    at psi = 1 (the command as if it arrives); "delivery": the loss-aware tail's command at the fleet's
    psi-bar (lawn_env.tail.DeliveryLaw, with the reference backend); the links and the planned psi in
    info as they are."""
    env = gym.make("lawn/Comm-v1", control={"law": law}).unwrapped
    env.reset(seed=6)
    env.action_space.seed(6)
    from lawn_env.mpc import OutageAwareMPC
    from lawn_env.tail import DeliveryLaw

    independent = OutageAwareMPC.from_config(env.config, backend="osqp")
    lossy = DeliveryLaw(env.config, backend="daqp")
    for _ in range(15):
        a = env.action_space.sample()
        x = env.sim.x_aug.copy()
        ref = env.sim.reference_window().copy()
        power = lawn_env.spaces.DirectActions(env.config, "comm").decode(a, x, ref, env.sim.drone_position).power_w
        q_next = env.sim.drone_target(a[4:].astype(float) * env.config.drone.max_speed_mps)
        psi = env.sim.planning_success(power, q_next)
        if law == "delivery":
            expected = lossy.solve(x, ref, psi, int(np.asarray(env.sim.slot).reshape(-1)[0])).increments[:, 0]
        else:
            expected = independent.solve(x, ref, psi if law == "paper" else np.ones_like(psi)).increments[:, 0]
        _, _, _, _, info = env.step(a)
        assert np.allclose(info["success_probability_planned"], psi) and np.all(psi < 1.0)
        applied = np.where(info["delivered"][:, None], expected, 0.0)
        assert np.allclose(info["applied_increment"], applied, atol=1e-6)
        assert info["mpc_fallbacks"] == 0


@pytest.mark.parametrize("env_id", ["lawn/Comm-v1", "lawn/CommRL-v1"])
def test_under_measurement_noise_the_comm_mpc_plans_from_the_measured_state(env_id):
    """The MPC that drives the AGVs plans from what a planner on the drone has, the measured state
    (the snapshot's), and is the RL interface's anchor MPC (one per env): its increments are an
    independent MPC's from the snapshot, not from the true state, which differs by the noise."""
    from lawn_env.mpc import OutageAwareMPC

    noise = {"measurement_noise_position_m": 0.5, "measurement_noise_velocity_mps": 0.2}
    env = gym.make(env_id, disturbance=noise).unwrapped
    env.reset(seed=3)
    anchor = env.actions.mpc
    assert (anchor is env.mpc) if env_id == "lawn/CommRL-v1" else anchor is None
    independent = OutageAwareMPC.from_config(env.config, backend="daqp")
    codec = lawn_env.action_codec(env.config, "comm", env.interface)  # its own MPC, warm-started apart
    rng = np.random.default_rng(3)
    for _ in range(10):
        snap = env.snapshot()
        assert not np.allclose(snap.x_aug, env.sim.x_aug)  # the noise is there
        a = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        decision = codec.decode(a, snap.x_aug, snap.reference, snap.drone_position, snap.slot)
        psi = env.sim.planning_link.success_sq(decision.power_w, env.sim.planning_link.distance_sq(
            decision.drone_next, snap.x_aug[:, 0:2]))
        expected = independent.solve(snap.x_aug, snap.reference, psi, snap.slot).increments[:, 0]
        _, _, _, _, info = env.step(a)
        np.testing.assert_allclose(info["success_probability_planned"], psi, rtol=1e-6)  # the prior's stakes: QPs warm-started apart
        applied = np.where(info["delivered"][:, None], expected, 0.0)
        np.testing.assert_allclose(info["applied_increment"], applied, atol=1e-6)


def test_ce_error_raises_outage():
    base = gym.make("lawn/Joint-v1", channel={"rate_threshold_bps_hz": 1.0}).unwrapped
    ce = gym.make("lawn/Joint-v1", channel={"rate_threshold_bps_hz": 1.0, "ce_error_var": 0.05}).unwrapped
    out = []
    for env in (base, ce):
        env.reset(seed=0)
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape))
        out.append(info["outage_probability"])
    assert np.all(out[1] > out[0])
    # closed form with the CE floor: the planning link of a CSI-unaware planner ignores it
    unaware = lawn_env.channel.LinkParams.from_config(
        ce.config.override({"channel.ce_aware_planning": False}), planning=True)
    assert unaware.ce_error_var == 0.0 and ce.sim.planning_link.ce_error_var == 0.05


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_render_rgb_array(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8 and frame.std() > 0
    env.close()


def test_k32_random_paths_runs():
    env = gym.make("lawn/Joint-v1", config="k32")
    obs, _ = env.reset(seed=0)
    env.action_space.seed(0)
    assert obs.shape == env.observation_space.shape
    for _ in range(5):
        obs, r, *_ = env.step(env.action_space.sample())
    assert np.isfinite(obs).all() and np.isfinite(r)


# -- Gymnasium's versioning: the v0 ids stay registered beside the current ones ------------------

def _random_episode_return(env_id: str, seed: int) -> float:
    env = gym.make(env_id, config="disturbed")
    env.reset(seed=seed)
    rng = np.random.default_rng(1)
    total, done = 0.0, False
    while not done:
        action = rng.uniform(env.action_space.low, env.action_space.high).astype(env.action_space.dtype)
        _, reward, terminated, truncated, _ = env.step(action)
        total += float(reward)
        done = terminated or truncated
    return total


@pytest.mark.parametrize("env_id", list(lawn_env.LEGACY_ENV_IDS))
def test_v0_ids_stay_registered_and_warn_out_of_date(env_id):
    with pytest.warns(DeprecationWarning, match=f"{env_id} is out of date"):
        env = gym.make(env_id)
    base, kwargs = lawn_env.LEGACY_ENV_IDS[env_id]
    assert type(env.unwrapped) is type(gym.make(base).unwrapped)
    assert {k: getattr(env.unwrapped, k) for k in kwargs if k != "interface"} == \
        {k: v for k, v in kwargs.items() if k != "interface"}
    assert gym.spec(env_id).vector_entry_point is None  # make_vec steps v0 scenarios with their own generators


def test_comm_v0_keeps_its_recorded_episode_under_measurement_noise():
    # The return of this episode under the code before the MPC planned from the measured state (recorded
    # again when every product moved to one fixed summation order, lawn_env.products, the same on every
    # machine): lawn/Comm-v0 still gives it bit for bit, lawn/Comm-v1 differs.
    with pytest.warns(DeprecationWarning):
        v0 = _random_episode_return("lawn/Comm-v0", seed=3)
    assert v0 == -17739840.10413076
    assert _random_episode_return("lawn/Comm-v1", seed=3) != v0


def test_joint_v0_make_vec_is_gymnasiums_sync_vector_env():
    with pytest.warns(DeprecationWarning):
        envs = gym.make_vec("lawn/Joint-v0", num_envs=2)
    assert isinstance(envs, gym.vector.SyncVectorEnv)
    assert type(gym.make_vec("lawn/Joint-v1", num_envs=2)).__name__ == "JointVectorEnv"


def test_a_run_recorded_under_a_v0_id_plays_its_current_version(tmp_path):
    from agents.runs import AgentRecord, RunDir

    for legacy, (current, _) in lawn_env.LEGACY_ENV_IDS.items():
        assert RunDir(tmp_path, AgentRecord(**{"env": legacy, "algo": "ppo"})).env == current
    assert RunDir(tmp_path, AgentRecord(**{"env": "lawn/Comm-v1", "algo": "ppo"})).env == "lawn/Comm-v1"
    assert RunDir(tmp_path, AgentRecord(**{"env": lawn_env.PARALLEL_ENV_ID, "algo": "ppo"})).env == lawn_env.PARALLEL_ENV_ID


def test_every_env_id_has_one_role_from_one_table():
    """The role of an env id (what its actions decide) comes from ``lawn_env.ENV_ROLES`` alone, for the
    central, RL, earlier and multi-agent ids; the role's central id inverts it; an unknown id is named."""
    ids = {**{e: e for e in lawn_env.ENV_IDS}, **lawn_env.RL_ENV_IDS,
           **{e: base for e, (base, _) in lawn_env.LEGACY_ENV_IDS.items()}, **lawn_env.PARALLEL_ENV_IDS}
    for env_id, central in ids.items():
        role = lawn_env.env_role(env_id)
        assert role == lawn_env.ENV_ROLES[central] and lawn_env.role_env_id(role) == central
    for env_id in (*lawn_env.ENV_IDS, *lawn_env.RL_ENV_IDS):
        assert gym.make(env_id).unwrapped.role == lawn_env.env_role(env_id)
    with pytest.raises(ValueError, match=r"unknown env id 'lawn/Nope-v1'; known: lawn/Joint-v1"):
        lawn_env.env_role("lawn/Nope-v1")
    with pytest.raises(ValueError, match=r"role='both'; valid: joint, comm"):
        lawn_env.role_env_id("both")
