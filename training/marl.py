"""Multi-agent training on the PettingZoo env through SuperSuit (parameter sharing).

The drone and the K AGVs act through one shared network: SuperSuit pads every agent's
observation and action to a common size and appends a one-hot agent indicator
(``agent_indicator_v0``), then flattens the agents into a vector environment for SB3. The AGVs
share all parameters; the drone's outputs come from the same network conditioned on its
indicator (SB3 trains one policy per VecEnv, so a separate drone network would need two
coupled learners). ``agents.learned.MARLPolicy`` runs such a policy on ``lawn/Joint-v0``.

With the interface's entity layout (``interface={"layout": "entities", ...}``, ``policy:
FleetPolicy``) the shared network is :class:`agents.fleet.FleetPolicy`: every agent sees the
whole fleet and which entity it is, the spaces do not depend on K, and one network trained at one
fleet size acts at any other (``agents.learned.SB3Policy`` drives ``lawn/Joint-v0`` with it).
"""

from __future__ import annotations

from typing import Any

from lawn_env import ScenarioConfig, parallel_env
from lawn_env.interface import InterfaceLike

__all__ = ["wrap_parallel", "make_marl_vec_env"]


def wrap_parallel(config: ScenarioConfig, interface: InterfaceLike = None) -> Any:
    """The PettingZoo env (on the given interface) with SuperSuit's padding and agent indicator.
    In the entity layout every agent already has the same observation space, with ``me`` saying
    which entity it is: only the drone's action is padded (to an AGV's row)."""
    import supersuit as ss

    env = parallel_env(config, interface=interface)
    if env.entities is not None:
        return ss.pad_action_space_v0(env)
    env = ss.pad_observations_v0(env)
    env = ss.pad_action_space_v0(env)
    return ss.agent_indicator_v0(env, type_only=False)


def make_marl_vec_env(config: ScenarioConfig, n_envs: int, seed: int, interface: InterfaceLike = None) -> Any:
    """An SB3 VecEnv with one sub-environment per agent per copy of the system, seeded."""
    import supersuit as ss
    from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

    class _Seeded(SB3VecEnvWrapper):
        """SuperSuit's SB3 adapter with SB3's ``seed`` (the next reset uses it)."""

        _next_seed = None

        def seed(self, seed=None):
            self._next_seed = seed
            return [seed]

        def reset(self, seed=None, options=None):
            seed = seed if seed is not None else self._next_seed
            self._next_seed = None
            observations, self.reset_infos = self.venv.reset(seed=seed)
            return observations

    venv = ss.pettingzoo_env_to_vec_env_v1(wrap_parallel(config, interface))
    venv = ss.concat_vec_envs_v1(venv, n_envs, num_cpus=0, base_class="gymnasium")
    wrapped = _Seeded(venv)
    wrapped.seed(seed)
    return wrapped
