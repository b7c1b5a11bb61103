"""lawn_env: wireless predictive control over low-altitude networks, as RL environments.

``import lawn_env`` registers ``lawn/Joint-v1`` and ``lawn/Comm-v1`` with Gymnasium
(``gym.make("lawn_env:lawn/Joint-v1")`` works without the import), and the v0 ids, whose
episodes the version histories (:class:`~lawn_env.JointEnv`, :class:`~lawn_env.CommEnv`) tell apart.
``lawn_env.parallel_env`` builds the PettingZoo environment. The physics lives in :mod:`lawn_env.channel`,
:mod:`lawn_env.dynamics`, :mod:`lawn_env.drone` and :mod:`lawn_env.references`.
"""

from typing import Any

from . import kernel_cache

kernel_cache.install()  # before any kernel is decorated: their cache follows every source file they use

from gymnasium.envs.registration import register, registry

from . import channel, drone, dynamics, presets, references
from .config import ChannelConfig, ControlConfig, DisturbanceConfig, DroneConfig, ReferenceConfig, ScenarioConfig
from .core import Simulation, Snapshot
from .envs.comm import CommEnv
from .envs.joint import JointEnv
from .envs.mixed import MixedFleetEnv
from .envs.parallel import LawnParallelEnv, env, parallel_env, raw_env
from .errors import ConfigError, UnknownConfigKeyError
from .interface import RL_INTERFACE, RLInterface, action_codec
from .presets import resolve_config
from .spaces import ObservationLayout

__version__ = "0.1.0"

#: Registered environment ids and their entry points: the one registry the CLI reads.
ENV_IDS = {
    "lawn/Joint-v1": "lawn_env.envs.joint:JointEnv",
    "lawn/Comm-v1": "lawn_env.envs.comm:CommEnv",
}

#: The same environments with the RL interface (``interface="rl"``, :mod:`lawn_env.interface`):
#: for training; comparisons always run the ids of :data:`ENV_IDS`.
RL_ENV_IDS = {
    "lawn/JointRL-v1": "lawn/Joint-v1",
    "lawn/CommRL-v1": "lawn/Comm-v1",
}

#: The multi-agent environment's id (PettingZoo has no registry; :func:`lawn_env.parallel_env` builds
#: it) and the central environment each multi-agent id mirrors: its episodes are that env's under
#: the same decisions, and learned multi-agent policies are evaluated on it.
PARALLEL_ENV_ID = "lawn/Parallel-v0"
PARALLEL_ENV_IDS = {PARALLEL_ENV_ID: "lawn/Joint-v1"}


def central_env_id(env_id: str) -> str:
    """The Gymnasium id an env id is evaluated on: the central env a multi-agent id mirrors, else
    the id itself."""
    return PARALLEL_ENV_IDS.get(env_id, env_id)


#: No registered time limit: the envs end their episodes themselves at ``num_slots`` (truncation),
#: and a made env's ``spec.max_episode_steps`` reports that length (``LawnEnv.spec``). A
#: registered limit could only disagree with a caller's ``num_slots``, and Gymnasium's native
#: vector entry points admit no extra registered wrappers to reconcile the two.
_EPISODE: dict[str, Any] = {"disable_env_checker": False}
#: Native vector envs (``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``).
VECTOR_ENTRY_POINTS = {"lawn/Joint-v1": "lawn_env.envs.vector:JointVectorEnv",
                       "lawn/Comm-v1": "lawn_env.envs.vector:CommVectorEnv"}
for _env_id, _entry_point in ENV_IDS.items():
    if _env_id not in registry:
        register(id=_env_id, entry_point=_entry_point, vector_entry_point=VECTOR_ENTRY_POINTS.get(_env_id),
                 **_EPISODE)
for _env_id, _base in RL_ENV_IDS.items():
    if _env_id not in registry:
        register(id=_env_id, entry_point=ENV_IDS[_base], vector_entry_point=VECTOR_ENTRY_POINTS.get(_base),
                 kwargs={"interface": "rl"}, **_EPISODE)

#: The earlier versions, kept registered (Gymnasium warns that they are out of date): the same classes
#: with v0's episodes where the code can give them. ``lawn/Comm-v0``'s MPC plans from the true state
#: under measurement noise; neither v0 id has a native vector env, so ``gym.make_vec`` steps v0
#: scenarios side by side with their own generators (Gymnasium's ``SyncVectorEnv``), as v0's did.
LEGACY_ENV_IDS = {
    "lawn/Joint-v0": ("lawn/Joint-v1", {}),
    "lawn/Comm-v0": ("lawn/Comm-v1", {"planning_state": "true"}),
    "lawn/JointRL-v0": ("lawn/Joint-v1", {"interface": "rl"}),
    "lawn/CommRL-v0": ("lawn/Comm-v1", {"interface": "rl", "planning_state": "true"}),
}
for _env_id, (_base, _kwargs) in LEGACY_ENV_IDS.items():
    if _env_id not in registry:
        register(id=_env_id, entry_point=ENV_IDS[_base], kwargs=_kwargs, **_EPISODE)

#: What the actions of each environment decide (a role of :data:`lawn_env.spaces.ROLES`): every
#: increment, power and move (``joint``), or the power and the move (``comm``); the one place of it.
ENV_ROLES = {"lawn/Joint-v1": "joint", "lawn/Comm-v1": "comm"}


def env_role(env_id: str) -> str:
    """The role of an env id of any kind (central, RL interface, earlier version or multi-agent):
    ``"joint"`` or ``"comm"``; an unknown id raises ``ValueError`` naming the known ones."""
    base = central_env_id(env_id)
    base = RL_ENV_IDS.get(base, LEGACY_ENV_IDS[base][0] if base in LEGACY_ENV_IDS else base)
    if base not in ENV_ROLES:
        known = [*ENV_IDS, *RL_ENV_IDS, *LEGACY_ENV_IDS, *PARALLEL_ENV_IDS]
        raise ValueError(f"unknown env id {env_id!r}; known: {', '.join(known)}")
    return ENV_ROLES[base]


def role_env_id(role: str) -> str:
    """The central env id of a role (``"joint"``: ``lawn/Joint-v1``, ``"comm"``: ``lawn/Comm-v1``)."""
    for env_id, own in ENV_ROLES.items():
        if own == role:
            return env_id
    raise ValueError(f"role={role!r}; valid: {', '.join(ENV_ROLES.values())}")


__all__ = [
    "ENV_IDS",
    "RL_ENV_IDS",
    "LEGACY_ENV_IDS",
    "PARALLEL_ENV_ID",
    "PARALLEL_ENV_IDS",
    "central_env_id",
    "ENV_ROLES",
    "env_role",
    "role_env_id",
    "RLInterface",
    "RL_INTERFACE",
    "action_codec",
    "ChannelConfig",
    "ControlConfig",
    "DroneConfig",
    "ReferenceConfig",
    "DisturbanceConfig",
    "ScenarioConfig",
    "ConfigError",
    "UnknownConfigKeyError",
    "resolve_config",
    "Simulation",
    "Snapshot",
    "ObservationLayout",
    "JointEnv",
    "CommEnv",
    "LawnParallelEnv",
    "parallel_env",
    "raw_env",
    "env",
    "channel",
    "dynamics",
    "drone",
    "presets",
    "references",
    "MixedFleetEnv",
]
