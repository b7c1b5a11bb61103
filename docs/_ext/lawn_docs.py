"""The reference pages of the lawn docs, generated from the code, and the Sphinx extension of the
API pages.

**Generated blocks** (this file's command line). The environment pages, the configuration page and
the command-line page hold their reference in the page itself, as plain Markdown that reads the same
on GitHub as on the site: the roles of the docstrings (reST's ``:class:`` or MyST's ``{class}``)
become plain code spans. Each is a generated block of :mod:`paper.pages`::

    <!-- NAME:begin cmd="python docs/_ext/lawn_docs.py KIND [ARG] --out runs/docs/NAME.md"
         table="runs/docs/NAME.md" group="reference" -->   (one line in the page)
    ...
    <!-- NAME:end -->

``python -m paper.pages refresh --only reference`` refreshes them all, and
``tests/test_reference_pages.py`` fails while a page differs from what the code produces. The kinds:

* ``env ID``: an environment page from the env class's docstring (Gymnasium's sections: Description,
  Action Space, ... Version History) under a summary table of its spaces at the defaults;
* ``parallel``: the same for the PettingZoo environment;
* ``config``: one table per configuration section from the config dataclasses' field docstrings
  (pydantic's ``use_attribute_docstrings``) and their validated bounds;
* ``presets``: every preset with what it changes from the default scenario;
* ``cli``: ``lawn`` and each subcommand with its usage and arguments (``--help`` at a fixed width of
  :data:`CLI_WIDTH` columns, the defaults of a machine with several cores).

The output depends on the code alone, not on the machine (no paths, times, terminal width or core
count): the same code writes the same bytes.

**Sphinx** (``setup``). A page holds a marker line ``<!-- lawn-docs: api PACKAGE -->``; on
``source-read`` the marker is replaced by the API reference of every module of the package (found
by walking it, so a new module is never left out), one section per module, rendered by autodoc.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sphinx.application import Sphinx

MARKER = re.compile(r"^<!-- lawn-docs: (?P<kind>[\w-]+)(?: (?P<arg>\S+))? -->$", re.MULTILINE)
#: A reST role (``:class:`~a.b.C```, ``:py:func:`title <a.f>```) or a MyST one (``{mod}`a.b```).
ROLE = re.compile(r"(?::[\w:]+:|\{[\w:]+\})`(?P<short>~)?(?P<target>[^`]+)`")
#: The width of the command line's help on its page (argparse's own follows the terminal).
CLI_WIDTH = 100
#: The core count the command-line page is written for (``--workers``' default depends on it).
CLI_CORES = 64


def plain(text: str) -> str:
    """``text`` with its reST and MyST roles made plain code spans: ``:class:`~a.b.C``` becomes
    ```C```, ``{mod}`a.b``` becomes ```a.b``` (Markdown that GitHub renders as the site does)."""

    def span(m: re.Match) -> str:
        target = m["target"]
        titled = re.fullmatch(r"(?P<title>.+?)\s*<(?P<ref>[^>]+)>", target)
        if titled:
            return f"`{titled['title']}`"
        return f"`{target.rsplit('.', 1)[-1]}`" if m["short"] else f"`{target}`"

    return ROLE.sub(span, text)


def _md_docstring(doc: str) -> str:
    """A class docstring written in Gymnasium's Markdown, its roles made code spans."""
    import inspect

    return plain(inspect.cleandoc(doc))


def _space(space: Any) -> str:
    return f"`{space!r}`".replace("\n", " ")


def _summary(rows: list[tuple[str, str]], cls: type, num_agvs: int) -> str:
    """The page body: the summary table (Gymnasium's env pages open with one), then the docstring."""
    table = [f"| | (default scenario: K = {num_agvs}) |", "|---|---|",
             *(f"| {a} | {b} |" for a, b in [*rows, ("Class", f"`{cls.__module__}.{cls.__name__}`")])]
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
        ("RL interface id", (f"`{rl.spec.id}`: actions {_space(rl.action_space)}, observations within "
                             f"±{float(rl.observation_space.high.max()):g}")),
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
        ("Action spaces", (f"`drone`: {_space(par.action_space('drone'))}; "
                           f"`agv_k`: {_space(par.action_space('agv_0'))}")),
        ("Observation spaces", (f"`drone`: shape {par.observation_space('drone').shape}; "
                                f"`agv_k`: shape {par.observation_space('agv_0').shape}")),
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
    return plain(" ".join((text or "").split()).replace("|", "\\|"))


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
        title = f"`{prefix[:-1]}`: `{cls.__name__}`" if prefix else "Top level: `ScenarioConfig`"
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


def _fixed_width(parser: argparse.ArgumentParser) -> None:
    """Format ``parser``'s help at :data:`CLI_WIDTH` columns, uncoloured, whatever the terminal."""
    cls = parser.formatter_class

    def formatter(prog: str) -> argparse.HelpFormatter:
        return cls(prog, width=CLI_WIDTH)

    parser.formatter_class = formatter
    if hasattr(parser, "color"):  # Python 3.14 colours help on a terminal
        parser.color = False


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, str, argparse.ArgumentParser]]:
    """``parser``'s subcommands, in its order: (name, its line in the parent's help, its parser)."""
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            lines = {a.dest: a.help or "" for a in action._choices_actions}
            out += [(name, lines.get(name, ""), sub) for name, sub in action.choices.items()]
    return out


def cli_page() -> str:
    """``lawn --help`` and every subcommand's (nested ones included), each under a heading."""
    from unittest import mock

    import lawn_cli as cli

    cli.COMMANDS  # noqa: B018  (imports every command first: only building the parser sees the fixed core count)
    with mock.patch("os.cpu_count", return_value=CLI_CORES):
        parser = cli.build_parser()
    out = []

    def section(level: int, summary: str, p: argparse.ArgumentParser) -> None:
        _fixed_width(p)
        help_text = p.format_help().rstrip()
        out.append(f"{'#' * level} `{p.prog}`\n")
        summary = " ".join(summary.split())
        if summary:
            out.append(f"{summary[0].upper()}{summary[1:]}.\n")
        out.append(f"```text\n{help_text}\n```\n")
        for _name, line, sub in _subcommands(p):
            section(min(level + 1, 3), line, sub)

    section(2, "", parser)
    return "\n".join(out)


def api_page(package: str) -> str:
    import importlib
    import pkgutil

    packages = ("lawn_env", "agents", "evaluation", "training", "paper", "lawn_cli")
    if package not in packages:
        raise ValueError(f"lawn-docs api {package!r}: valid packages: {', '.join(packages)}")
    root = importlib.import_module(package)
    modules = sorted(m.name for m in pkgutil.walk_packages(root.__path__, package + ".")
                     if not m.name.endswith("__main__"))
    names = [package, *modules]
    return "\n".join(f"## `{name}`\n\n```{{eval-rst}}\n.. automodule:: {name}\n```\n" for name in names)


#: The generated blocks' kinds (this file's command line): each returns the block's Markdown.
GENERATORS: dict[str, Callable[..., str]] = {"env": env_page, "parallel": parallel_page, "config": config_page,
                                             "presets": presets_table, "cli": cli_page}
#: The marker kinds that Sphinx expands when the site is built.
MARKERS: dict[str, Callable[..., str]] = {"api": api_page}


def generate(kind: str, arg: str | None = None) -> str:
    """The Markdown of generated block kind ``kind`` (with ``arg``: the env id of ``env``)."""
    if kind not in GENERATORS:
        raise ValueError(f"lawn-docs: unknown kind {kind!r}; valid: {', '.join(GENERATORS)}")
    return GENERATORS[kind](arg) if arg else GENERATORS[kind]()


def _expand(match: re.Match) -> str:
    kind, arg = match["kind"], match["arg"]
    if kind not in MARKERS:
        raise ValueError(f"lawn-docs marker {match.group(0)!r}: unknown kind; valid: {', '.join(MARKERS)} "
                         f"(the other pages are generated blocks: python docs/_ext/lawn_docs.py --help)")
    return MARKERS[kind](arg) if arg else MARKERS[kind]()


def _source_read(app: Sphinx, docname: str, source: list[str]) -> None:
    source[0] = MARKER.sub(_expand, source[0])


def setup(app: Sphinx) -> dict:
    app.connect("source-read", _source_read)
    return {"version": "2", "parallel_read_safe": True, "parallel_write_safe": True}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python docs/_ext/lawn_docs.py",
                                     description="Write the Markdown of a generated reference block of the docs.")
    parser.add_argument("kind", choices=list(GENERATORS), help="what to generate")
    parser.add_argument("arg", nargs="?", default=None, help="env: the environment id (e.g. lawn/Joint-v1)")
    parser.add_argument("--out", default=None, help="the Markdown file to write (default: standard output)")
    args = parser.parse_args(argv)
    if args.kind == "env" and not args.arg:
        parser.error("env needs an environment id, e.g. lawn/Joint-v1")
    if args.kind != "env" and args.arg:
        parser.error(f"{args.kind} takes no argument")
    try:
        text = generate(args.kind, args.arg)
    except ValueError as exc:
        print(f"lawn_docs: {exc}", file=sys.stderr)
        return 2
    if args.out is None:
        sys.stdout.write(text)
    else:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
