"""docs/LEARNED.md's zoo blocks (``lawn zoo build``): :func:`build_zoo` evaluates every finished
recipe run by the stages of :mod:`training.zoo` (and the distilled agents by :mod:`training.distil`),
writes the tables into the page's blocks, the learning curves and the episodes beside it, and
exports each recipe's validation-selected run to the zoo."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.learned import ZOO_DIR
from evaluation.episode import EpisodeResult, EpisodeSpec, read_results, write_results
from evaluation.run import evaluate
from evaluation.seeds import TEST_EPISODES, VALIDATION_SEED_BASE
from lawn_env import ScenarioConfig
from training.distil import evaluate_distil, export_distil
from training.recipes import RECIPES, SECTIONS, Recipe, finished, recipe
from training.zoo import (
    ZooEvaluation,
    ZooTables,
    evaluate_zoo,
    export_zoo,
    finished_runs,
    plot_curves,
    render_zoo,
    zoo_tables,
)

from .pages import block_names, replace_body

__all__ = ["build_zoo", "merged_rows", "SECTION_BLOCKS"]

#: The sections written into one generated block each (both their tables), beside ``main``'s two
#: blocks (``zoo-main``, ``zoo-runs``) and ``distil``'s own.
SECTION_BLOCKS = {"fleet": "zoo-fleet", "scratch": "zoo-scratch"}


def build_zoo(runs: Path, out_doc: Path, workers: int = 2, progress: bool = True,
              episodes: int = TEST_EPISODES, export: bool = True, target: Path = ZOO_DIR,
              only: Sequence[str] | None = None) -> str:
    """The four stages over the finished recipe runs: write the tables into ``out_doc`` (and its
    learning-curve plot), export each recipe's validation-selected run into ``target``; returns the
    recipe tables (Markdown). The page has sections (:data:`training.recipes.SECTIONS`): ``only``
    (recipe names) rebuilds the sections those recipes are in and keeps the rest of the page, and of
    ``docs/learned/episodes.csv``, as it is. Everything is evaluated and rendered before the first
    file is written (the page and the episodes are replaced whole, through a temporary file)."""
    names = list(only or [])
    sections, out_doc = _sections(names, Path(out_doc)), Path(out_doc)
    built: dict[str, tuple[ZooEvaluation, ZooTables]] = {}
    distilled = (evaluate_distil(Path(runs), workers, progress, episodes) if _wanted("distil", sections, names, runs)
                 else None)
    for section in (x for x in sections if x != "distil" and _wanted(x, sections, names, runs)):
        ev = evaluate_zoo(finished_runs(Path(runs), _of_section(section)), episodes, workers, progress)
        built[section] = (ev, zoo_tables(ev))
    if not built and distilled is None:
        raise ValueError(f"{runs}: no finished recipe runs (lawn zoo train --runs {runs} trains them)")
    rendered = {section: render_zoo(tables) for section, (_, tables) in built.items()}
    page = _read_text(out_doc)
    source = "lawn zoo build" + (f" --only {' '.join(names)}" if names else "")
    if "main" in built:
        for name, text in zip(("zoo-main", "zoo-runs"), rendered["main"], strict=True):
            page = replace_body(page, name, text, source=source, where=str(out_doc))
    for section, block in SECTION_BLOCKS.items():
        if section in built:
            page = replace_body(page, block, "\n\n".join(rendered[section]), source=source, where=str(out_doc))
    if distilled is not None:
        page = replace_body(page, "zoo-distil", distilled.block, source=source, where=str(out_doc))
        (out_doc.parent / "learned").mkdir(parents=True, exist_ok=True)
        write_results(distilled.rows, out_doc.parent / "learned" / "distil.csv", atomic=True)
    if "main" in built:
        _plot_main_curves(built["main"][0], out_doc, workers)
    if built:
        rows = merged_rows(read_results(out_doc.parent / "learned" / "episodes.csv"), built)
        write_results(rows, out_doc.parent / "learned" / "episodes.csv", atomic=True)
    _write_atomic(out_doc, page)
    if export:
        for ev, tables in built.values():
            export_zoo(tables, ev, target)
        if distilled is not None:
            export_distil(distilled, target)
    return "\n\n".join([table for table, _ in rendered.values()] + ([distilled.block] if distilled else []))


def _sections(names: list[str], out_doc: Path) -> list[str]:
    """The sections ``names`` (recipes; none: all) are in, after checking the page has their blocks."""
    for name in names:
        recipe(name)  # an unknown name is an error that names the recipes
    sections = [x for x in SECTIONS if not names or any(RECIPES[n].section == x for n in names)]
    for section, block in (*SECTION_BLOCKS.items(), ("distil", "zoo-distil")):
        if names and "main" not in sections and section in sections and block not in block_names(_read_text(out_doc)):
            raise ValueError(f"{out_doc}: no generated block {block!r} to rebuild; build the whole page (lawn zoo "
                             "build without --only)")
    return sections


def _of_section(section: str) -> dict[str, Recipe]:
    return {n: r for n, r in RECIPES.items() if r.section == section}


def _wanted(section: str, sections: list[str], names: list[str], runs: Path) -> bool:
    """Rebuild ``section``: it was named, or (building everything) it has a finished run."""
    return section in sections and (bool(names) or any(finished(Path(runs) / r.name / f"seed-{s}", r.timesteps)
                                                       for r in _of_section(section).values() for s in r.seeds))


def _plot_main_curves(ev: ZooEvaluation, out_doc: Path, workers: int) -> None:
    """The main section's learning curves (``learned/curves.png`` beside the page), with rg-mpc's
    cost on the first ten validation seeds."""
    specs = {env: [EpisodeSpec("rg-mpc", env, ScenarioConfig(), VALIDATION_SEED_BASE + i) for i in range(10)]
             for env in ev.envs}
    reference = {env: evaluate(s, workers=workers, progress=False) for env, s in specs.items()}
    (out_doc.parent / "learned").mkdir(parents=True, exist_ok=True)
    plot_curves(ev.found, {env: float(np.mean([r.control_cost for r in rs])) for env, rs in reference.items()},
                out_doc.parent / "learned" / "curves.png")


def _read_text(path: Path) -> str:
    """The file's text, empty when it does not exist."""
    return Path(path).read_text() if Path(path).exists() else ""


def _write_atomic(path: Path, text: str) -> None:
    """Write ``text`` through a temporary file renamed over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _run_of(policy: str) -> str | None:
    """The recipe a learned row's run belongs to (``PREFIX:.../<recipe>/seed-<s>``), else None."""
    path = Path(policy.partition(":")[2])
    return path.parent.name if policy.partition(":")[0] in ("sb3", "bc", "marl") and path.name.startswith("seed-") \
        else None


def merged_rows(old: list[EpisodeResult], built: Mapping[str, tuple[ZooEvaluation, Any]]) -> list[EpisodeResult]:
    """The episodes of the rebuilt sections (each (policy, env, seed) once: the sections share
    their references), with, when a section was not rebuilt, the recorded episodes the new ones do
    not replace, less the rebuilt sections' runs."""
    new: dict[tuple[str, str, int], EpisodeResult] = {}
    for ev, _ in built.values():
        for r in ev.rows:
            new.setdefault((r.policy, r.env, r.seed), r)
    if all(section in built for section in SECTIONS if section != "distil"):  # the distil episodes: distil.csv
        return list(new.values())
    rebuilt = {name for name, r in RECIPES.items() if r.section in built}
    kept = [r for r in old if (r.policy, r.env, r.seed) not in new and _run_of(r.policy) not in rebuilt]
    return kept + list(new.values())
