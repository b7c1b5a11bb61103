"""Learned policies (Stable-Baselines3 run directories) behind the common policy protocol.

``make_policy("sb3:DIR", config)`` loads ``DIR/model.zip`` with its normalization statistics;
``bc:DIR`` is the same for behaviour-cloned policies (saved in SB3's format); ``marl:DIR`` runs a
parameter-shared multi-agent policy on ``lawn/Joint-v0``. torch and SB3 are imported only here,
when such a policy is built.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np

from lawn_env import ScenarioConfig

from .errors import MissingExtra
from .policies import COMM, JOINT, Policy

__all__ = ["SB3Policy", "MARLPolicy", "LOADERS"]


def _read_run(path: Path) -> dict:
    path = Path(path)
    if not (path / "run.json").exists() or not (path / "model.zip").exists():
        raise ValueError(f"{path} is not a lawn train run directory (needs run.json and model.zip)")
    return json.loads((path / "run.json").read_text())


def _load_model(path: Path, algo: str):
    try:
        from stable_baselines3 import A2C, PPO, SAC, TD3
    except ImportError:  # exercised only without the extra
        raise MissingExtra("trained agents need the rl extra: bash scripts/setup.sh full, "
                           "or pip install torch==2.13.0 && pip install -e '.[rl]'") from None
    import torch

    torch.set_num_threads(1)  # small networks, one observation at a time
    classes = {"ppo": PPO, "sac": SAC, "td3": TD3, "a2c": A2C}
    if algo not in classes:
        raise ValueError(f"{path}: unknown algorithm {algo!r} in run.json")
    return classes[algo].load(str(Path(path) / "model.zip"), device="cpu")


def _load_normalizer(path: Path):
    norm = Path(path) / "vecnormalize.pkl"
    if not norm.exists():
        return None
    with open(norm, "rb") as fh:
        stats = pickle.load(fh)
    stats.training = False
    return stats


class SB3Policy(Policy):
    """A trained SB3 agent: normalizes observations as in training, acts deterministically."""

    name = "sb3"
    env_ids = (JOINT, COMM)

    def __init__(self, path, config: ScenarioConfig | None = None, env_id: str | None = None, seed: int | None = None):
        self.path = Path(path)
        run = _read_run(self.path)
        trained_config = ScenarioConfig.from_dict(json.loads((self.path / "config.json").read_text()))
        trained_env = run["env"]
        if trained_env not in self.env_ids:
            raise ValueError(f"{self.path} was trained on {trained_env}; use marl:{self.path} for multi-agent runs")
        env_id = env_id or trained_env
        if env_id != trained_env:
            raise ValueError(f"{self.path} was trained on {trained_env}, not {env_id}")
        super().__init__(config if config is not None else trained_config, env_id, seed)
        self.algo = run.get("target", run["algo"])
        self.model = _load_model(self.path, self.algo)
        self.normalizer = _load_normalizer(self.path)
        expected = self.model.observation_space.shape
        if expected != (self.layout.size,):
            raise ValueError(f"{self.path} expects observations of shape {expected}; this scenario gives "
                             f"({self.layout.size},): evaluate it with its training config ({self.path / 'config.json'})")

    def act(self, obs) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float32)
        if self.normalizer is not None:
            x = self.normalizer.normalize_obs(x)
        action, _ = self.model.predict(x, deterministic=True)
        return np.clip(action, -1.0, 1.0).astype(np.float32)


class MARLPolicy(Policy):
    """A parameter-shared multi-agent policy driving ``lawn/Joint-v0`` from the central observation:
    each agent's observation is rebuilt as SuperSuit built it in training, and the AGVs' increments
    and the drone's power and move are assembled into the joint action."""

    name = "marl"
    env_ids = (JOINT,)

    def __init__(self, path, config: ScenarioConfig | None = None, env_id: str | None = None, seed: int | None = None):
        self.path = Path(path)
        run = _read_run(self.path)
        if run["env"] != "lawn/Parallel-v0":
            raise ValueError(f"{self.path} was trained on {run['env']}, not the multi-agent env; use sb3:{self.path}")
        trained_config = ScenarioConfig.from_dict(json.loads((self.path / "config.json").read_text()))
        super().__init__(config if config is not None else trained_config, env_id or JOINT, seed)
        self.model = _load_model(self.path, run["algo"])
        self.normalizer = _load_normalizer(self.path)
        k = self.config.num_agvs
        self.n_agents = k + 1
        self.obs_width = self.model.observation_space.shape[0] - self.n_agents
        if self.obs_width != self.layout.size:
            raise ValueError(f"{self.path} expects {self.model.observation_space.shape[0]} inputs; this scenario "
                             f"has K={k}: evaluate it with its training config")

    def agent_observations(self, obs) -> np.ndarray:
        """(K+1, width): the drone's and each AGV's padded observation with its one-hot indicator,
        in PettingZoo's agent order (drone, agv_0, ...)."""
        central = np.asarray(obs, dtype=np.float32)
        blocks = self.layout.agv_blocks(central)
        glob = central[-self.layout.global_features:]
        out = np.zeros((self.n_agents, self.obs_width + self.n_agents), dtype=np.float32)
        out[0, : central.size] = central
        for i in range(self.n_agents - 1):
            own = np.concatenate([blocks[i], glob])
            out[i + 1, : own.size] = own
        out[np.arange(self.n_agents), self.obs_width + np.arange(self.n_agents)] = 1.0
        return out

    def act(self, obs) -> np.ndarray:
        x = self.agent_observations(obs)
        if self.normalizer is not None:
            x = self.normalizer.normalize_obs(x)
        actions, _ = self.model.predict(x, deterministic=True)
        actions = np.clip(actions, -1.0, 1.0)
        k = self.config.num_agvs
        increments = actions[1:, :2].reshape(-1)
        drone = actions[0, : k + 2]
        return np.concatenate([increments, drone]).astype(np.float32)


def _sb3(path, config=None, env_id=None, seed=None, **kwargs):
    if kwargs:
        raise ValueError(f"learned policies take no settings; got {sorted(kwargs)}")
    return SB3Policy(path, config, env_id, seed)


def _marl(path, config=None, env_id=None, seed=None, **kwargs):
    if kwargs:
        raise ValueError(f"learned policies take no settings; got {sorted(kwargs)}")
    return MARLPolicy(path, config, env_id, seed)


#: Prefixes of ``make_policy`` names that load a run directory: ``sb3:DIR``, ``bc:DIR``, ``marl:DIR``.
LOADERS = {"sb3": _sb3, "bc": _sb3, "marl": _marl}
