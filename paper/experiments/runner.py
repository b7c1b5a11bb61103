"""Run any experiment: its tables (missing sweep rows run, builders for the rest), its plot, its
claims checked on the tables; the claims' results go to ``OUT/claims.json`` and ``OUT/claims.md``,
which is all the reproduction page reads (:func:`paper.experiments.reproduction.write_reproduction`;
:func:`.claims.write_claims` writes them)."""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path

from evaluation.episode import read_csv, write_rows
from evaluation.sweep import SweepRow, SweepTableError, read_rows, run_sweep

from .base import Experiment, TableRow, Tables
from .claims import Claim
from .registry import EXPERIMENTS

__all__ = ["tables_of", "make_figures", "read_mode", "check_claims"]


def tables_of(exp: Experiment, out: Path, quick: bool = False, workers: int = 1, progress: bool = False,
              run: bool = True) -> Tables:
    """The experiment's tables in ``out/data`` (with ``run``: their missing rows run first)."""

    sweeps: dict[str, list[SweepRow]] = {}
    for name, spec in exp.sweeps(quick).items():
        path = out / "data" / f"{name}.csv"
        if run:
            try:
                run_sweep(spec, path, workers=workers, progress=progress)
            except SweepTableError as exc:
                raise SweepTableError(f"{exc}. For `lawn figures`: delete {path} or choose another --out (the "
                                      "figure's table was written by another spec or version)") from None
        sweeps[name] = read_rows(path).rows
    built: dict[str, list[TableRow]] = {}
    for name, builder in exp.builders.items():
        path = out / "data" / f"{name}.csv"
        if run and not path.exists():
            write_rows([r.as_row() for r in builder.build(out, quick)], path)
        built[name] = [builder.read(cells) for cells in read_csv(path)]
    return Tables(sweeps, built)


def make_figures(names: Sequence[str], out: Path, quick: bool = False, workers: int = 1,
                 progress: bool = True) -> dict[str, float]:
    """Build the named figures (all when ``names`` is empty): run the missing table rows, plot;
    returns seconds per figure and records, in ``out/timings.json``, the time of every figure whose
    rows were run (what building it from scratch takes)."""
    names = list(names) or list(EXPERIMENTS)
    unknown = [n for n in names if n not in EXPERIMENTS]
    if unknown:
        raise ValueError(f"unknown figures {unknown}; valid: {', '.join(EXPERIMENTS)}")
    out = Path(out)
    (out / "data").mkdir(parents=True, exist_ok=True)
    (out / "mode.json").write_text(json.dumps({"mode": "quick" if quick else "full"}) + "\n")
    timings = {}
    record = out / "timings.json"
    computed = json.loads(record.read_text()) if record.exists() else {}
    for name in names:
        start = time.perf_counter()
        exp = EXPERIMENTS[name]
        paths = [out / "data" / f"{t}.csv" for t in exp.table_names(quick)]
        before = [p.stat().st_mtime_ns if p.exists() else None for p in paths]
        exp.plot(tables_of(exp, out, quick, workers, progress), out / name)
        timings[name] = time.perf_counter() - start
        if [p.stat().st_mtime_ns if p.exists() else None for p in paths] != before:
            computed[name] = timings[name]
    record.write_text(json.dumps(computed, indent=2) + "\n")
    return timings


def read_mode(out: Path) -> str | None:
    """The mode (``"quick"`` or ``"full"``) of the figures in ``out`` (:func:`make_figures` records it in
    ``mode.json``); None where none is recorded."""
    try:
        mode = json.loads((Path(out) / "mode.json").read_text()).get("mode")
    except (OSError, ValueError, AttributeError):
        return None
    return mode if mode in ("quick", "full") else None


def check_claims(out: Path) -> list[Claim]:
    """The claims of every experiment whose tables exist in ``out/data``, checked on them."""
    out = Path(out)
    claims = []
    for exp in EXPERIMENTS.values():
        if not all((out / "data" / f"{t}.csv").exists() for t in exp.table_names()):
            continue
        claims += exp.claims(tables_of(exp, out, run=False))
    return claims
