"""The options of a ``lawn train`` run, checked before anything is written.

A run's hyperparameters (``training/hyperparams/<algo>.yml`` with the ``--hp`` overrides) hold two
kinds of keys: those ``lawn train`` reads itself (:data:`LAWN_KEYS`) and the keyword arguments of
the Stable-Baselines3 algorithm. :func:`split_params` separates them and checks every one (names,
types, which algorithm takes which option), so a typo fails before the run directory gets its
``run.json``; a failed run directory would otherwise block the corrected command.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Any, Mapping

from lawn_env import PARALLEL_ENV_ID
from lawn_env.interface import resolve_interface

__all__ = ["LAWN_KEYS", "RunOptions", "split_params", "public_keys", "lr_schedule", "start_at_anchor"]

#: Hyperparameter keys that ``lawn train`` reads itself (the rest go to the SB3 algorithm), with the
#: algorithms each applies to (None: all).
LAWN_KEYS: dict[str, tuple[str, ...] | None] = {
    "n_envs": None, "normalize": None, "policy": None, "interface": None,
    "actor_warmup_steps": ("ppo", "a2c"), "init_log_std": ("ppo", "a2c"), "start_at_anchor": ("ppo", "sac"),
}
#: Constructor arguments ``lawn train`` sets itself: not hyperparameters.
_SET_BY_LAWN = {"self", "env", "policy", "seed", "verbose", "tensorboard_log"}


@dataclass
class RunOptions:
    """What :func:`split_params` found: ``lawn train``'s own options and the SB3 keyword arguments."""

    n_envs: int = 1
    normalize: bool | dict = False
    policy: str = "MlpPolicy"
    interface: Any = None
    actor_warmup_steps: int = 0
    init_log_std: float | None = None
    start_at_anchor: bool = False
    algo_kwargs: dict = field(default_factory=dict)


def public_keys(cls: type) -> list[str]:
    """The hyperparameters an SB3 algorithm class takes: its constructor's public arguments, less
    those ``lawn train`` sets itself."""
    return sorted(p for p in inspect.signature(cls.__init__).parameters if not p.startswith("_") and p not in _SET_BY_LAWN)


def lr_schedule(value: Any, key: str = "learning_rate") -> Any:
    """``lin_3e-4`` (rl-zoo's notation): linear decay from 3e-4 to 0 over the run; numbers as they are."""
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            start = float(value[4:])
        except ValueError:
            raise ValueError(f"--hp {key}={value!r}: lin_<number> expected, e.g. lin_3e-4") from None
        return lambda progress_remaining: progress_remaining * start
    return value


def _number(params: dict, key: str, kind: type, low: float) -> None:
    if key not in params:
        return
    value = params[key]
    try:
        number = kind(value)
    except (TypeError, ValueError):
        number = None
    if number is None or isinstance(value, bool) or number != value and kind is int or number < low:
        raise ValueError(f"--hp {key}={value!r}: must be {'an integer' if kind is int else 'a number'} >= {low:g}")
    params[key] = number


def split_params(algo: str, env_id: str, params: Mapping[str, Any], vec: str = "dummy") -> RunOptions:
    """``lawn train``'s options and the SB3 keyword arguments of ``params``, every one checked: an
    unknown key, a value of the wrong type, an option the algorithm does not take, ``--vec native``
    on an env it does not run; the error names the key, the value and what is allowed."""
    from agents.runs import algorithm_class

    cls = algorithm_class(algo)
    params = dict(params)
    _number(params, "n_envs", int, 1)
    _number(params, "actor_warmup_steps", int, 0)
    _number(params, "init_log_std", float, -20)
    for key, algos in LAWN_KEYS.items():
        if key in params and algos is not None and algo not in algos:
            raise ValueError(f"--hp {key}: applies to {', '.join(algos)}, not {algo}")
    normalize = params.get("normalize", False)
    if isinstance(normalize, Mapping):
        from stable_baselines3.common.vec_env import VecNormalize

        allowed = public_keys(VecNormalize) + ["venv"]
        unknown = sorted(set(normalize) - set(allowed) | ({"venv"} & set(normalize)))
        if unknown:
            raise ValueError(f"--hp normalize: unknown VecNormalize options {unknown}; valid: "
                             f"{', '.join(k for k in allowed if k != 'venv')}")
    elif not isinstance(normalize, bool):
        raise ValueError(f"--hp normalize={normalize!r}: true, false or a dict of VecNormalize options")
    if vec == "native":
        from .vec import NATIVE_ENV_IDS

        if env_id not in NATIVE_ENV_IDS:
            raise ValueError(f"--vec native runs {', '.join(NATIVE_ENV_IDS)} (got {env_id}); pass --vec dummy")
    elif vec != "dummy":
        raise ValueError(f"--vec {vec!r}; valid: dummy, native")
    options = RunOptions(**{k: params.pop(k) for k in list(params) if k in LAWN_KEYS})
    options.start_at_anchor = bool(options.start_at_anchor)
    policy = options.policy
    if policy == "FleetPolicy":  # lawn's attention policy for the entity layout (agents/fleet.py)
        from agents.fleet import FleetPolicy

        if algo not in ("ppo", "a2c"):
            raise ValueError(f"--hp policy=FleetPolicy is an actor-critic policy: ppo or a2c, not {algo}")

        options.policy = FleetPolicy
    elif isinstance(policy, str) and policy not in getattr(cls, "policy_aliases", {}):
        raise ValueError(f"--hp policy={policy!r}: {cls.__name__} takes "
                         f"{', '.join([*cls.policy_aliases, 'FleetPolicy'])}")
    if env_id == PARALLEL_ENV_ID and options.interface is not None and options.policy is not _fleet_policy() \
            and resolve_interface(options.interface).layout == "entities":
        raise ValueError(f"--hp policy={policy!r}: the multi-agent env's entity layout trains --hp policy=FleetPolicy "
                         "(each agent acts with its own row of the fleet network)")
    for key in ("learning_rate", "clip_range"):
        if key in params:
            params[key] = lr_schedule(params[key], key)
    valid = public_keys(cls)
    unknown = sorted(set(params) - set(valid))
    if unknown:
        mine = [k for k, algos in LAWN_KEYS.items() if algos is None or algo in algos]
        raise ValueError(f"unknown {cls.__name__} hyperparameters {unknown}; valid: {', '.join(sorted(valid + mine))}")
    options.algo_kwargs = params
    return options


def _fleet_policy() -> type | None:
    """agents.fleet.FleetPolicy (None without torch)."""
    try:
        from agents.fleet import FleetPolicy
    except ImportError:
        return None
    return FleetPolicy


def start_at_anchor(model: Any, algo: str) -> None:
    """``start_at_anchor``: the policy's output layer starts at zero weights and bias, so that its
    deterministic action is the zero action: the run starts at its interface's anchor, and model
    selection, which validates the start, compares what training finds against the anchor itself.
    SB3's SAC initializes its mean layer like any other (its untrained policy acts far from zero);
    PPO's orthogonal init with gain 0.01 acts near zero but not at it (the zoo's PPO-joint starts are
    +1.7 % ± 1.0 % above the anchor across seeds). A run started ``--init-from`` keeps the weights it
    loads: it starts at the policy it fine-tunes."""
    import torch

    def heads() -> list:  # a fleet network's means are its two heads' outputs (its action_net is the identity)
        net = model.policy.mlp_extractor
        return [net.agv_head, net.drone_head] if hasattr(net, "agv_head") else [model.policy.action_net]

    layers = {"sac": lambda: [model.actor.mu], "ppo": heads}
    if algo not in layers:
        raise ValueError(f"start_at_anchor: supported for {', '.join(layers)}, not {algo!r}")
    with torch.no_grad():
        for layer in layers[algo]():
            layer.weight.zero_()
            layer.bias.zero_()
