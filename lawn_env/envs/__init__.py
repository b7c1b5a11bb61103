"""Environment classes; register them with ``import lawn_env``."""

from .comm import CommEnv
from .joint import JointEnv
from .parallel import LawnParallelEnv, env, parallel_env, raw_env

__all__ = ["JointEnv", "CommEnv", "LawnParallelEnv", "parallel_env", "raw_env", "env"]
