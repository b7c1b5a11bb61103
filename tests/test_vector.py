"""The native vector env: lockstep with the single env, Gymnasium's vector
conventions, spaces, errors."""

import gymnasium as gym
import numpy as np
import pytest

import lawn_env
from lawn_env import ScenarioConfig, channel
from lawn_env.core import SlotDraws, draw_slot

N = 4


def _make(num_envs=N, env_id="lawn/Joint-v1", **kwargs):
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)


def _single_runs(env_id, config, seeds, actions, **kwargs):
    """Run one single env per seed on its column of ``actions`` (T, N, size) until its episode
    ends, recording the slot draws it makes from its own generator and what it returns."""
    runs = []
    for i, seed in enumerate(seeds):
        env = gym.make(env_id, config=config, **kwargs)
        sim = env.unwrapped.engine.sim
        draws, real = [], sim.draw
        sim.draw = lambda rng, real=real, draws=draws: draws.append(real(rng)) or draws[-1]
        obs, info = env.reset(seed=seed)
        steps = [(obs, 0.0, False, False, info)]
        for a in actions[:, i]:
            steps.append(env.step(a))
            if steps[-1][2] or steps[-1][3]:
                break
        runs.append((draws, steps))
    return runs


def _stacked_draws(runs, t):
    """Slot t's draws of every single run stacked into one batch (a run that has ended: its last)."""
    rows = [draws[min(t, len(draws) - 1)] for draws, _ in runs]
    return SlotDraws(*[None if rows[0][j] is None else np.concatenate([r[j] for r in rows])
                       for j in range(len(SlotDraws._fields))])


def _assert_info_equal(got, want, i=None):
    for key, value in want.items():
        if key == "episode_metrics":
            continue
        np.testing.assert_array_equal(got[key] if i is None else got[key][i], value, err_msg=key)


def _lockstep(env_id, config, actions, seed, **kwargs):
    """Env i of the vector env, fed the single envs' draws, returns bit for bit what the single
    env reset with seed + i returns, for its whole episode (observations, rewards, flags, infos);
    returns the number of episodes that were terminated."""
    n = actions.shape[1]
    runs = _single_runs(env_id, config, [seed + i for i in range(n)], actions, **kwargs)
    envs = _make(num_envs=n, env_id=env_id, config=config, **kwargs)
    t_now = [0]
    envs.unwrapped._draw = lambda: _stacked_draws(runs, t_now[0])
    obs, info = envs.reset(seed=seed)
    for i, (_, steps) in enumerate(runs):
        np.testing.assert_array_equal(obs[i], steps[0][0])
        _assert_info_equal(info, steps[0][4], i)
    live, terminated_any = np.ones(n, dtype=bool), 0
    for t in range(actions.shape[0]):
        obs, reward, terminated, truncated, info = envs.step(actions[t])
        t_now[0] += 1
        for i in np.flatnonzero(live):
            s_obs, s_reward, s_term, s_trunc, s_info = runs[i][1][t + 1]
            np.testing.assert_array_equal(obs[i], s_obs)
            assert reward[i] == s_reward and (terminated[i], truncated[i]) == (s_term, s_trunc)
            _assert_info_equal(info, s_info, i)
            if s_term or s_trunc:
                live[i] = False
                terminated_any += int(s_term)
                assert info["_episode_metrics"][i] and info["episode_metrics"][i] == s_info["episode_metrics"]
                assert info["episode_control_cost"][i] == s_info["episode_metrics"]["control_cost"]
        if not live.any():
            break
    assert not live.any()
    return terminated_any


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
@pytest.mark.parametrize("config", [ScenarioConfig(num_slots=30), ScenarioConfig(num_agvs=5, num_slots=30)],
                         ids=["paper-paths", "random-paths"])
def test_lockstep_with_the_single_envs_on_their_draws(config, env_id):
    """Env i of the vector env reset with seed s equals the single env reset with s + i, bit for
    bit, for a whole episode, when it gets the single env's slot draws (Comm-v1: the compiled QP
    solver's answers depend only on each problem's own data and warm start)."""
    rng = np.random.default_rng(0)
    size = (1 if env_id == "lawn/Comm-v1" else 3) * config.num_agvs + 2
    _lockstep(env_id, config, rng.uniform(-1, 1, (config.num_slots, N, size)).astype(np.float32), 10)


@pytest.mark.parametrize("env_id", sorted(lawn_env.ENV_IDS) + sorted(lawn_env.RL_ENV_IDS))
@pytest.mark.parametrize("preset", ["default", "k8", "disturbed"])
def test_one_env_of_the_vector_env_is_the_single_env(env_id, preset):
    """``make_vec(id, num_envs=1)`` reset with seed s and ``make(id)`` reset with seed s give bit for
    bit the same observations, rewards, flags and infos for whole episodes under the same actions,
    autoresets included: the same engine, the same generator, the same draws."""
    config = lawn_env.presets.get(preset).override(num_slots=12)
    single = gym.make(env_id, config=config)
    envs = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", config=config)
    rng = np.random.default_rng(7)
    actions = rng.uniform(-1, 1, (30,) + single.action_space.shape).astype(np.float32)
    obs, info = single.reset(seed=4)
    v_obs, v_info = envs.reset(seed=4)
    np.testing.assert_array_equal(v_obs[0], obs)
    _assert_info_equal(v_info, info, 0)
    restart = False
    for a in actions:
        v_obs, v_reward, v_term, v_trunc, v_info = envs.step(a[None])
        if restart:  # the vector env's next-step autoreset is the single env's reset() without a seed
            obs, info = single.reset()
            assert v_reward[0] == 0.0 and not (v_term[0] or v_trunc[0])
        else:
            obs, reward, term, trunc, info = single.step(a)
            assert (v_reward[0], v_term[0], v_trunc[0]) == (reward, term, trunc)
            if term or trunc:
                assert v_info["episode_metrics"][0] == info["episode_metrics"]
        np.testing.assert_array_equal(v_obs[0], obs)
        _assert_info_equal(v_info, info, 0)
        restart = not restart and bool(v_term[0] or v_trunc[0])


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_next_step_autoreset_truncation_and_seeding(env_id):
    envs = _make(env_id=env_id, config=ScenarioConfig(num_slots=5))
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
    obs, info = envs.reset(seed=3)
    assert obs.shape == (N, envs.single_observation_space.shape[0]) and obs.dtype == np.float32
    assert envs.observation_space.contains(obs) and set(info) >= set(lawn_env.envs.base.INFO_KEYS)
    zero = np.zeros(envs.action_space.shape, dtype=np.float32)
    for _ in range(4):
        _, reward, terminated, truncated, _ = envs.step(zero)
        assert not truncated.any() and (reward < 0).all()
    _, _, _, truncated, info = envs.step(zero)
    assert truncated.all() and (info["slot"] == 5).all()
    obs, reward, terminated, truncated, info = envs.step(zero)  # the autoreset step
    assert (reward == 0).all() and not truncated.any() and not terminated.any() and (info["slot"] == 0).all()
    # each restarted env drew its second episode's initial offsets from its own generator (seed 3 + i),
    # right after the first episode's: the next N(0, 3 m) draws, around the fixed paths' start; env 0's
    # generator is the env's own, which drew the 5 slots' randomness of every env in between
    sim = envs.unwrapped.sim
    for i in range(N):
        rng = np.random.default_rng(3 + i)
        rng.normal(0.0, 3.0, (4, 2))  # the first episode's offsets
        for _ in range(5 if i == 0 else 0):
            draw_slot(rng, sim.params, N)
        offsets = rng.normal(0.0, 3.0, (4, 2))
        np.testing.assert_array_equal(sim.x_aug[i, :, 0:2], np.clip(sim.params.fixed_reference[:, 0, 0:2] + offsets, 0, 200))
    # the same seed gives the same numbers; a list of seeds sets each env
    a, _ = _make(env_id=env_id).reset(seed=7)
    b, _ = _make(env_id=env_id).reset(seed=[7, 8, 9, 10])
    np.testing.assert_array_equal(a, b)


def test_comm_vector_env_reports_its_qps_and_matches_the_one_by_one_solver():
    """Comm-v1's vector env: per-env MPC info with a leading env axis, the same keys as the
    single env's, and the compiled solver's episode equal to DAQP's (one QP at a time) to 1e-6."""
    config = ScenarioConfig(num_slots=12)
    single = gym.make("lawn/Comm-v1", config=config)
    _, single_info = single.reset(seed=0)
    runs = {}
    for backend in ("compiled", "daqp"):
        envs = _make(env_id="lawn/Comm-v1", config=config, qp_backend=backend)
        assert envs.single_action_space == single.action_space
        assert envs.single_observation_space == single.observation_space
        _, info = envs.reset(seed=0)
        assert set(info) >= set(single_info)
        rewards = []
        for t in range(12):
            action = np.tile(np.linspace(-0.5, 0.5, 6, dtype=np.float32), (N, 1))
            _, reward, _, _, info = envs.step(action)
            rewards.append(reward)
            assert info["mpc_iterations"].shape == (N, 4) and info["mpc_fallbacks"].shape == (N,)
            assert info["success_probability_planned"].shape == (N, 4) and not info["mpc_fallbacks"].any()
        runs[backend] = np.array(rewards)
    np.testing.assert_allclose(runs["compiled"], runs["daqp"], rtol=1e-6)
    with pytest.raises(ValueError, match="unknown QP backend 'batched'; valid: compiled, daqp, osqp"):
        _make(env_id="lawn/Comm-v1", qp_backend="batched")


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_bad_actions_name_the_env_index_and_the_expected_shape(env_id):
    envs = _make(env_id=env_id)
    envs.reset(seed=0)
    good = np.zeros(envs.action_space.shape, dtype=np.float32)
    bad = good.copy()
    bad[2, 5] = np.nan
    with pytest.raises(ValueError, match="env 2: action entry 5"):
        envs.step(bad)
    bad = good.copy()
    bad[3, 0] = 1.5
    with pytest.raises(ValueError, match="env 3"):
        envs.step(bad)
    with pytest.raises(ValueError, match=f"expected \\({N}, {good.shape[1]}\\)"):
        envs.step(good[:, :-1])
    with pytest.raises(ValueError, match="dtype"):
        envs.step(good.astype(complex))


def test_renders_the_chosen_env_with_its_trails():
    envs = _make(config=ScenarioConfig(num_slots=4), render_mode="rgb_array", render_env=2)
    envs.reset(seed=0)
    zero = np.zeros(envs.action_space.shape, dtype=np.float32)
    for _ in range(3):
        envs.step(zero)
    frame = envs.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    trail = envs.unwrapped.engine.trail
    assert len(trail.trajectories()["agv_position"]) == 4 and trail.view.slot == 3
    np.testing.assert_array_equal(trail.view.x_aug, envs.unwrapped.sim.x_aug[2])
    envs.step(zero), envs.step(zero)  # the end, then the autoreset: the trails start over
    assert len(trail.trajectories()["drone_position"]) == 1
    with pytest.raises(ValueError, match="render_env=9"):
        _make(render_mode="rgb_array", render_env=9)
    with pytest.raises(ValueError, match="render_mode='human'"):
        _make(render_mode="human")


@pytest.mark.parametrize("env_id", ["lawn/JointRL-v1", "lawn/CommRL-v1"])
def test_rl_ids_have_native_vector_envs_on_the_rl_interface(env_id):
    envs = gym.make_vec(env_id, num_envs=2)  # the vector entry point is the default mode
    single = gym.make(env_id)
    assert envs.unwrapped.interface == single.unwrapped.interface == lawn_env.RL_INTERFACE
    assert envs.single_observation_space == single.observation_space
    envs.reset(seed=0)
    _, reward, *_ = envs.step(np.zeros(envs.action_space.shape, dtype=np.float32))
    assert reward.shape == (2,) and (reward <= 0).all() and (reward >= lawn_env.RL_INTERFACE.reward_floor).all()


def test_unsupported_settings_are_refused_not_ignored():
    with pytest.raises(ValueError, match="interface='fast'"):
        _make(interface="fast")
    with pytest.raises(ValueError, match="num_envs"):
        _make(num_envs=0)


def test_same_step_autoreset_puts_the_final_observation_in_info():
    from lawn_env.envs.vector import JointVectorEnv

    envs = JointVectorEnv(N, config=ScenarioConfig(num_slots=3), autoreset_mode="SameStep")
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    first, _ = envs.reset(seed=1)
    zero = np.zeros(envs.action_space.shape, dtype=np.float32)
    envs.step(zero), envs.step(zero)
    obs, reward, terminated, truncated, info = envs.step(zero)
    assert truncated.all() and info["_final_obs"].all() and (reward < 0).all()
    assert (info["final_obs"][:, -1] == 1.0).all() and (obs[:, -1] == 0.0).all()  # time n/N: 1 at the end, 0 anew
    with pytest.raises(ValueError, match="autoreset_mode"):
        JointVectorEnv(N, autoreset_mode="Disabled")


def test_sb3_trains_on_the_native_vector_env(tmp_path):
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import VecMonitor

    from training.sb3 import NativeVecEnv
    from training.spec import TrainSpec
    from training.train import train

    venv = VecMonitor(NativeVecEnv(ScenarioConfig(num_slots=4), 2))
    venv.seed(0)
    venv.reset()
    for _ in range(4):
        obs, reward, done, infos = venv.step(np.zeros((2, venv.action_space.shape[0]), dtype=np.float32))
    assert done.all() and infos[0]["TimeLimit.truncated"] and "episode" in infos[0]
    assert infos[0]["terminal_observation"].shape == obs[0].shape and obs[0][-1] == 0.0
    summary = train(TrainSpec(algo="ppo", env_id="lawn/Joint-v1", config=ScenarioConfig(num_slots=12), timesteps=256,
                              seed=0, out_dir=tmp_path / "run", n_envs=4,
                              hp_overrides={"n_steps": 32, "batch_size": 64, "n_epochs": 1}, eval_every=128,
                              eval_episodes=1, checkpoint_every=128, progress=False, interface="v0", vec="native"))
    assert summary.timesteps == 256 and summary.best_validation_cost > 0
    # the training protocol's default (the RL interface) on Comm-v1's native vector env
    summary = train(TrainSpec(algo="ppo", env_id="lawn/Comm-v1", config=ScenarioConfig(num_slots=12), timesteps=128,
                              seed=0, out_dir=tmp_path / "comm", n_envs=4,
                              hp_overrides={"n_steps": 32, "batch_size": 64, "n_epochs": 1}, eval_every=128,
                              eval_episodes=1, checkpoint_every=128, progress=False, vec="native"))
    assert summary.timesteps == 128 and summary.best_validation_cost > 0
    with pytest.raises(ValueError, match="native"):
        TrainSpec(algo="ppo", env_id="lawn/Parallel-v0", config=ScenarioConfig(num_slots=12), timesteps=64, seed=0,
                  out_dir=tmp_path / "rl", n_envs=2, progress=False, vec="native")


@pytest.mark.parametrize("env_id, anchor", [("lawn/Joint-v1", {}), ("lawn/Comm-v1", {}),
                                             ("lawn/Joint-v1", {"power_anchor": "distance", "increment_anchor": "lqr"})])
def test_rl_interface_lockstep_with_the_single_env(env_id, anchor):
    """With the RL interface (anchored actions, scaled reward, termination, clipped features) env i
    of the vector env equals the single RL env on seed s + i, bit for bit, until its episode ends."""
    iface = {"base": "rl", "termination_distance_m": 4.0, **anchor}  # tight, so that some env is terminated
    rng = np.random.default_rng(3)
    size = (1 if env_id == "lawn/Comm-v1" else 3) * 4 + 2
    actions = rng.uniform(-1, 1, (30, N, size)).astype(np.float32)
    actions[:, 1] *= 0.1  # env 1 stays on track, the others may be terminated
    assert _lockstep(env_id, ScenarioConfig(num_slots=30), actions, 20, interface=iface) > 0


@pytest.mark.parametrize("env_id, interface", [("lawn/Joint-v1", "v0"), ("lawn/Comm-v1", "v0"), ("lawn/Joint-v1", "rl")])
def test_disturbance_mode_lockstep_with_the_single_env(env_id, interface):
    """The disturbed preset (wind and gusts, control period 2 with period-aware planning, actuator
    lag, process and measurement noise): env i equals the single env on seed s + i bit for bit when
    both see the same draws (the single env's, :func:`lawn_env.core.draw_slot`'s order)."""
    config = lawn_env.presets.get("disturbed").override({"num_slots": 20})
    size = (1 if env_id == "lawn/Comm-v1" else 3) * 4 + 2
    actions = np.random.default_rng(5).uniform(-1, 1, (20, N, size)).astype(np.float32)
    _lockstep(env_id, config, actions, 30, interface=interface)


# ---------------------------------------------------------------------- gaps a test audit found
@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_seeding_a_list_of_the_wrong_length_and_none(env_id):
    envs = _make(env_id=env_id, config=ScenarioConfig(num_slots=6))
    with pytest.raises(ValueError, match=f"a list of 3 seeds for {N} envs"):
        envs.reset(seed=[1, 2, 3])
    twin = _make(env_id=env_id, config=ScenarioConfig(num_slots=6))
    zero = np.zeros(envs.action_space.shape, dtype=np.float32)
    for e in (envs, twin):  # a seeded reset, then unseeded resets continue from its generator
        e.reset(seed=4)
        e.step(zero)
    a, _ = envs.reset(seed=None)
    b, _ = twin.reset(seed=None)
    np.testing.assert_array_equal(a, b)
    assert envs.observation_space.contains(a)
    fresh = [_make(env_id=env_id).reset()[0] for _ in range(2)]  # never seeded: the OS's entropy
    assert not np.array_equal(fresh[0], fresh[1])


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_step_and_render_before_reset_are_refused(env_id):
    envs = _make(env_id=env_id, render_mode="rgb_array")
    with pytest.raises(RuntimeError, match="reset"):
        envs.step(np.zeros(envs.action_space.shape, dtype=np.float32))
    with pytest.raises(RuntimeError, match="reset"):
        envs.render()
    single = gym.make(env_id, render_mode="rgb_array")
    with pytest.raises(RuntimeError, match="reset"):
        single.unwrapped.step(np.zeros(single.action_space.shape, dtype=np.float32))
    with pytest.raises(RuntimeError, match="reset"):
        single.unwrapped.render()


def _comm_reset_psi(envs, i):
    """What Comm's info reports as ``success_probability_planned`` at the start of env i's
    episode: psi of the planning link at equal power from the drone's start."""
    sim, cfg = envs.unwrapped.sim, envs.unwrapped.config
    link = channel.LinkParams.from_config(cfg, planning=True)
    power = np.full(cfg.num_agvs, cfg.power_budget_w / cfg.num_agvs)
    return link.success_sq(power, link.distance_sq(np.asarray(cfg.drone.start_m, float), sim.x_aug[i, :, 0:2]))


def test_comm_info_on_the_next_step_autoreset_describes_the_new_episode():
    envs = _make(env_id="lawn/Comm-v1", config=ScenarioConfig(num_slots=3))
    envs.reset(seed=2)
    rng = np.random.default_rng(2)
    for _ in range(3):
        _, _, _, truncated, info = envs.step(rng.uniform(-1, 1, envs.action_space.shape).astype(np.float32))
    assert truncated.all() and (info["mpc_iterations"] > 0).any()
    _, reward, _, _, info = envs.step(rng.uniform(-1, 1, envs.action_space.shape).astype(np.float32))
    assert (reward == 0).all() and (info["slot"] == 0).all()
    assert (info["mpc_iterations"] == 0).all() and (info["mpc_fallbacks"] == 0).all()
    for i in range(N):
        np.testing.assert_allclose(info["success_probability_planned"][i], _comm_reset_psi(envs, i), rtol=1e-12)


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
def test_same_step_autoreset_on_termination_and_for_comm(env_id):
    """SameStep: the step that ends an episode, by truncation or by the RL interface's
    termination, returns the new episode's first observation, the final one in info, and infos
    (Comm's MPC keys included) describing the step that ended it."""
    from lawn_env.envs.vector import CommVectorEnv, JointVectorEnv

    cls = CommVectorEnv if env_id == "lawn/Comm-v1" else JointVectorEnv
    iface = {"base": "rl", "termination_distance_m": 3.0}  # the 3 m offsets end some episodes at once
    envs = cls(8, config=ScenarioConfig(num_slots=4), interface=iface, autoreset_mode="SameStep")
    envs.reset(seed=0)
    zero = np.zeros(envs.action_space.shape, dtype=np.float32)
    ended_by = {"terminated": 0, "truncated": 0}
    for _ in range(8):
        obs, reward, terminated, truncated, info = envs.step(zero)
        ended = terminated | truncated
        assert not (terminated & truncated).any()
        ended_by["terminated"] += int(terminated.sum())
        ended_by["truncated"] += int(truncated.sum())
        if ended.any():
            np.testing.assert_array_equal(info["_final_obs"], ended)
            assert (obs[ended, -1] == 0.0).all() and (info["final_obs"][ended, -1] > 0.0).all()
            assert (info["slot"][ended] > 0).all()  # the info is the ending step's
            assert (reward[terminated] < envs.interface.reward_floor).all()  # the floor of the slots not played
            if env_id == "lawn/Comm-v1":
                assert (info["mpc_iterations"][ended] > 0).any()
    assert ended_by["terminated"] > 0 and ended_by["truncated"] > 0


@pytest.mark.parametrize("env_id", ["lawn/Joint-v1", "lawn/Comm-v1"])
@pytest.mark.parametrize("config", [ScenarioConfig(num_slots=8), ScenarioConfig(num_agvs=5, num_slots=8),
                                    ScenarioConfig(num_slots=8).override(**{"disturbance.wind_gust_std_mps": 1.0,
                                               "disturbance.process_noise_position_m": 0.1,
                                               "disturbance.measurement_noise_position_m": 0.2})],
                         ids=["paper-paths", "random-paths", "disturbed"])
def test_the_same_seed_gives_the_same_episodes_from_the_envs_own_generators(env_id, config):
    """Determinism with nothing replaced: the vector env's and the single env's own seeded
    generators, twice, give bitwise the same observations, rewards and infos (autoresets included)."""
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, (12, N, (1 if env_id == "lawn/Comm-v1" else 3) * config.num_agvs + 2))
    actions = actions.astype(np.float32)

    def vector_run():
        envs = _make(env_id=env_id, config=config)
        out = [envs.reset(seed=9)]
        out += [envs.step(a) for a in actions]
        return out

    def single_run():
        env = gym.make(env_id, config=config)
        out = [env.reset(seed=9)]
        for a in actions[:, 0]:
            step = env.step(a)
            out.append(step)
            if step[2] or step[3]:
                out.append(env.reset())
        return out

    for run in (vector_run, single_run):
        first, second = run(), run()
        assert len(first) == len(second)
        for x, y in zip(first, second, strict=True):
            for u, v in zip(x, y, strict=True):
                if isinstance(u, dict):
                    assert u.keys() == v.keys()
                    for key in u:
                        if isinstance(u[key], dict):
                            assert u[key] == v[key]
                        else:
                            np.testing.assert_array_equal(u[key], v[key], err_msg=key)
                else:
                    np.testing.assert_array_equal(u, v)
