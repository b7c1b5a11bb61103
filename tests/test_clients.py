"""Outside clients run the environments for a few hundred steps, each as its users
call it. Slow (``pytest -m slow``); a client that is not installed is skipped with the reason
(``pip install -e ".[compat]"`` installs TorchRL and Tianshou at versions that work with the
CPU build of torch 2.13.0; ``".[rllib]"`` installs RLlib, which pins Gymnasium 1.2.2, so in an
environment of its own). Every env is named in the ``lawn_env:lawn/...`` form, which registers
the ids in worker processes that never imported ``lawn_env``."""

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def test_cleanrl_style_async_vector_loop():
    """CleanRL's PPO builds ``gym.vector.SyncVectorEnv``/``AsyncVectorEnv`` of ``gym.make`` thunks
    and steps them with autoreset; async workers import nothing but what the id names."""
    import gymnasium as gym

    envs = gym.vector.AsyncVectorEnv([lambda: gym.make("lawn_env:lawn/CommRL-v1") for _ in range(2)],
                                     context="spawn")
    obs, infos = envs.reset(seed=0)
    assert obs.shape == (2, envs.single_observation_space.shape[0])
    finished = 0
    for _ in range(300):
        obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rewards))
        finished += int(np.sum(terminated | truncated))
    envs.close()
    assert finished >= 2  # episodes ended and were reset automatically


def test_rl_zoo3_trains_ppo_from_lawns_hyperparameters(tmp_path):
    """rl-zoo3's command line as the clients page gives it: the ids from ``--gym-packages``, the
    hyperparameters from ``--conf-file training.recipes`` (lawn's own PPO file in rl-zoo3's form)."""
    pytest.importorskip("rl_zoo3", reason="rl-zoo3 not installed (pip install -e '.[compat]')")
    import subprocess
    import sys

    from training.recipes import hyperparams

    assert set(hyperparams) == {"lawn/CommRL-v1", "lawn/JointRL-v1"}
    assert all(h["n_timesteps"] > 0 and "interface" not in h for h in hyperparams.values())
    done = subprocess.run([sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", "lawn/CommRL-v1",
                           "--gym-packages", "lawn_env", "--conf-file", "training.recipes", "-n", "2048",
                           "--eval-freq", "-1", "--seed", "0", "--log-folder", str(tmp_path)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "ppo" / "lawn-CommRL-v1_1" / "lawn-CommRL-v1.zip").exists()
    assert "('normalize', 'dict(norm_obs=True" in done.stdout  # lawn's VecNormalize settings were read


def test_torchrl_gym_env_specs_and_infos():
    pytest.importorskip("torchrl", reason="TorchRL not installed (pip install -e '.[compat]')")
    from torchrl.envs.libs.gym import GymEnv
    from torchrl.envs.utils import check_env_specs

    env = GymEnv("lawn_env:lawn/Comm-v1", num_slots=20)  # TorchRL passes frameskip= first: a TypeError
    env.set_info_dict_reader()  # every info key, read with the reset info's shapes and dtypes
    check_env_specs(env)
    data = env.rollout(200, break_when_any_done=False)
    assert data.batch_size[0] == 200
    assert data["next", "stage_cost"].shape[0] == 200 and data["next", "delivered"].shape[-1] == 4


def test_torchrl_pettingzoo_wrapper_keeps_infos():
    pytest.importorskip("torchrl", reason="TorchRL not installed (pip install -e '.[compat]')")
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    import lawn_env

    env = PettingZooWrapper(lawn_env.parallel_env(num_agvs=2, num_slots=20), use_mask=False)
    data = env.rollout(60, break_when_any_done=False)
    assert data.batch_size[0] == 60


def test_tianshou_vector_env():
    pytest.importorskip("tianshou", reason="Tianshou not installed (pip install -e '.[compat]')")
    import gymnasium as gym
    from tianshou.env import DummyVectorEnv

    envs = DummyVectorEnv([lambda: gym.make("lawn_env:lawn/JointRL-v1") for _ in range(2)])
    for i, space in enumerate(envs.action_space):
        space.seed(i)
    obs, info = envs.reset()
    assert obs.shape == (2,) + envs.observation_space[0].shape
    ended = 0
    for _ in range(200):
        actions = np.stack([envs.action_space[i].sample() for i in range(2)])
        obs, rewards, terminated, truncated, info = envs.step(actions)
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rewards)) and rewards.shape == (2,)
        assert all(i["stage_cost"] >= 0 and 1 <= i["slot"] <= 120 for i in info)
        done = np.flatnonzero(terminated | truncated)
        ended += done.size
        if done.size:
            envs.reset(done)
    assert ended >= 2  # 200 steps of 120-slot episodes (or shorter, terminated): each env ended at least once


def _lawn_parallel(config):
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    import lawn_env  # inside the creator: RLlib's workers are fresh processes

    return ParallelPettingZooEnv(lawn_env.parallel_env(**config))


def test_rllib_multi_agent_ppo_one_iteration():
    """RLlib's multi-agent PPO, a drone policy and a shared AGV policy, one training iteration
    (``ray[rllib]`` pins its own Gymnasium, so it is not part of the ``compat`` extra)."""
    pytest.importorskip("ray.rllib", reason="RLlib not installed (pip install 'ray[rllib]'; it pins Gymnasium 1.2)")
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.tune.registry import register_env

    register_env("lawn_parallel", _lawn_parallel)
    config = (
        PPOConfig()
        .environment("lawn_parallel", env_config={"num_agvs": 2, "num_slots": 20, "interface": "rl"})
        .multi_agent(policies={"drone", "agv"},
                     policy_mapping_fn=lambda agent_id, episode, **kw: "drone" if agent_id == "drone" else "agv")
        .env_runners(num_env_runners=0)
        .training(train_batch_size=120, minibatch_size=60, num_epochs=1)
    )
    ray.init(num_cpus=2, include_dashboard=False, ignore_reinit_error=True)
    try:
        algo = config.build_algo()
        result = algo.train()
        algo.stop()
    finally:
        ray.shutdown()
    assert result["env_runners"]["num_env_steps_sampled_lifetime"] >= 120
