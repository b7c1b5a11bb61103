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

from typing import Any, cast

import numba
import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

__all__ = ["EntityFeatures", "FleetNet", "FleetAgentNet", "FleetPolicy", "FleetInference"]


def _shape(space: spaces.Space[Any]) -> tuple[int, ...]:
    """A Box's shape (gymnasium types ``Space.shape`` as optional; the entity layout's spaces are Boxes)."""
    assert space.shape is not None
    return space.shape


class EntityFeatures(BaseFeaturesExtractor):
    """The entity observation as one flat tensor ``[agvs, globals, mask]`` (and ``me``, the
    multi-agent env's one-hot of the acting entity), which :class:`FleetNet` splits back into its
    parts (SB3's policies pass one tensor from the extractor on)."""

    def __init__(self, observation_space: spaces.Dict):
        rows, features = _shape(observation_space["agvs"])
        self.keys = ["globals", "mask"] + (["me"] if "me" in observation_space.spaces else [])
        super().__init__(observation_space, rows * features + sum(_shape(observation_space[k])[0] for k in self.keys))

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        return th.cat([observations["agvs"].flatten(1), *(observations[k] for k in self.keys)], dim=1)


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
        rows = th.nonzero(mask.amax(dim=0) > 0.5)  # the rows past every sample's last AGV are padding:
        present = int(rows[-1, 0]) + 1 if len(rows) else 1  # masked as keys, zeroed as outputs: dropped
        agvs, mask = agvs[:, :present], mask[:, :present]
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


class FleetAgentNet(FleetNet):
    """:class:`FleetNet` for one agent of the multi-agent env's entity layout (each observation
    ends with ``me``, the acting entity's one-hot): the same computation for every entity, then the
    acting one's action row (the drone's move padded to the row's width) and its token as the
    value's latent. Parameter sharing across agents is the network's own sharing across rows.
    The agents share SB3's state-independent log-std per action entry: the drone's move explores
    with the AGVs' increment noise (and its padded third entry, which the env ignores, with the
    power weight's)."""

    def __init__(self, rows: int, features: int, num_globals: int, per_agv: int, **sizes: Any):
        super().__init__(rows, features, num_globals, per_agv, **sizes)
        self.latent_dim_pi = per_agv

    def _agent(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        tokens, mask = self._tokens(features[:, : -(self.rows + 1)])
        return tokens, mask, features[:, -(self.rows + 1) :][:, : tokens.shape[1], None]

    def _own_action(self, tokens: th.Tensor, me: th.Tensor) -> th.Tensor:
        drone = self.drone_head(tokens[:, 0])
        drone = th.cat([drone, drone.new_zeros((drone.shape[0], self.per_agv - 2))], dim=1)
        return (me * th.cat([drone[:, None], self.agv_head(tokens[:, 1:])], dim=1)).sum(dim=1)

    def forward_actor(self, features: th.Tensor) -> th.Tensor:
        tokens, _, me = self._agent(features)
        return self._own_action(tokens, me)

    def forward_critic(self, features: th.Tensor) -> th.Tensor:
        tokens, _, me = self._agent(features)
        return (me * tokens).sum(dim=1)

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        tokens, _, me = self._agent(features)  # the attention once for the action and the value
        return self._own_action(tokens, me), (me * tokens).sum(dim=1)


class FleetPolicy(ActorCriticPolicy):
    """SB3's actor-critic with :class:`FleetNet` in place of the MLPs: the network's outputs are
    the actions' means themselves (no dense layer over all rows, which would tie the actions to
    the rows' order). ``width``, ``heads`` and ``layers`` size the network."""

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Box, lr_schedule: Any, width: int = 64,
                 heads: int = 4, layers: int = 2, **kwargs: Any):
        if not isinstance(observation_space, spaces.Dict) or "agvs" not in observation_space.spaces:
            raise ValueError("FleetPolicy reads the entity layout: make the env with interface={'layout': 'entities'} "
                             f"(got an observation space {observation_space})")
        self.fleet = {"width": int(width), "heads": int(heads), "layers": int(layers)}
        kwargs.setdefault("features_extractor_class", EntityFeatures)
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)

    def _build_mlp_extractor(self) -> None:
        # SB3 types the extractor as its MlpExtractor; this policy builds its own network in its place (the
        # hook SB3 documents for custom networks), hence the ignores below
        obs_space = cast(spaces.Dict, self.observation_space)  # checked in __init__
        rows, features = _shape(obs_space["agvs"])
        num_globals = _shape(obs_space["globals"])[0]
        actions = _shape(self.action_space)[0]
        if "me" in obs_space.spaces:  # one agent of the multi-agent env: its own row
            if obs_space["me"].shape != (rows + 1,) or actions < 2:
                raise ValueError(f"FleetPolicy for one agent needs obs['me'] of shape ({rows + 1},) (the drone, then "
                                 f"the {rows} rows) and an action of 2 or more entries; got "
                                 f"{obs_space['me'].shape} and {self.action_space.shape}")
            self.mlp_extractor = FleetAgentNet(rows, features, num_globals, actions, **self.fleet)  # type: ignore[assignment]
            return
        per_agv = (actions - 2) // rows
        self.mlp_extractor = FleetNet(rows, features, num_globals, per_agv, **self.fleet)  # type: ignore[assignment]

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        self.action_net = nn.Identity()  # the means are FleetNet's rows: shared weights, any order
        # as SB3's own _build: optimizer_class is typed as torch's Optimizer base, whose __init__ takes no lr
        self.optimizer = self.optimizer_class(  # type: ignore[call-arg]
            self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), **self.fleet}


def _numpy(tensor: th.Tensor, transpose: bool = False) -> np.ndarray:
    array = tensor.detach().cpu().numpy().astype(np.float32)
    return np.ascontiguousarray(array.T if transpose else array)


def _linear(layer: nn.Linear) -> tuple[np.ndarray, np.ndarray]:
    return _numpy(layer.weight, transpose=True), _numpy(layer.bias)


@numba.njit(cache=True)  # type: ignore[untyped-decorator]  # numba is not followed (pyproject.toml: numba's follow_imports)
def _layer_norm(x: np.ndarray, gain: np.ndarray, bias: np.ndarray, eps: float) -> np.ndarray:
    n, width = x.shape
    out = np.empty_like(x)
    for i in range(n):
        mean = 0.0
        for c in range(width):
            mean += x[i, c]
        mean /= width
        var = 0.0
        for c in range(width):
            var += (x[i, c] - mean) ** 2
        inv = 1.0 / np.sqrt(var / width + eps)
        for c in range(width):
            out[i, c] = (x[i, c] - mean) * inv * gain[c] + bias[c]
    return out


@numba.njit(cache=True)  # type: ignore[untyped-decorator]  # numba is not followed (pyproject.toml: numba's follow_imports)
def _mix(qkv: np.ndarray, heads: int) -> np.ndarray:
    """Scaled dot-product attention of every head over all the tokens: ``qkv`` (n, 3 width) holds
    the queries, keys and values; returns the heads' outputs side by side (n, width)."""
    n, width = qkv.shape[0], qkv.shape[1] // 3
    d = width // heads
    scale = np.float32(1.0 / np.sqrt(d))
    mixed = np.empty((n, width), dtype=qkv.dtype)
    for h in range(heads):
        o = h * d
        q = np.ascontiguousarray(qkv[:, o : o + d]) * scale
        keys = np.ascontiguousarray(qkv[:, width + o : width + o + d].T)
        scores = q @ keys
        for i in range(n):
            top = scores[i].max()
            total = np.float32(0.0)
            for j in range(n):
                scores[i, j] = np.exp(scores[i, j] - top)
                total += scores[i, j]
            scores[i] /= total
        mixed[:, o : o + d] = scores @ np.ascontiguousarray(qkv[:, 2 * width + o : 2 * width + o + d])
    return mixed


@numba.njit(cache=True)  # type: ignore[untyped-decorator]  # numba is not followed (pyproject.toml: numba's follow_imports)
def _attend(x: np.ndarray, weights: tuple[Any, ...], heads: int, eps: float) -> np.ndarray:
    """One post-norm encoder layer (``nn.TransformerEncoderLayer``: ReLU, no dropout, no mask) on
    the tokens ``x`` (n, width); ``weights`` as :class:`_Attention` packs them."""
    in_w, in_b, out_w, out_b, w1, b1, w2, b2, g1, c1, g2, c2 = weights
    x = _layer_norm(x + (_mix(x @ in_w + in_b, heads) @ out_w + out_b), g1, c1, eps)
    hidden = np.maximum(x @ w1 + b1, np.float32(0.0))
    out: np.ndarray = _layer_norm(x + (hidden @ w2 + b2), g2, c2, eps)
    return out


class _Attention:
    """One ``nn.TransformerEncoderLayer`` of :class:`FleetNet`, its weights as float32 arrays."""

    def __init__(self, layer: nn.TransformerEncoderLayer):
        if layer.norm_first or layer.activation_relu_or_gelu != 1 or not layer.self_attn.batch_first:
            raise ValueError("FleetInference runs post-norm, ReLU, batch-first encoder layers (FleetNet's); got "
                             f"norm_first={layer.norm_first}, activation {layer.activation_relu_or_gelu} (1: ReLU), "
                             f"batch_first={layer.self_attn.batch_first}")
        attn = layer.self_attn
        self.heads = int(attn.num_heads)
        if layer.norm1.eps != layer.norm2.eps:
            raise ValueError(f"FleetInference runs encoder layers whose two norms share their eps; got "
                             f"{layer.norm1.eps} and {layer.norm2.eps}")
        self.eps = float(layer.norm1.eps)
        self.weights = (_numpy(attn.in_proj_weight, transpose=True), _numpy(attn.in_proj_bias),
                        *_linear(attn.out_proj), *_linear(layer.linear1), *_linear(layer.linear2),
                        _numpy(layer.norm1.weight), _numpy(layer.norm1.bias), _numpy(layer.norm2.weight),
                        _numpy(layer.norm2.bias))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        out: np.ndarray = _attend(x, self.weights, self.heads, self.eps)
        return out


class FleetInference:
    """A :class:`FleetPolicy`'s deterministic action for one observation, in numpy (float32): the
    same layers as :class:`FleetNet`, on the AGVs present only (a padded row is masked as a key and
    zeroed as an output, so dropping it is exact), without torch's per-call cost, which dominates
    a single small observation (``benchmarks/fleet_decision.py``). The torch module stays the
    oracle (tests compare them); the weights are copied when this is built."""

    def __init__(self, policy: FleetPolicy):
        if not isinstance(policy, FleetPolicy):
            raise TypeError(f"FleetInference runs a FleetPolicy, got {type(policy).__name__}")
        if policy.use_sde or policy.squash_output or not isinstance(policy.features_extractor, EntityFeatures):
            raise ValueError("FleetInference copies the Gaussian mean of a FleetPolicy that reads EntityFeatures; got "
                             f"use_sde={policy.use_sde}, squash_output={policy.squash_output}, features extractor "
                             f"{type(policy.features_extractor).__name__}")
        net = cast(FleetNet, policy.mlp_extractor)  # what FleetPolicy builds
        self.rows, self.per_agv = net.rows, net.per_agv
        self.agv = [_linear(cast(nn.Linear, net.agv_encoder[i])) for i in (0, 2)]  # _mlp's Linear layers
        self.glob = [_linear(cast(nn.Linear, net.global_encoder[i])) for i in (0, 2)]
        self.attention = [_Attention(cast(nn.TransformerEncoderLayer, layer)) for layer in net.attention]
        self.agv_head, self.drone_head = _linear(net.agv_head), _linear(net.drone_head)

    @staticmethod
    def _encode(x: np.ndarray, mlp: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        for weight, bias in mlp:
            x = np.tanh(x @ weight + bias)
        return x

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """The action (rows * per_agv + 2,) for one entity observation (``agvs``, ``globals``, ``mask``)."""
        present = np.flatnonzero(np.asarray(obs["mask"]) > 0.5)
        glob = np.asarray(obs["globals"], dtype=np.float32)[None]
        agvs = np.asarray(obs["agvs"], dtype=np.float32)[present]
        tokens = np.concatenate([self._encode(glob, self.glob), self._encode(agvs, self.agv)])
        for layer in self.attention:
            tokens = layer(tokens)
        action = np.zeros(self.rows * self.per_agv + 2, dtype=np.float32)
        action[:-2].reshape(self.rows, self.per_agv)[present] = tokens[1:] @ self.agv_head[0] + self.agv_head[1]
        action[-2:] = tokens[0] @ self.drone_head[0] + self.drone_head[1]
        return action
