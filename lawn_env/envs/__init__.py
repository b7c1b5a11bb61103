"""Environment classes; register them with ``import lawn_env``."""

from .comm import CommEnv
from .joint import JointEnv
from .parallel import LawnParallelEnv, parallel_env

__all__ = ["JointEnv", "CommEnv", "LawnParallelEnv", "parallel_env"]
