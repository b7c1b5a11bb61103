"""lawn's PPO hyperparameters in rl-baselines3-zoo's form, for ``python -m rl_zoo3.train``:

    python -m rl_zoo3.train --algo ppo --env lawn/CommRL-v0 --gym-packages lawn_env --conf-file training.rl_zoo

rl-zoo3 reads ``hyperparams`` from this module (``--conf-file`` takes a Python package). They are
``training/hyperparams/ppo.yml``'s, the file ``lawn train`` reads, keyed by the RL ids (whose
``interface="rl"`` the file's ``interface: rl`` asks for), with the keys only ``lawn train`` knows
dropped, the dicts written as rl-zoo3 expects them (strings it evaluates) and the training budget
(``n_timesteps``) of the shipped agent's recipe on that env (:data:`training.recipes.RECIPES`).
"""

from __future__ import annotations

from typing import Any

from lawn_env import RL_ENV_IDS

__all__ = ["hyperparams", "zoo_hyperparams"]

def zoo_hyperparams(algo: str = "ppo") -> dict[str, dict[str, Any]]:
    """rl-zoo3's hyperparameters of ``algo`` for every RL id whose base env's entry in lawn's file
    trains on the RL interface."""
    from .recipes import RECIPES
    from .options import LAWN_KEYS
    from .train import load_hyperparams

    plain = [r for r in RECIPES.values() if r.algo == algo and not r.hp and r.init_from is None]
    budgets = {r.env_id: r.timesteps for r in plain}
    if len(budgets) != len(plain):
        raise ValueError(f"more than one plain {algo} recipe per env: {[r.name for r in plain]}")
    zoo_keys = {"n_envs", "normalize", "policy"}  # rl-zoo3 reads these three itself
    out = {}
    for rl_id, base in RL_ENV_IDS.items():
        params, _ = load_hyperparams(algo, base)
        if params.get("interface", "rl") != "rl":
            continue
        zoo = {k: v for k, v in params.items() if k in zoo_keys or k not in LAWN_KEYS}
        if base in budgets:
            zoo["n_timesteps"] = budgets[base]
        for key in ("normalize", "policy_kwargs"):
            if isinstance(zoo.get(key), dict):
                zoo[key] = f"dict({', '.join(f'{k}={v!r}' for k, v in zoo[key].items())})"
        out[rl_id] = zoo
    return out


#: What ``--conf-file training.rl_zoo`` gives rl-zoo3 (PPO).
hyperparams = zoo_hyperparams("ppo")
