"""The paired reward: the agent's slot reward measured against an anchor policy's on the same seed.

A lawn env's randomness does not depend on the actions: every slot draws the same arrays from the
env's generator (:func:`lawn_env.core.draw_slot`), whatever was decided. So a second copy of the
scenario, reset with the same seed and played by an anchor policy, sees the same initial state,
the same fading, gusts and noise, slot by slot; the anchor's slot reward ``b_t`` is then a number
fixed by the seed and the slot, whatever the agent does. :class:`PairedReward` gives the agent

    r'_t = r_t - b_t    (the anchor's slot cost minus the agent's, through the env's reward map)

with ``r_t`` the env's own reward (the RL interface's scaled, clipped cost and its termination
penalty, or minus the raw cost on the benchmark interface) and ``b_t`` the same map of the
anchor's slot cost. When the agent's episode terminates early, its last step also subtracts the
anchor's rewards of the slots it did not play, discounted by ``gamma``, so the subtracted total
``sum_t gamma^t b_t`` covers the whole episode whatever the agent does: every policy's expected
return moves by the same constant, and the optimal policy is the one of the unmodified reward.
What changes is the variance: an agent near the anchor loses the commands the anchor loses on
the same slots, and the difference cancels the luck the two share.

The wrapper seeds every episode itself (from the seed of the first ``reset``, or a given one) so
both copies start from the same seed; ``info["anchor_stage_cost"]`` and
``info["anchor_reward"]`` report the anchor's slot. Evaluation never uses it: comparisons play
the unmodified scenario (:mod:`lawn_env.interface`).
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from agents.base import Policy
from agents.policies import make_policy
from lawn_env import role_env_id
from lawn_env.envs.base import LawnEnv

__all__ = ["PairedReward"]

_SEED_RANGE = 2**31


class PairedReward(gym.Wrapper[Any, Any, Any, Any]):
    """``env`` (a ``lawn/Joint-v1`` or ``lawn/Comm-v1`` env, any interface, possibly wrapped) with
    the reward paired against ``anchor`` (a policy name for :func:`agents.make_policy`, e.g.
    ``"dv-mpc"``, or a built :class:`~agents.base.Policy` of the env's scenario) on a shadow copy of
    the scenario (module docstring); ``gamma`` discounts the anchor's slots an early termination
    leaves unplayed (the learner's discount)."""

    def __init__(self, env: gym.Env[Any, Any], anchor: str | Policy = "dv-mpc", gamma: float = 1.0):
        super().__init__(env)
        base = env.unwrapped
        if not isinstance(base, LawnEnv):
            raise TypeError(f"PairedReward wraps a lawn env (lawn/Joint-v1, lawn/Comm-v1); got {type(base).__name__}")
        if not (isinstance(gamma, (int, float)) and 0.0 < gamma <= 1.0):
            raise ValueError(f"gamma={gamma!r}: must be a number in (0, 1]")
        env_id = role_env_id(base.role)
        kwargs: dict[str, Any] = {"config": base.config}
        if base.planning_state != "measured":
            kwargs["planning_state"] = base.planning_state
        #: the anchor's copy of the scenario, on the benchmark interface the policies act on
        self.shadow: LawnEnv = type(base)(**kwargs)
        if isinstance(anchor, str):
            anchor = make_policy(anchor, base.config, env_id=env_id)
        elif not isinstance(anchor, Policy) or anchor.env_id != env_id:
            raise ValueError(f"anchor={anchor!r}: a policy name or a Policy driving {env_id}")
        self.anchor = anchor
        self.base: LawnEnv = base
        self.gamma = float(gamma)
        self._seeds: np.random.Generator | None = None
        self._shadow_obs: Any = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if seed is not None or self._seeds is None:
            self._seeds = np.random.default_rng(seed)
        episode_seed = int(self._seeds.integers(_SEED_RANGE))
        obs, info = self.env.reset(seed=episode_seed, options=options)
        self._shadow_obs, _ = self.shadow.reset(seed=episode_seed)
        self.anchor.reset(seed=episode_seed)
        return obs, info

    def _anchor_slot(self) -> tuple[float, float]:
        """One slot of the anchor on the shadow: its stage cost and its reward by the env's map."""
        self._shadow_obs, _, _, _, info = self.shadow.step(self.anchor.act(self._shadow_obs))
        cost = float(info["stage_cost"])
        reward = float(self.base.interface.rewards_from_costs(np.array(cost)))
        return cost, reward

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        cost, baseline = self._anchor_slot()
        info = {**info, "anchor_stage_cost": cost, "anchor_reward": baseline}
        if terminated:  # the anchor's unplayed slots, so the subtracted total does not depend on when
            discount = self.gamma
            while not self.shadow.sim.done:
                baseline += discount * self._anchor_slot()[1]
                discount *= self.gamma
        return obs, float(reward) - baseline, terminated, truncated, info

    def close(self) -> None:
        self.shadow.close()
        super().close()
