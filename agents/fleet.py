"""A permutation-equivariant policy for any fleet size: masked attention over AGV tokens.

It reads the entity layout (:mod:`lawn_env.entities`: a row per AGV padded to 64 rows, a mask, a
row of globals) and writes its actions (a row per AGV, then the drone's two entries), so one
network serves every K up to 64. Every AGV's row goes through the same encoder and the same head,
and the AGVs meet only through attention over a set (the drone and the scenario's globals as one
more token that every AGV attends to, padded rows masked out as keys): permuting the AGVs permutes
their action rows and leaves the drone's and the value unchanged, and a padded row changes
nothing. For Stable-Baselines3: ``PPO(FleetPolicy, env)`` on an env made with
``interface={"layout": "entities", ...}``; saved and loaded like any SB3 model.

Needs torch and Stable-Baselines3 (the ``rl`` extra); :mod:`agents` imports without them, and this
module is imported only when used.
"""

from __future__ import annotations

from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

__all__ = ["EntityFeatures", "FleetNet", "FleetPolicy"]


class EntityFeatures(BaseFeaturesExtractor):
    """The entity observation as one flat tensor ``[agvs, globals, mask]``, which :class:`FleetNet`
    splits back into its parts (SB3's policies pass one tensor from the extractor on)."""

    def __init__(self, observation_space: spaces.Dict):
        rows, features = observation_space["agvs"].shape
        super().__init__(observation_space, rows * features + observation_space["globals"].shape[0] + rows)

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        return th.cat([observations["agvs"].flatten(1), observations["globals"], observations["mask"]], dim=1)


def _mlp(inputs: int, width: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(inputs, width), nn.Tanh(), nn.Linear(width, width), nn.Tanh())


class FleetNet(nn.Module):
    """Tokens for the AGVs (a shared encoder of each row) and one for the drone and the globals,
    ``layers`` rounds of masked self-attention over them, then each AGV's action row from its
    token (a shared head; padded rows give zeros), the drone's action and the value's latent from
    the global token. SB3's ``mlp_extractor``: ``forward_actor`` gives the actions' means."""

    def __init__(self, rows: int, features: int, num_globals: int, per_agv: int, width: int = 64, heads: int = 4,
                 layers: int = 2):
        super().__init__()
        self.rows, self.features, self.num_globals, self.per_agv = rows, features, num_globals, per_agv
        self.latent_dim_pi = rows * per_agv + 2
        self.latent_dim_vf = width
        self.agv_encoder = _mlp(features, width)
        self.global_encoder = _mlp(num_globals, width)
        self.attention = nn.ModuleList(
            nn.TransformerEncoderLayer(width, heads, dim_feedforward=2 * width, dropout=0.0, batch_first=True)
            for _ in range(layers))
        self.agv_head = nn.Linear(width, per_agv)
        self.drone_head = nn.Linear(width, 2)

    def _split(self, flat: th.Tensor) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        n = self.rows * self.features
        agvs = flat[:, :n].reshape(-1, self.rows, self.features)
        return agvs, flat[:, n : n + self.num_globals], flat[:, n + self.num_globals :]

    def _tokens(self, flat: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        agvs, glob, mask = self._split(flat)
        present = max(1, int(mask.sum(dim=1).max()))  # the rows past every sample's fleet are padding:
        agvs, mask = agvs[:, :present], mask[:, :present]  # masked as keys and zeroed as outputs, so dropped
        tokens = th.cat([self.global_encoder(glob)[:, None], self.agv_encoder(agvs)], dim=1)
        padded = th.cat([th.zeros_like(mask[:, :1], dtype=th.bool), mask < 0.5], dim=1)
        for layer in self.attention:
            tokens = layer(tokens, src_key_padding_mask=padded)
        return tokens, mask

    def _actions(self, tokens: th.Tensor, mask: th.Tensor) -> th.Tensor:
        rows = self.agv_head(tokens[:, 1:]) * mask[..., None]
        padding = rows.new_zeros((rows.shape[0], self.rows - rows.shape[1], self.per_agv))
        return th.cat([th.cat([rows, padding], dim=1).flatten(1), self.drone_head(tokens[:, 0])], dim=1)

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        tokens, mask = self._tokens(features)
        return self._actions(tokens, mask), tokens[:, 0]

    def forward_actor(self, features: th.Tensor) -> th.Tensor:
        return self._actions(*self._tokens(features))

    def forward_critic(self, features: th.Tensor) -> th.Tensor:
        return self._tokens(features)[0][:, 0]


class FleetPolicy(ActorCriticPolicy):
    """SB3's actor-critic with :class:`FleetNet` in place of the MLPs: the network's outputs are
    the actions' means themselves (no dense layer over all rows, which would tie the actions to
    the rows' order). ``width``, ``heads`` and ``layers`` size the network."""

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Box, lr_schedule: Any, width: int = 64,
                 heads: int = 4, layers: int = 2, **kwargs: Any):
        if not isinstance(observation_space, spaces.Dict) or "agvs" not in observation_space.spaces:
            raise ValueError("FleetPolicy reads the entity layout: make the env with interface={'layout': 'entities'} "
                             f"(got an observation space {observation_space})")
        self.fleet = dict(width=int(width), heads=int(heads), layers=int(layers))
        kwargs.setdefault("features_extractor_class", EntityFeatures)
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)

    def _build_mlp_extractor(self) -> None:
        rows, features = self.observation_space["agvs"].shape
        per_agv = (self.action_space.shape[0] - 2) // rows
        self.mlp_extractor = FleetNet(rows, features, self.observation_space["globals"].shape[0], per_agv, **self.fleet)

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        self.action_net = nn.Identity()  # the means are FleetNet's rows: shared weights, any order
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), **self.fleet}
