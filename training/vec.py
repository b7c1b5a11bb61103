"""Stable-Baselines3 on lawn's native vector env (``lawn train --vec native``).

:class:`NativeVecEnv` is an SB3 ``VecEnv`` over :class:`lawn_env.envs.vector.JointVectorEnv` or
``CommVectorEnv`` (any interface) run with same-step autoreset, which is SB3's convention: the
step that ends an episode returns the next episode's first observation, the final one in ``infos[i]["terminal_observation"]``
and ``infos[i]["TimeLimit.truncated"]`` for truncations. ``VecMonitor`` (episode returns and
lengths) and ``VecNormalize`` go on top as on any SB3 VecEnv.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from lawn_env import ENV_IDS, RL_ENV_IDS, ScenarioConfig
from lawn_env.interface import InterfaceLike

__all__ = ["NATIVE_ENV_IDS", "NativeVecEnv"]

#: The ids registered with a native vector env (their ``vector_entry_point``).
NATIVE_ENV_IDS = tuple(i for i in (*ENV_IDS, *RL_ENV_IDS) if gym.spec(i).vector_entry_point is not None)


class NativeVecEnv(VecEnv):
    """``n_envs`` scenarios of ``env_id`` (``NATIVE_ENV_IDS``) in one batched simulation, on
    ``interface`` (an RL id's default: ``"rl"``)."""

    def __init__(self, config: ScenarioConfig, n_envs: int, env_id: str = "lawn/Joint-v0",
                 interface: InterfaceLike = None):
        if env_id not in NATIVE_ENV_IDS:
            raise ValueError(f"env_id={env_id!r}: the native vector envs are {', '.join(NATIVE_ENV_IDS)}")
        kwargs = {} if interface is None else {"interface": interface}  # None keeps the id's own (RL ids: "rl")
        self.venv = gym.make_vec(env_id, num_envs=n_envs, vectorization_mode="vector_entry_point", config=config,
                                 autoreset_mode="SameStep", **kwargs)
        super().__init__(n_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._seed: int | None = None
        self._actions: np.ndarray | None = None
        self.render_mode = None

    def reset(self) -> np.ndarray:
        obs, _ = self.venv.reset(seed=self._seed)
        self._seed = None
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions  # SB3 clips Box actions before stepping; the env rejects what it cannot take

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{"stage_cost": float(c)} for c in info["stage_cost"]]
        if done.any():
            for i in np.flatnonzero(done).tolist():
                infos[i]["terminal_observation"] = info["final_obs"][i]
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, reward.astype(np.float32), done, infos

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def close(self) -> None:
        self.venv.close()

    # attribute access as SB3's VecEnvs offer it (one batched env: the same answer for every index)
    def get_attr(self, attr_name: str, indices: Any = None) -> list:
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list:
        raise NotImplementedError(f"env_method({method_name!r}): the native vector env has no per-env objects")

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._get_indices(indices))
