"""The pipeline's records and their one file format: an :class:`EpisodeSpec` in (what to play, with
:class:`Play`, how), an :class:`EpisodeResult` out (what happened), from the worker pool to the CSV on
disk and back.

Every stage between passes these: :mod:`.run` plays specs into results, :mod:`.stats` reduces
results, :mod:`.report` formats the statistics, :mod:`.protocols` declares which specs to play.
A CSV of results (:func:`write_results`, :func:`read_results`) has one row per episode with the
fields' names as columns, in field order; a per-AGV or per-slot field is a JSON list in its cell, a
field a run did not record (an older file's) is no column at all, and reads back as None. A JSON file
of results is a list of objects with the same keys, a per-AGV or per-slot field a JSON array of
numbers; it stays valid JSON: a NaN is ``null``, an infinity the string ``"Infinity"`` or
``"-Infinity"``, both read back as the float they were.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from lawn_env import ScenarioConfig
from lawn_env.metrics import EpisodeMetrics

__all__ = ["TRANSIENT_SLOTS", "Play", "DEFAULT_PLAY", "EpisodeSpec", "Entry", "EpisodeResult", "Results",
           "write_results", "read_results", "write_rows", "write_csv", "read_csv", "parse_bool"]

#: Where an episode's control cost splits (docs/benchmark.md, "The cost's structure"): slots
#: 0..TRANSIENT_SLOTS-1 are the transient (the AGVs' recovery from their initial offsets while the
#: drone flies in from the area's edge), the slots from TRANSIENT_SLOTS on the sustained part.
#: ``--transient-slots`` of ``lawn evaluate`` and ``lawn benchmark`` moves it.
TRANSIENT_SLOTS = 20


@dataclass(frozen=True)
class Play:
    """How a batch of episodes is played: ``workers`` processes, a progress bar or not, and the
    transient/sustained split of the control cost (:func:`.run.split_cost`)."""

    workers: int = 1
    progress: bool = True
    transient_slots: int = TRANSIENT_SLOTS


#: The default way to play: one process, a progress bar, the default split.
DEFAULT_PLAY = Play()


class EpisodeSpec(NamedTuple):
    """One episode to play: the policy (or reference row) by name, the env it is evaluated on, the
    scenario, the seed and the policy's settings (``policy_kwargs`` of :func:`agents.make_policy`)."""

    policy: str
    env: str
    config: ScenarioConfig
    seed: int
    settings: Mapping[str, Any] = {}


class Entry(NamedTuple):
    """One row of a protocol's table before its seeds: a policy on an env, and the ``anchor:NAME`` a
    learned agent acts around (None for the others), found once when the protocol is declared."""

    policy: str
    env: str
    anchor: str | None = None


#: The fields written as a JSON list in one cell.
_ARRAYS = ("rmse_per_agv_m", "outage_rate_per_agv", "mean_power_w", "stage_costs")


@dataclass(frozen=True, eq=False)
class EpisodeResult:
    """One played episode: the metrics of MODEL.md §6 as fields (``lawn_env.core.episode_metrics``),
    the decision statistics, the control cost's transient and sustained parts (split at
    ``transient_slots``), the per-slot stage costs and the task (the preset) it was played on. Only
    the policy, env, seed and control cost are always there: a field an older table did not record is
    None, and the statistics skip it."""

    policy: str
    env: str
    seed: int
    slots: int | None = None
    control_cost: float = math.nan
    tracking_cost: float | None = None
    effort_cost: float | None = None
    rmse_m: float | None = None
    rmse_per_agv_m: np.ndarray | None = field(default=None, repr=False)  # (K,)
    outage_rate: float | None = None
    outage_rate_predicted: float | None = None
    outage_rate_per_agv: np.ndarray | None = field(default=None, repr=False)  # (K,)
    mean_power_w: np.ndarray | None = field(default=None, repr=False)  # (K,): per link, every slot counted
    drone_path_length_m: float | None = None
    max_tracking_error_m: float | None = None
    diverged: bool | None = None
    decision_time_median_s: float | None = None
    decision_time_p95_s: float | None = None
    ao_iterations_mean: float | None = None
    qp_fallbacks: int | None = None
    transient_cost: float | None = None
    sustained_cost: float | None = None
    transient_slots: int | None = None
    stage_costs: np.ndarray | None = field(default=None, repr=False)  # (slots,); None once a table drops it
    task: str | None = None  # the preset; None: the one scenario of a paper-protocol run

    def value(self, metric: str) -> float | None:
        """A scalar field as a float (None when not recorded); ValueError naming the fields otherwise."""
        if metric not in _SCALARS:
            raise ValueError(f"metric {metric!r} is not a scalar field of an episode result; valid: "
                             f"{', '.join(_SCALARS)}")
        got = getattr(self, metric)
        return None if got is None else float(got)

    def with_(self, **changes: Any) -> EpisodeResult:
        """A copy with ``changes`` (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    def as_row(self) -> dict[str, Any]:
        """The CSV row: every recorded field in field order (arrays as JSON lists, the flag as 0/1)."""
        row: dict[str, Any] = {}
        for f in _FIELDS:
            got = getattr(self, f.name)
            if got is None:
                continue
            if f.name in _ARRAYS:
                got = json.dumps(np.asarray(got, dtype=float).tolist())
            elif f.name == "diverged":
                got = int(got)
            row[f.name] = got
        return row

    @classmethod
    def from_metrics(cls, metrics: EpisodeMetrics, **fields: Any) -> EpisodeResult:
        """The result of an episode's metrics (MODEL.md §6, :class:`lawn_env.metrics.EpisodeMetrics`)
        and ``fields`` (the policy, env and seed, the decision statistics, the cost's split, the stage
        costs), each value as its field's type (arrays as float arrays, the flag as a bool)."""
        values = {**metrics.as_dict(), **fields}
        return cls(**{k: v for k, v in ((k, _parse(k, v)) for k, v in values.items()) if v is not None})

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> EpisodeResult:
        """The result of a row: a CSV row's strings or a dict of values (the metrics of an episode);
        an absent or empty cell is None. ValueError naming a column that is not a field."""
        unknown = [k for k in row if k not in _TYPES]
        if unknown:
            raise ValueError(f"columns {unknown} are not fields of an episode result; valid: {', '.join(_TYPES)}")
        values = {k: _parse(k, v) for k, v in row.items() if not (isinstance(v, str) and not v.strip())}
        return cls(**{k: v for k, v in values.items() if v is not None})


_FIELDS = dataclasses.fields(EpisodeResult)
_TYPES = {f.name: str(f.type) for f in _FIELDS}
#: The fields a statistic can reduce (every number that is not a per-AGV or per-slot list).
_SCALARS = tuple(f.name for f in _FIELDS if f.name not in _ARRAYS and f.name not in ("policy", "env", "task"))
#: Evaluation results, the input of every statistic and table.
Results = Sequence[EpisodeResult]


def _parse(name: str, value: Any) -> Any:
    if value is None:
        return None
    if name in _ARRAYS:
        return np.asarray(json.loads(value) if isinstance(value, str) else value, dtype=float)
    if name in ("policy", "env", "task"):
        return str(value)
    if name == "diverged":
        return parse_bool(value)
    if _TYPES[name].startswith("int"):
        return int(value)
    return float(value)


def write_results(results: Iterable[EpisodeResult], path: str | Path, atomic: bool = False) -> Path:
    """Results as one CSV row each (:meth:`EpisodeResult.as_row`; the columns in field order, a field
    some results do not record empty in theirs), or as JSON by the extension; ``atomic`` as
    :func:`write_csv`'s."""
    if Path(path).suffix.lower() == ".json":
        return write_rows([_json_row(r) for r in results], path)
    rows = [r.as_row() for r in results]
    if not atomic:
        return write_rows(rows, path)
    return write_csv(rows, path, atomic=True)


def read_results(path: str | Path) -> list[EpisodeResult]:
    """The results of a CSV or, by the extension, a JSON file written by :func:`write_results` (an
    empty list when it does not exist)."""
    path = Path(path)
    if path.suffix.lower() != ".json":
        return [EpisodeResult.from_row(row) for row in read_csv(path)]
    if not path.exists():
        return []
    rows = json.loads(path.read_text())
    if not isinstance(rows, list) or not all(isinstance(row, dict) for row in rows):
        raise ValueError(f"{str(path)!r}: not a JSON list of episode results (objects)")
    return [EpisodeResult.from_row({k: _from_json(k, v) for k, v in row.items()}) for row in rows]


def _json_row(result: EpisodeResult) -> dict[str, Any]:
    """:meth:`EpisodeResult.as_row` for a JSON file: the arrays as lists of numbers, every float
    finite or null (NaN) or ``"Infinity"``/``"-Infinity"``, so that the file is valid JSON."""
    row = result.as_row()
    for name in row:
        got = getattr(result, name)
        if name in _ARRAYS:
            row[name] = [_json_float(x) for x in np.asarray(got, dtype=float).reshape(-1).tolist()]
        elif isinstance(got, (float, np.floating)):
            row[name] = _json_float(float(got))
        elif isinstance(got, np.integer):
            row[name] = int(got)
    return row


def _json_float(x: float) -> float | str | None:
    """A float as JSON has it: NaN as null, an infinity as ``"Infinity"`` or ``"-Infinity"``."""
    if math.isnan(x):
        return None
    if math.isinf(x):
        return "Infinity" if x > 0 else "-Infinity"
    return x


def _from_json(name: str, value: Any) -> Any:
    """A JSON file's value as :meth:`EpisodeResult.from_row` takes it: a float field's (or an
    array's element's) null is NaN and its ``"Infinity"``/``"-Infinity"`` the infinity."""
    if name in _ARRAYS and isinstance(value, list):
        return [math.nan if x is None else float(x) for x in value]
    if value is None and _TYPES.get(name, "").startswith("float"):
        return math.nan
    return value


def write_rows(rows: Sequence[Mapping[str, Any]], path: str | Path) -> Path:
    """Write rows as CSV or JSON, chosen by the file extension (``.csv`` or ``.json``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".json"):
        raise ValueError(f"--out {str(path)!r}: the extension must be .csv or .json, got {suffix or 'none'!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".json":
        path.write_text(json.dumps(list(rows), indent=2))
    else:
        write_csv(rows, path)
    return path


def write_csv(rows: Sequence[Mapping[str, Any]], path: Path | str, atomic: bool = False) -> Path:
    """Rows as CSV with the union of their keys as columns (first-seen order). ``atomic`` writes a
    temporary file, syncs it and renames it over ``path``, so a reader never sees half a table."""
    path = Path(path)
    fields: list[str] = []
    for row in rows:
        fields += [k for k in row if k not in fields]
    if all(f in _TYPES for f in fields):  # episode results: their fields' order
        fields = [f for f in _TYPES if f in fields]
    target = path.with_suffix(path.suffix + ".tmp") if atomic else path
    with target.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
        if atomic:
            fh.flush()
            os.fsync(fh.fileno())
    if atomic:
        os.replace(target, path)
    return path


def read_csv(path: Path | str) -> list[dict[str, str]]:
    """The rows of a CSV file as dicts of strings (an empty list when the file does not exist)."""
    path = Path(path)
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def parse_bool(value: object) -> bool:
    """A boolean table cell: a bool, or ``true``/``false``/``1``/``0`` in any case."""
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("true", "1"):
        return True
    if text in ("false", "0"):
        return False
    raise ValueError(f"not a boolean table value: {value!r}")
