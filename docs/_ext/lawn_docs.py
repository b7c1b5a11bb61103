"""Pages of the lawn docs generated from the code when the site is built.

A page holds a marker line ``<!-- lawn-docs: KIND [ARG] -->``; on ``source-read`` the marker is
replaced by Markdown made from the installed package, so these parts never go stale:

* ``env ID``: an environment page from the env class's docstring (Gymnasium's sections: Description,
  Action Space, ... Version History) under a summary table of its spaces at the defaults;
* ``parallel``: the same for the PettingZoo environment;
* ``config``: one table per configuration section from the config dataclasses' field docstrings
  (pydantic's ``use_attribute_docstrings``) and their validated bounds;
* ``presets``: every preset with what it changes from the default scenario;
* ``api PACKAGE``: the API reference of every module of a package (found by walking it, so a new
  module is never left out), one section per module.
"""

from __future__ import annotations

import re
from typing import Any

from sphinx.application import Sphinx

MARKER = re.compile(r"^<!-- lawn-docs: (?P<kind>[\w-]+)(?: (?P<arg>\S+))? -->$", re.MULTILINE)


def _md_docstring(doc: str) -> str:
    """A class docstring written in Gymnasium's Markdown, with its reST roles made MyST roles."""
    import inspect

    return re.sub(r":(\w+):`", r"{\1}`", inspect.cleandoc(doc))  # :class:`x` -> {class}`x`


def _space(space: Any) -> str:
    return f"`{space!r}`".replace("\n", " ")


def _summary(rows: list[tuple[str, str]], cls: type, num_agvs: int) -> str:
    """The page body: the summary table (Gymnasium's env pages open with one), then the docstring."""
    table = [f"| | (default scenario: K = {num_agvs}) |", "|---|---|",
             *(f"| {a} | {b} |" for a, b in [*rows, ("Class", f"{{class}}`{cls.__module__}.{cls.__name__}`")])]
    return "\n".join(table) + f"\n\n{_md_docstring(cls.__doc__)}\n"


def env_page(env_id: str) -> str:
    import gymnasium as gym

    import lawn_env

    if env_id not in lawn_env.ENV_IDS:
        raise ValueError(f"lawn-docs env {env_id!r}: unknown; valid: {', '.join(lawn_env.ENV_IDS)}")
    env = gym.make(env_id)
    rl = gym.make(next(k for k, v in lawn_env.RL_ENV_IDS.items() if v == env_id))
    rows = [
        ("Action Space", _space(env.action_space)),
        ("Observation Space", _space(env.observation_space)),
        ("RL interface id", f"`{rl.spec.id}`: actions {_space(rl.action_space)}, observations within "
                            f"±{float(rl.observation_space.high.max()):g}"),
        ("Episode length", f"`max_episode_steps = {env.spec.max_episode_steps}` (`num_slots`; truncation)"),
        ("Native vector env", f"`gym.make_vec(\"{env_id}\", num_envs=N, vectorization_mode=\"vector_entry_point\")`"),
        ("Import", f"`import lawn_env; gym.make(\"{env_id}\")` or `gym.make(\"lawn_env:{env_id}\")`"),
    ]
    page = _summary(rows, type(env.unwrapped), env.unwrapped.config.num_agvs)
    env.close()
    rl.close()
    return page


def parallel_page() -> str:
    import lawn_env

    par = lawn_env.parallel_env()
    rows = [
        ("Agents", ", ".join(f"`{a}`" for a in par.possible_agents)),
        ("Action spaces", f"`drone`: {_space(par.action_space('drone'))}; "
                          f"`agv_k`: {_space(par.action_space('agv_0'))}"),
        ("Observation spaces", f"`drone`: shape {par.observation_space('drone').shape}; "
                               f"`agv_k`: shape {par.observation_space('agv_0').shape}"),
        ("State space", f"shape {par.state_space.shape} (the central observation)"),
        ("Episode length", f"`max_cycles` = `num_slots` ({par.config.num_slots})"),
        ("Import", "`lawn_env.parallel_env()` (parallel API), `lawn_env.env()` (AEC API)"),
        ("Id", f"`{lawn_env.PARALLEL_ENV_ID}` (mirrors `{lawn_env.PARALLEL_ENV_IDS[lawn_env.PARALLEL_ENV_ID]}`)"),
    ]
    page = _summary(rows, type(par), par.config.num_agvs)
    par.close()
    return page


def _bounds(info: Any) -> str:
    symbols = {"ge": "≥", "gt": ">", "le": "≤", "lt": "<"}
    parts = [f"{symbols[k]} {getattr(m, k):g}" for m in info.metadata for k in symbols if hasattr(m, k)]
    return ", ".join(parts)


def _default(info: Any) -> str:
    value = info.default
    if isinstance(value, str):
        return f'`"{value}"`'
    return f"`{value!r}`"


def _cell(text: str | None) -> str:
    return " ".join((text or "").split()).replace("|", "\\|")


def config_page() -> str:
    from lawn_env import ScenarioConfig

    out = []
    top = ScenarioConfig.__pydantic_fields__
    sections = [("", ScenarioConfig, {k: v for k, v in top.items() if v.description is not None})]
    for name, info in top.items():
        if info.description is None:
            cls = info.annotation
            sections.append((f"{name}.", cls, cls.__pydantic_fields__))
    for prefix, cls, fields in sections:
        title = f"`{prefix[:-1]}`: {{class}}`~lawn_env.config.{cls.__name__}`" if prefix else \
            "Top level: {class}`~lawn_env.config.ScenarioConfig`"
        doc = _cell((cls.__doc__ or "").strip().split("\n\n")[0])
        out.append(f"## {title}\n\n{doc}\n")
        out.append("| field | default | bounds | meaning |\n|---|---|---|---|")
        for name, info in fields.items():
            out.append(f"| `{prefix}{name}` | {_default(info)} | {_bounds(info)} | {_cell(info.description)} |")
        out.append("")
    return "\n".join(out)


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def presets_table() -> str:
    from lawn_env import presets

    base = _flat(presets.get("default").to_dict())
    rows = ["| preset | in the suite | changes from `default` |", "|---|---|---|"]
    for name in presets.names():
        changed = _flat(presets.get(name).to_dict())
        diff = [f"`{k}={v!r}`" for k, v in changed.items() if base.get(k) != v]
        rows.append(f"| `{name}` | {'yes' if name in presets.SUITE else ''} | {', '.join(diff) or '—'} |")
    return "\n".join(rows) + "\n"


def api_page(package: str) -> str:
    import importlib
    import pkgutil

    if package not in ("lawn_env", "agents", "training"):
        raise ValueError(f"lawn-docs api {package!r}: valid packages: lawn_env, agents, training")
    root = importlib.import_module(package)
    names = [package] + sorted(m.name for m in pkgutil.walk_packages(root.__path__, package + ".")
                               if not m.name.endswith("__main__"))
    return "\n".join(f"## `{name}`\n\n```{{eval-rst}}\n.. automodule:: {name}\n```\n" for name in names)


GENERATORS = {"env": env_page, "parallel": parallel_page, "config": config_page, "presets": presets_table,
              "api": api_page}


def _expand(match: re.Match) -> str:
    kind, arg = match["kind"], match["arg"]
    if kind not in GENERATORS:
        raise ValueError(f"lawn-docs marker {match.group(0)!r}: unknown kind; valid: {', '.join(GENERATORS)}")
    return GENERATORS[kind](arg) if arg else GENERATORS[kind]()


def _source_read(app: Sphinx, docname: str, source: list[str]) -> None:
    source[0] = MARKER.sub(_expand, source[0])


def setup(app: Sphinx) -> dict:
    app.connect("source-read", _source_read)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
