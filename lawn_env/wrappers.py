"""``EpisodeLength``: keeps Gymnasium's time limit and the scenario's episode length in agreement.

The episode length of a lawn environment is its config's ``num_slots`` (references and metrics are
built for it); ``gym.make`` also wraps it in a ``TimeLimit`` from the registered
``max_episode_steps`` (120, the default ``num_slots``) or from its own ``max_episode_steps``
argument. Registered as the outermost wrapper of every id, this wrapper reconciles the two when the
environment is made:

* ``gym.make(id)``: both 120;
* ``gym.make(id, num_slots=N)``: the time limit follows, ``env.spec.max_episode_steps == N``;
* ``gym.make(id, max_episode_steps=M)`` with ``num_slots`` left at a different value: a
  ``ValueError`` naming both and the fix (``num_slots=M``), never a silent change of either.
"""

from __future__ import annotations

import gymnasium as gym
from gymnasium.wrappers import TimeLimit

__all__ = ["EpisodeLength"]


class EpisodeLength(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """See the module docstring; it forwards everything else unchanged."""

    def __init__(self, env: gym.Env):
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        num_slots = env.unwrapped.config.num_slots
        limit = _time_limit(env)
        if limit is None or limit._max_episode_steps == num_slots:
            return
        env_id = env.unwrapped.spec.id if env.unwrapped.spec is not None else None
        registered = gym.spec(env_id).max_episode_steps if env_id in gym.registry else None
        if limit._max_episode_steps != registered:  # the caller asked for this limit
            raise ValueError(
                f"gym.make({env_id!r}, max_episode_steps={limit._max_episode_steps}) disagrees with the scenario's "
                f"num_slots={num_slots}: the episode length of lawn environments is num_slots; pass "
                f"num_slots={limit._max_episode_steps} instead (the time limit follows it)")
        limit._max_episode_steps = num_slots  # the registered default follows the caller's num_slots
        limit._cached_spec = None


def _time_limit(env: gym.Env) -> TimeLimit | None:
    while isinstance(env, gym.Wrapper):
        if isinstance(env, TimeLimit):
            return env
        env = env.env
    return None
