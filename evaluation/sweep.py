"""``lawn sweep SPEC``: a grid of config fields x policies x seeds, one tidy row per run.

A spec (YAML or JSON, or a dict) names the grid::

    name: blocklength
    env: lawn/Joint-v1
    preset: default                     # base scenario (a grid key "preset" switches it)
    set: {num_slots: 120}               # fixed overrides (dotted keys)
    grid: {channel.blocklength: [256, 1024], channel.infinite_blocklength: [false]}
    policies: [rg-mpc, ao-mpc, epa]
    seeds: 10                           # or an explicit list

A row holds the grid values, the policy, the seed, the episode metrics, the resolved config, its
stable hash and the software version, and is keyed by (config hash, policy, policy arguments, seed,
env, version): a rerun skips the rows it would produce again, so a killed sweep resumes, while a
changed spec or lawn version reruns. An incomplete (truncated) or duplicate row is dropped and rerun;
a table holding rows this spec would not produce is refused unless ``extend=True`` (``--extend``).
The table (CSV) is rewritten atomically after every run. Runs go to a local process pool, or to Ray
with ``backend="ray"`` (optional extra).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import lawn_env
from agents import make_policy
from agents.errors import MissingExtra
from lawn_env import presets

from .cells import markdown_table
from .episode import read_csv, write_csv
from .pool import worker_pool
from .run import run_episode
from .stats import mean_ci

__all__ = ["SweepTable", "SweepSpec", "SweepTableError", "load_spec", "expand", "run_sweep", "read_table", "read_rows",
           "config_hash", "summarize_sweep"]


class SweepSpec(dict[str, Any]):
    """A validated sweep specification."""


_SPEC_KEYS = {"name", "env", "preset", "set", "grid", "policies", "seeds", "policy_args"}


def _read_spec(spec: str | Path | Mapping[str, Any]) -> tuple[Any, str]:
    """The spec's document (a YAML or JSON file, or the mapping itself) and how errors name it."""
    source = "the sweep spec"
    if not isinstance(spec, (Mapping, str, os.PathLike)):
        raise TypeError(f"spec must be a mapping or the path of a YAML/JSON file; got {type(spec).__name__}")
    if not isinstance(spec, Mapping):
        path = Path(spec)
        source = f"sweep spec {str(path)!r}"
        if not path.exists():
            raise ValueError(f"{source} does not exist")
        text = path.read_text()
        try:
            if path.suffix.lower() == ".json":
                spec = json.loads(text)
            else:
                import yaml

                spec = yaml.safe_load(text)
        except ValueError as exc:  # json.JSONDecodeError
            raise ValueError(f"{source} is not valid JSON: {exc}") from None
        except Exception as exc:  # yaml.YAMLError and its subclasses
            mark = getattr(exc, "problem_mark", None)
            where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
            raise ValueError(f"{source} is not valid YAML{where}: {getattr(exc, 'problem', None) or exc}") from None
    return spec, source


def _seed_list(seeds: Any, source: str) -> list[int]:
    """A spec's ``seeds``: a count (seeds 0..n-1) or a list of seeds >= 0."""
    if isinstance(seeds, bool) or not isinstance(seeds, (int, list, tuple)):
        raise ValueError(f"{source}: seeds must be a count >= 1 or a non-empty list of seeds >= 0; got {seeds!r}")
    if isinstance(seeds, int):
        if seeds < 1:
            raise ValueError(f"{source}: seeds={seeds} must be >= 1 (a count) or a non-empty list of seeds >= 0")
        return list(range(seeds))
    if not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
        raise ValueError(f"{source}: seeds={seeds!r} must be a non-empty list of integers >= 0")
    return [int(s) for s in seeds]


def load_spec(spec: str | Path | Mapping[str, Any]) -> SweepSpec:
    """A sweep spec (a mapping or a YAML/JSON file) validated: its keys, grid, policies, seeds and env, and
    every grid point's config and policy built once, so a bad spec fails before any episode runs."""
    spec, source = _read_spec(spec)
    if not isinstance(spec, Mapping):
        raise ValueError(f"{source} must be a mapping of {', '.join(sorted(_SPEC_KEYS))}; got "
                         f"{type(spec).__name__ if spec is not None else 'an empty document'}")
    unknown = set(spec) - _SPEC_KEYS
    if unknown:
        raise ValueError(f"unknown sweep spec keys {sorted(unknown)}; valid: {', '.join(sorted(_SPEC_KEYS))}")
    grid = spec.get("grid", {})
    if not isinstance(grid, Mapping):
        raise ValueError(f"{source}: grid must map config keys to lists of values; got {grid!r}")
    for key, values in grid.items():
        if not isinstance(values, (list, tuple)) or not values:
            raise ValueError(f"{source}: grid key {key!r} must map to a non-empty list of values; got {values!r}")
    policies = spec.get("policies", ["rg-mpc"])
    if not isinstance(policies, (list, tuple)) or not policies or not all(isinstance(p, str) for p in policies):
        raise ValueError(f"{source}: policies must be a non-empty list of policy names; got {policies!r}")
    out = SweepSpec(name=spec.get("name", "sweep"), env=spec.get("env", "lawn/Joint-v1"),
                    preset=spec.get("preset", "default"), set=dict(spec.get("set", {})),
                    grid={k: list(v) for k, v in dict(spec.get("grid", {})).items()},
                    policies=list(spec.get("policies", ["rg-mpc"])), policy_args=dict(spec.get("policy_args", {})))
    out["seeds"] = _seed_list(spec.get("seeds", 5), source)
    if out["env"] not in lawn_env.ENV_IDS:
        raise ValueError(f"sweep env {out['env']!r}; valid: {', '.join(lawn_env.ENV_IDS)}")

    for point in expand(out):  # validate every grid point and policy before running anything
        cfg = point_config(out, point)
        for name in out["policies"]:
            make_policy(name, cfg, env_id=out["env"], **out["policy_args"].get(name, {}))
    return out


def point_config(spec: Mapping[str, Any], point: Mapping[str, Any]) -> lawn_env.ScenarioConfig:
    """The scenario of one grid point: its ``preset`` (a grid key may switch presets) with the
    spec's fixed overrides, then the point's other values."""
    rest = {k: v for k, v in point.items() if k != "preset"}
    return presets.get(point.get("preset", spec["preset"])).override(spec["set"]).override(rest)


def expand(spec: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Every grid point of ``spec`` (one point, ``{}``, without a grid)."""
    grid = spec["grid"]
    return [dict(zip(grid, values, strict=True)) for values in itertools.product(*grid.values())] or [{}]


class SweepTableError(ValueError):
    """The table given to a sweep holds rows this spec would not produce."""


#: Fields every sweep row must hold, parsed to check a row is complete (a truncated write is not).
_REQUIRED = {"policy": str, "seed": int, "env": str, "lawn_version": str, "config_hash": str, "policy_args": str,
             "slots": int, "control_cost": float, "rmse_m": float, "outage_rate": float}


def config_hash(config_dict: Mapping[str, Any], policy_args: Mapping[str, Any] | None = None) -> str:
    """A stable hash (16 hex digits) of a resolved config (``ScenarioConfig.to_dict()``) and, when
    given, a policy's arguments: equal inputs give equal hashes in any process."""
    payload = json.dumps({"config": config_dict, "policy_args": dict(policy_args or {})}, sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


def _key(row: Mapping[str, Any]) -> tuple[Any, ...]:
    return (str(row["config_hash"]), str(row["policy"]), str(row["policy_args"]), int(row["seed"]), str(row["env"]),
            str(row["lawn_version"]))


def _problem(row: Mapping[str, Any]) -> str | None:
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
    """A sweep table's usable rows and a message per row dropped (incomplete or duplicate)."""

    rows: list[dict[str, Any]]
    dropped: list[str]


def read_rows(path: Path) -> SweepTable:
    """The usable rows of a sweep table and a message per dropped row (incomplete or duplicate)."""
    rows, dropped, seen = [], [], set()
    for i, row in enumerate(read_table(path), start=2):  # line 1 is the header
        why = _problem(row)
        if why is None and _key(row) in seen:
            why = "a duplicate of an earlier row"
        if why is not None:
            dropped.append(f"{Path(path).name} line {i}: {why}")
            continue
        seen.add(_key(row))
        rows.append(row)
    return SweepTable(rows, dropped)


def read_table(path: Path) -> list[dict[str, Any]]:
    """Every row of a sweep table as written (an empty list before the first row)."""
    return read_csv(path)


def _run(task: tuple[Any, ...]) -> dict[str, Any]:
    point, policy, seed, env_id, cfg_dict, policy_kwargs, sweep_name = task
    cfg = lawn_env.ScenarioConfig.from_dict(cfg_dict)
    row = run_episode(policy, env_id, cfg, seed, policy_kwargs)
    out = {"sweep": sweep_name, **point}
    out.update(row.as_row())
    out["lawn_version"] = lawn_env.__version__
    out["config_hash"] = config_hash(cfg_dict)
    out["policy_args"] = json.dumps(dict(policy_kwargs), sort_keys=True)
    out["config"] = json.dumps(cfg.to_dict(), sort_keys=True)
    return out


def run_sweep(spec: str | Path | Mapping[str, Any], table: str | Path, workers: int = 1, backend: str = "process",
              progress: bool = True, max_runs: int | None = None, extend: bool = False) -> list[dict[str, Any]]:
    """Run the missing rows of ``spec`` into ``table`` (CSV); returns all rows of the table.

    Rows are keyed by config hash, policy, policy arguments, seed, env and version (module
    docstring); unusable rows are dropped and rerun, with a warning. A table holding rows this spec
    would not produce raises :class:`SweepTableError` unless ``extend``. ``max_runs`` stops after
    that many new runs (for tests of resumption).
    """
    import warnings

    spec = load_spec(spec)
    table = Path(table)
    table.parent.mkdir(parents=True, exist_ok=True)
    wanted: dict[tuple[Any, ...], tuple[Any, ...]] = {}
    for point in expand(spec):
        cfg_dict = point_config(spec, point).to_dict()
        chash = config_hash(cfg_dict)
        for policy in spec["policies"]:
            policy_kwargs = spec["policy_args"].get(policy, {})
            args = json.dumps(dict(policy_kwargs), sort_keys=True)
            for seed in spec["seeds"]:
                key = (chash, policy, args, int(seed), spec["env"], lawn_env.__version__)
                wanted[key] = (point, policy, seed, spec["env"], cfg_dict, policy_kwargs, spec["name"])
    rows, dropped = read_rows(table)
    if dropped:
        warnings.warn(f"{table}: dropped {len(dropped)} unusable rows, to be rerun: " + "; ".join(dropped[:5])
                      + (" ..." if len(dropped) > 5 else ""), stacklevel=2)
    foreign = [r for r in rows if _key(r) not in wanted]
    if foreign and not extend:
        raise SweepTableError(
            f"{table} holds {len(foreign)} rows that sweep {spec['name']!r} would not produce (another spec, preset, "
            f"set, grid or policy arguments, another lawn version than {lawn_env.__version__}, or a table written "
            "before rows carried config hashes); write to a new table, or pass --extend (extend=True) to keep them "
            "beside this sweep's rows")
    done = {_key(r) for r in rows}
    tasks = [task for key, task in wanted.items() if key not in done]
    if max_runs is not None:
        tasks = tasks[:max_runs]
    if not tasks:
        ordered = _canonical(rows, wanted)
        if dropped or ordered != rows:
            write_csv(ordered, table, atomic=True)
        return ordered
    from tqdm.auto import tqdm

    bar = tqdm(total=len(tasks), desc=spec["name"], unit="run", disable=None if progress else True, leave=False)
    try:
        for row in execute(_run, tasks, workers, backend):
            rows.append(row)
            write_csv(rows, table, atomic=True)
            bar.update()
    finally:
        bar.close()
    rows = read_rows(table)[0]
    if all(k in {_key(r) for r in rows} for k in wanted):  # complete: one order, however it was interrupted
        write_csv(_canonical(rows, wanted), table, atomic=True)
        rows = read_rows(table)[0]
    return rows


def _canonical(rows: list[dict[str, Any]], wanted: Mapping[tuple[Any, ...], Any]) -> list[dict[str, Any]]:
    """Rows in the spec's order (grid point, policy, seed), rows of other specs (``extend``) first
    as they were: a finished table is the same file whatever order its runs finished in."""
    rank = {key: i for i, key in enumerate(wanted)}
    foreign = [r for r in rows if _key(r) not in rank]
    return foreign + sorted((r for r in rows if _key(r) in rank), key=lambda r: rank[_key(r)])


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


def summarize_sweep(rows: list[dict[str, Any]], grid_keys: Sequence[str],
                    metrics: Sequence[str] = ("control_cost", "rmse_m", "outage_rate")) -> str:
    """Markdown table: mean ± 95 % interval of ``metrics`` per grid point and policy."""
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((*(str(r[k]) for k in grid_keys), r["policy"]), []).append(r)
    table = []
    for key, members in groups.items():
        stats = [mean_ci(float(r[m]) for r in members) for m in metrics]
        table.append([*key, str(len(members)), *(f"{mean:.4g} ± {half:.2g}" for mean, half in stats)])
    return markdown_table([*grid_keys, "policy", "runs", *metrics], table)
