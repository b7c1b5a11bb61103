"""``lawn sweep SPEC``: a grid of config fields x policies x seeds, one tidy row per run.

A spec (YAML or JSON, or a dict) names the grid::

    name: blocklength
    env: lawn/Joint-v1
    preset: default                     # base scenario (a grid key "preset" switches it)
    set: {num_slots: 120}               # fixed overrides (dotted keys)
    grid: {channel.blocklength: [256, 1024], channel.infinite_blocklength: [false]}
    policies: [rg-mpc, ao-mpc, epa]
    seeds: 10                           # or an explicit list

The spec is a :class:`SweepSpec` (:mod:`.sweep_spec` reads and checks it). A row, a
:class:`SweepRow`, holds the grid values and the episode's :class:`EpisodeResult` (its policy, seed
and metrics), the resolved config, its stable hash and the software version, and is keyed by
(config hash, policy, policy arguments, seed, env, version): a rerun skips the rows it would produce
again, so a killed sweep resumes, while a changed spec or lawn version reruns. An incomplete
(truncated) or duplicate row is dropped and rerun; a table holding rows this spec would not produce
is refused unless ``extend=True`` (``--extend``). The table (CSV) is rewritten atomically after
every run, through the rows' records: the same columns in the same order, each cell as it was. Runs
go to a local process pool, or to Ray with ``backend="ray"`` (optional extra).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import lawn_env
from agents.errors import MissingExtra

from .cells import markdown_table
from .episode import EpisodeResult, read_csv, write_csv
from .pool import worker_pool
from .run import run_episode
from .stats import mean_ci
from .sweep_spec import SpecValue, SweepSpec, expand, load_spec, point_config

__all__ = ["SpecValue", "SweepSpec", "SweepRow", "SweepTable", "SweepTableError", "load_spec", "expand", "run_sweep",
           "read_table", "read_rows", "config_hash", "summarize_sweep"]

class SweepTableError(ValueError):
    """The table given to a sweep holds rows this spec would not produce."""


#: Fields every sweep row must hold, parsed to check a row is complete (a truncated write is not).
_REQUIRED = {"policy": str, "seed": int, "env": str, "lawn_version": str, "config_hash": str, "policy_args": str,
             "slots": int, "control_cost": float, "rmse_m": float, "outage_rate": float}
#: The columns of the episode's result (:class:`EpisodeResult`), and those a sweep adds around them.
_RESULT_COLUMNS = frozenset(f.name for f in dataclasses.fields(EpisodeResult))
_SWEEP_COLUMNS = frozenset({"sweep", "lawn_version", "config_hash", "policy_args", "config"})
#: A row's key: config hash, policy, policy arguments, seed, env, version.
RowKey = tuple[str, str, str, int, str, str]


def config_hash(config_dict: Mapping[str, Any], policy_args: Mapping[str, Any] | None = None) -> str:
    """A stable hash (16 hex digits) of a resolved config (``ScenarioConfig.to_dict()``) and, when
    given, a policy's arguments: equal inputs give equal hashes in any process."""
    payload = json.dumps({"config": config_dict, "policy_args": dict(policy_args or {})}, sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


def _cell(value: SpecValue) -> str:
    """A grid value as the table's cell holds it (what :mod:`csv` writes for it)."""
    return "" if value is None else str(value)


@dataclass(frozen=True, eq=False)
class SweepRow:
    """One run of a sweep: the sweep's name, the grid point's values, the episode's
    :class:`EpisodeResult` (its policy, env and seed among them) and what keys the row: the
    version, the resolved config (sorted JSON) and its hash, the policy's arguments (sorted JSON).

    The grid values are the table's cells (text, as read back: a grid may mix presets, numbers and
    flags, and a row kept beside another sweep's has empty cells for that sweep's keys); a reader
    parses the ones it compares. :meth:`as_row` writes the table's columns: the sweep's name, the
    grid, the result's fields, then the key's; :meth:`from_row` reads them back."""

    sweep: str
    grid: Mapping[str, str]
    result: EpisodeResult
    lawn_version: str
    config_hash: str
    policy_args: str
    config: str

    @property
    def policy(self) -> str:
        return self.result.policy

    @property
    def seed(self) -> int:
        return self.result.seed

    def metric(self, name: str) -> float:
        """A scalar metric of the episode (:meth:`EpisodeResult.value`); NaN where the run did not
        record it."""
        got = self.result.value(name)
        return math.nan if got is None else got

    @property
    def key(self) -> RowKey:
        """What a rerun compares: config hash, policy, policy arguments, seed, env and version."""
        return (self.config_hash, self.policy, self.policy_args, self.seed, self.result.env, self.lawn_version)

    def as_row(self) -> dict[str, object]:
        """The table's row: ``sweep``, the grid values, the result's cells, then the key's columns."""
        return {"sweep": self.sweep, **self.grid, **self.result.as_row(), "lawn_version": self.lawn_version,
                "config_hash": self.config_hash, "policy_args": self.policy_args, "config": self.config}

    @classmethod
    def from_row(cls, cells: Mapping[str, str]) -> SweepRow:
        """The row of a table's cells: the result's columns parsed (:meth:`EpisodeResult.from_row`),
        every column that is neither the result's nor the key's a grid value."""
        return cls(sweep=cells.get("sweep", ""),
                   grid={k: v for k, v in cells.items() if k not in _RESULT_COLUMNS and k not in _SWEEP_COLUMNS},
                   result=EpisodeResult.from_row({k: v for k, v in cells.items() if k in _RESULT_COLUMNS}),
                   lawn_version=cells["lawn_version"], config_hash=cells["config_hash"],
                   policy_args=cells["policy_args"], config=cells["config"])


def _problem(row: Mapping[str, str | None]) -> str | None:
    """Why a row read back from a table is unusable, or None."""
    for field_, kind in _REQUIRED.items():
        value = row.get(field_)
        if value is None or value == "":
            return f"missing {field_!r}"
        try:
            kind(value)
        except (TypeError, ValueError):
            return f"{field_}={value!r} is not {kind.__name__}"
    if None in row or any(v is None for v in row.values()):
        return "a truncated or malformed line"
    try:  # the last column: a cut line ends inside it, and its hash is the row's key
        if config_hash(json.loads(row.get("config") or "")) != row["config_hash"]:
            return "its config does not match its config_hash"
    except (TypeError, ValueError):
        return "its config is not complete JSON (a truncated line)"
    return None


class SweepTable(NamedTuple):
    """A sweep table's usable rows, a message per row dropped (incomplete or duplicate), and the
    header they were read under (none without usable rows), which a rewrite keeps."""

    rows: list[SweepRow]
    dropped: list[str]
    columns: tuple[str, ...] = ()


def read_rows(path: Path) -> SweepTable:
    """The usable rows of a sweep table and a message per dropped row (incomplete or duplicate)."""
    rows: list[SweepRow] = []
    dropped, seen = [], set()
    cells = read_csv(path)
    for i, row in enumerate(cells, start=2):  # line 1 is the header
        why = _problem(row)
        parsed = None
        if why is None:
            try:
                parsed = SweepRow.from_row(row)
            except ValueError as exc:
                why = f"unreadable ({exc})"
        if parsed is not None and parsed.key in seen:
            why = "a duplicate of an earlier row"
        if parsed is None or why is not None:
            dropped.append(f"{Path(path).name} line {i}: {why}")
            continue
        seen.add(parsed.key)
        rows.append(parsed)
    header = tuple(k for k in cells[0] if isinstance(k, str)) if rows else ()  # a long line's extra cells: key None
    return SweepTable(rows, dropped, header)


def read_table(path: Path) -> list[SweepRow]:
    """Every row of a sweep table as written (an empty list before the first row); ValueError on a
    row that does not parse (:func:`read_rows` drops those instead)."""
    return [SweepRow.from_row(row) for row in read_csv(path)]


def _write(rows: Sequence[SweepRow], columns: Sequence[str], table: Path) -> None:
    """The table, atomically: ``columns`` (the header its rows were read under) first, in their
    order, then the columns the other rows bring, as they first come."""
    header = dict.fromkeys(columns, "")
    write_csv([{**header, **r.as_row()} for r in rows], table, atomic=True)


class _Run(NamedTuple):
    """One run of a sweep, as a worker takes it: the grid point, the policy and its arguments, the
    seed, the env, the point's resolved config (``ScenarioConfig.to_dict()``) and the sweep's name."""

    point: Mapping[str, SpecValue]
    policy: str
    policy_args: Mapping[str, Any]
    seed: int
    env: str
    config: Mapping[str, Any]
    sweep: str


def _run(task: _Run) -> SweepRow:
    cfg = lawn_env.ScenarioConfig.from_dict(task.config)
    result = run_episode(task.policy, task.env, cfg, task.seed, task.policy_args)
    return SweepRow(sweep=task.sweep, grid={k: _cell(v) for k, v in task.point.items()}, result=result,
                    lawn_version=lawn_env.__version__, config_hash=config_hash(task.config),
                    policy_args=json.dumps(dict(task.policy_args), sort_keys=True),
                    config=json.dumps(cfg.to_dict(), sort_keys=True))


def _tasks(spec: SweepSpec) -> dict[RowKey, _Run]:
    """The runs of ``spec`` by the key of the row each writes, in the spec's order (grid point,
    policy, seed)."""
    wanted: dict[RowKey, _Run] = {}
    for point in expand(spec):
        cfg_dict = point_config(spec, point).to_dict()
        chash = config_hash(cfg_dict)
        for policy in spec.policies:
            policy_kwargs = spec.policy_args.get(policy, {})
            args = json.dumps(dict(policy_kwargs), sort_keys=True)
            for seed in spec.seeds:
                key = (chash, policy, args, int(seed), spec.env, lawn_env.__version__)
                wanted[key] = _Run(point, policy, policy_kwargs, seed, spec.env, cfg_dict, spec.name)
    return wanted


def run_sweep(spec: str | Path | Mapping[str, Any] | SweepSpec, table: str | Path, workers: int = 1,
              backend: str = "process", progress: bool = True, max_runs: int | None = None,
              extend: bool = False) -> list[SweepRow]:
    """Run the missing rows of ``spec`` into ``table`` (CSV); returns all rows of the table.

    Rows are keyed by config hash, policy, policy arguments, seed, env and version (module
    docstring); unusable rows are dropped and rerun, with a warning. A table holding rows this spec
    would not produce raises :class:`SweepTableError` unless ``extend``. ``max_runs`` stops after
    that many new runs (for tests of resumption).
    """
    spec = load_spec(spec)
    table = Path(table)
    table.parent.mkdir(parents=True, exist_ok=True)
    wanted = _tasks(spec)
    rows, dropped, columns = read_rows(table)
    if dropped:
        warnings.warn(f"{table}: dropped {len(dropped)} unusable rows, to be rerun: " + "; ".join(dropped[:5])
                      + (" ..." if len(dropped) > 5 else ""), stacklevel=2)
    foreign = [r for r in rows if r.key not in wanted]
    if foreign and not extend:
        raise SweepTableError(
            f"{table} holds {len(foreign)} rows that sweep {spec.name!r} would not produce (another spec, preset, "
            f"set, grid or policy arguments, another lawn version than {lawn_env.__version__}, or a table written "
            "before rows carried config hashes); write to a new table, or pass --extend (extend=True) to keep them "
            "beside this sweep's rows")
    done = {r.key for r in rows}
    tasks = [task for key, task in wanted.items() if key not in done]
    if max_runs is not None:
        tasks = tasks[:max_runs]
    if not tasks:
        ordered = _canonical(rows, wanted)
        if dropped or [r.key for r in ordered] != [r.key for r in rows]:
            _write(ordered, columns, table)
        return ordered
    from tqdm.auto import tqdm

    bar = tqdm(total=len(tasks), desc=spec.name, unit="run", disable=None if progress else True, leave=False)
    try:
        for row in execute(_run, tasks, workers, backend):
            rows.append(row)
            _write(rows, columns, table)
            bar.update()
    finally:
        bar.close()
    rows, _, columns = read_rows(table)
    if all(k in {r.key for r in rows} for k in wanted):  # complete: one order, however it was interrupted
        _write(_canonical(rows, wanted), columns, table)
        rows = read_rows(table).rows
    return rows


def _canonical(rows: list[SweepRow], wanted: Mapping[RowKey, object]) -> list[SweepRow]:
    """Rows in the spec's order (grid point, policy, seed), rows of other specs (``extend``) first
    as they were: a finished table is the same file whatever order its runs finished in."""
    rank = {key: i for i, key in enumerate(wanted)}
    foreign = [r for r in rows if r.key not in rank]
    return foreign + sorted((r for r in rows if r.key in rank), key=lambda r: rank[r.key])


def execute(fn: Callable[[Any], Any], tasks: Sequence[Any], workers: int, backend: str) -> Iterator[Any]:
    """Yield ``fn(task)`` for every task as the runs finish, on a process pool or on Ray
    (local, or the cluster at ``$RAY_ADDRESS``); ``fn`` must be a module-level function."""
    if backend == "ray":
        try:
            import ray
        except ImportError:

            raise MissingExtra("--backend ray needs Ray: pip install -e '.[ray]'") from None
        if not ray.is_initialized():
            ray.init(address=os.environ.get("RAY_ADDRESS"), num_cpus=None if os.environ.get("RAY_ADDRESS") else workers,
                     include_dashboard=False, log_to_driver=False)
        remote = ray.remote(fn)
        pending = [remote.remote(t) for t in tasks]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            yield ray.get(ready[0])
        return
    if backend != "process":
        raise ValueError(f"unknown backend {backend!r}; valid: process, ray")
    if workers <= 1:
        for t in tasks:
            yield fn(t)
        return
    from concurrent.futures import FIRST_COMPLETED, wait


    with worker_pool(workers) as pool:
        futures = {pool.submit(fn, t) for t in tasks}
        while futures:
            finished, futures = wait(futures, return_when=FIRST_COMPLETED)
            for fut in finished:
                yield fut.result()


def summarize_sweep(rows: Sequence[SweepRow], grid_keys: Sequence[str],
                    metrics: Sequence[str] = ("control_cost", "rmse_m", "outage_rate")) -> str:
    """Markdown table: mean ± 95 % interval of ``metrics`` per grid point and policy."""
    groups: dict[tuple[str, ...], list[SweepRow]] = {}
    for r in rows:
        groups.setdefault((*(r.grid.get(k, "") for k in grid_keys), r.policy), []).append(r)
    table = []
    for key, members in groups.items():
        stats = [mean_ci(r.metric(m) for r in members) for m in metrics]
        table.append([*key, str(len(members)), *(f"{mean:.4g} ± {half:.2g}" for mean, half in stats)])
    return markdown_table([*grid_keys, "policy", "runs", *metrics], table)
