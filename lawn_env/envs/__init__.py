"""Environment classes; register them with ``import lawn_env``."""

from .comm import CommEnv
from .joint import JointEnv
from .mixed import MixedFleetEnv
from .parallel import LawnParallelEnv, env, parallel_env, raw_env

__all__ = ["JointEnv", "CommEnv", "MixedFleetEnv", "LawnParallelEnv", "parallel_env", "raw_env", "env"]
