"""The ``lawn`` command line: one module per subcommand (its parser builder ``add`` and its
``run``), the shared flags and one policy-name type (:mod:`.common`); each subcommand's line in
``lawn --help`` is in :data:`COMMAND_HELP`."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

__all__ = ["main", "build_parser", "COMMANDS", "COMMAND_NAMES"]

#: Each subcommand's line in ``lawn --help``, in the order it lists them.
COMMAND_HELP = {
    "demo": "one seeded episode of lawn/Joint-v1 under a scripted policy",
    "render": "one seeded episode of a policy as an animation (drone, AGVs, reference paths, links coloured by "
              "outage probability)",
    "evaluate": "run a policy on seeded episodes and write one row per episode",
    "benchmark": "the expert and the baselines on the same seeded episodes; --protocol learned and --suite: the "
                 "learned agents' protocol and the task suite's leaderboard",
    "train": "train a Stable-Baselines3 agent (or behaviour cloning) on a lawn env",
    "zoo": "shipped learned agents: list them, train their recipes, benchmark and export",
    "dataset": "record a policy's episodes as a Minari dataset (data extra)",
    "sweep": "run a grid of config fields x policies x seeds into a tidy table",
    "figures": "the paper's experiments from tidy tables (running missing sweeps)",
    "gap": "per-slot optimality gap of planners against the global reference",
}
#: The subcommands; ``COMMANDS`` are their modules.
COMMAND_NAMES = tuple(COMMAND_HELP)

#: The commands that map episodes over ``--workers`` processes (evaluation/pool.py, ``pool_map``): their
#: helpers start before anything else (:func:`_start_helpers_early`). ``sweep``, ``figures`` and
#: ``train --seeds`` stream rows from a pool of their own.
_PARALLEL = ("evaluate", "benchmark", "gap")


def __getattr__(name: str) -> tuple[ModuleType, ...]:
    if name == "COMMANDS":  # imported on first use: the module itself stays light (see main)
        return tuple(importlib.import_module(f"{__name__}.{command}") for command in COMMAND_NAMES)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("lawn")
    except PackageNotFoundError:  # a checkout on the path, not installed
        import lawn_env

        return lawn_env.__version__


def _top_parser() -> tuple[argparse.ArgumentParser, argparse._SubParsersAction[argparse.ArgumentParser]]:
    parser = argparse.ArgumentParser(prog="lawn", description="Wireless predictive control over low-altitude networks.")
    parser.add_argument("--version", action="version", version=f"lawn {_version()}")
    parser.add_argument("--debug", action="store_true", help="on an error, show the full traceback")
    return parser, parser.add_subparsers(dest="command", required=True)


def build_parser() -> argparse.ArgumentParser:
    """The whole ``lawn`` parser: every subcommand's flags (it imports lawn and its kernels)."""
    parser, sub = _top_parser()
    for command in __getattr__("COMMANDS"):
        command.add(sub).set_defaults(func=command.run)
    return parser


def _light_parser() -> argparse.ArgumentParser:
    """The top level alone (``lawn --help``, ``--version``, a mistyped command): the subcommands by
    name and line, nothing imported."""
    parser, sub = _top_parser()
    for name in COMMAND_NAMES:
        sub.add_parser(name, help=COMMAND_HELP[name], add_help=False)
    return parser


#: Commands whose --out is a file (its folder must be writable) or a folder, checked before any work.
_FILE_OUT = ("evaluate", "sweep", "render")
_DIR_OUT = ("demo", "benchmark", "gap", "figures")


def _holds_results(args: argparse.Namespace, path: Path) -> bool:
    """Whether ``path`` holds an earlier run's results: a file there, a folder with anything in it, or
    what the command says (``holds_results``: ``lawn figures`` resumes the tables of its own mode)."""
    if hasattr(args, "holds_results"):
        return bool(args.holds_results(args, path))
    if args.command in _FILE_OUT:
        return path.exists()
    return path.is_dir() and any(path.iterdir())


def _numbered(path: Path, taken: Callable[[Path], bool]) -> Path:
    """``path``, or the first of ``NAME-2``, ``NAME-3``, ... (before the suffix) that ``taken`` lets through."""
    n = 1
    candidate = path
    while taken(candidate):
        n += 1
        candidate = path.with_name(f"{path.stem}-{n}{path.suffix}")
    return candidate


def _claim_out(args: argparse.Namespace) -> None:
    """Resolve ``--out`` of a command that writes results and make sure it replaces none in silence
    (``lawn sweep`` resumes its own table, ``lawn train`` refuses a run directory with its own message):
    an ``--out`` that holds an earlier run's results is refused unless ``--overwrite``; without ``--out``,
    the command's default path, or where that holds results the first free ``NAME-2``, ``NAME-3``, ...
    (printed)."""
    if not hasattr(args, "overwrite"):
        return
    if args.out is not None:
        path = Path(args.out)
        if _holds_results(args, path) and not args.overwrite:
            raise ValueError(f"--out {args.out} holds the results of an earlier run: pass --overwrite to replace "
                             "them, or give another --out")
        return
    default = Path(args.default_out(args))
    path = default if args.overwrite else _numbered(default, lambda p: _holds_results(args, p))
    if path != default:
        print(f"lawn {args.command}: {default} holds an earlier run's results; writing {path} (--out PATH chooses "
              "the place, --overwrite replaces them)")
    args.out = str(path)


def _check_out(command: str, out: str | None) -> None:
    """``--out`` must be writable before hours are spent computing what goes there."""
    if out is None or command not in _FILE_OUT + _DIR_OUT:
        return
    path = Path(out)
    folder = path.parent if command in _FILE_OUT else path
    if command in _FILE_OUT and path.is_dir():
        raise ValueError(f"--out {str(path)!r} is a directory; give a file")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".lawn-write-test-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ValueError(f"--out {str(path)!r}: cannot write to {str(folder)!r} ({exc.strerror or exc})") from None


def _one_line(exc: BaseException) -> str:
    """A config validation error as ``field: message (got value)``, several joined by ``; ``."""
    from pydantic import ValidationError

    if isinstance(exc, ValidationError):
        parts = []
        for err in exc.errors():
            field = ".".join(str(p) for p in err["loc"]) or exc.title
            got = f" (got {err['input']!r})" if "input" in err else ""
            parts.append(f"{field}: {err['msg']}{got}")
        return f"invalid {exc.title}: " + "; ".join(parts)
    return " ".join(str(exc).split("\n")) if str(exc) else type(exc).__name__


def _early_workers(argv: list[str]) -> int:
    """The ``--workers`` of a parallel command read from ``argv`` before the parser exists (argparse's
    abbreviations included, its default where absent); 0 when it is not one or the reading is unclear
    (help, a value that is no count): the parser then has its say."""
    words = [w for w in argv if w != "--debug"]
    if not words or words[0] not in _PARALLEL or "-h" in words or "--help" in words:
        return 0
    workers = min(2, os.cpu_count() or 1)
    for i, word in enumerate(words):
        flag, eq, value = word.partition("=")
        if len(flag) < 4 or not "--workers".startswith(flag):  # --workers, --work, --wo (argparse abbreviations)
            continue
        value = value if eq else (words[i + 1] if i + 1 < len(words) else "")
        if not (value.isascii() and value.isdecimal()):
            return 0
        workers = int(value)
    return workers


def _start_helpers_early(argv: list[str]) -> None:
    """The helper processes of a parallel command start importing lawn now, while this process imports
    it and builds the parser (evaluation/pool.py); nothing starts when the reading of ``argv`` is unclear
    or a helper cannot start (the command then reports it as it would without the early start)."""
    workers = _early_workers(argv)
    if workers <= 1:
        return
    from evaluation.pool import start_helpers

    try:
        start_helpers(workers)
    except Exception:  # e.g. a bad LAWN_START_METHOD: the map raises it again, inside main's error handling
        from evaluation.pool import stop_helpers

        stop_helpers()


def main(argv: list[str] | None = None) -> int:
    """The ``lawn`` command. Errors print one line and exit non-zero (2: bad input, 3: a missing
    extra, 130: interrupted, 1: anything else, which is a bug); ``--debug`` shows the traceback."""
    if argv is None:  # the command line itself (a call from Python starts nothing early)
        _start_helpers_early(sys.argv[1:])
    code = 1
    try:
        code = _run(argv)
        return code
    finally:
        if code != 0 and "evaluation.pool" in sys.modules:  # a failed command does not wait for its helpers
            from evaluation.pool import stop_helpers

            stop_helpers()


def _run(argv: list[str] | None) -> int:
    words = sys.argv[1:] if argv is None else argv
    if not any(w in COMMAND_NAMES for w in words if not w.startswith("-")):  # help, version or a mistyped command
        _light_parser().parse_args(argv)  # exits, with the help, the version or the error
    args = build_parser().parse_args(argv)
    from agents.errors import MissingExtra
    from evaluation.pool import HelperDied

    try:
        _claim_out(args)  # the default path resolved; never an earlier run's results without --overwrite
        _check_out(args.command, getattr(args, "out", None))
        code: int = args.func(args)
        return code
    except BaseException as exc:
        if args.debug or isinstance(exc, SystemExit):
            raise
        if isinstance(exc, KeyboardInterrupt):
            print(f"lawn {args.command}: interrupted", file=sys.stderr)
            return 130
        if isinstance(exc, (MissingExtra, HelperDied)):  # a helper killed, out of memory...: said, not a traceback
            print(f"lawn {args.command}: error: {exc}", file=sys.stderr)
            return 3 if isinstance(exc, MissingExtra) else 1
        if isinstance(exc, (ValueError, TypeError, OSError)):  # bad values, names, files: one clear line
            print(f"lawn {args.command}: error: {_one_line(exc)}", file=sys.stderr)
            return 2
        if isinstance(exc, Exception):
            print(f"lawn {args.command}: internal error: {type(exc).__name__}: {exc} "
                  "(rerun with --debug for the traceback, and please report it)", file=sys.stderr)
            return 1
        raise
