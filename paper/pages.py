"""The docs' generated blocks, and the one command that refreshes them.

Every table of README.md and of ``docs/**/*.md`` that a command produces lives in a block whose
markers name that command and the file it writes::

    <!-- NAME:begin cmd="lawn benchmark --out runs/bench --quiet" table="runs/bench/summary.md" group="benchmark" -->
    ...
    <!-- NAME:end -->

``cmd`` runs from the repository root (a shell line); ``table`` is the Markdown it leaves, spliced
into the block with the command and the package version and commit (:func:`evaluation.provenance.provenance`);
without ``table`` the command writes the block itself (``lawn zoo build``, ``lawn figures --docs``);
``copy="SRC DEST ..."`` copies its figures into the docs; ``group`` names the part of
``scripts/refresh_docs.sh --only``. A block without attributes (``<!-- NAME:begin -->``) is
measured once and never refreshed. Each name occurs in exactly one page (:func:`find_block`).

``python -m paper.pages refresh [--only NAME|GROUP ...]`` runs each distinct command once, one at
a time (the timed ones measure alone), and splices its tables; ``python -m paper.pages check NAME
FILE`` compares a fresh table with the block's; ``python -m paper.pages splice NAME FILE --source
CMD`` splices one file.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from evaluation.provenance import provenance

__all__ = ["Block", "blocks", "replace_block", "replace_body", "block_body", "block_names", "find_block", "pages",
           "first_table", "check_block", "refresh"]

ROOT = Path(__file__).resolve().parent.parent
#: The order in which refresh runs the groups' commands: the agents are built (``learned``) before the
#: suite plays them; a group not listed runs last.
GROUP_ORDER = ("figures", "benchmark", "gap", "dv", "speed", "throughput", "parallel", "qp", "fleet", "learned",
               "suite")
_BEGIN = re.compile(r'^<!-- ([\w.-]+):begin((?: [a-z]+="[^"]*")*) -->$', flags=re.MULTILINE)


@dataclass(frozen=True)
class Block:
    """A generated block: its name, page, and the command, table, figures and group its markers name."""

    name: str
    page: Path
    cmd: str = ""
    table: str = ""
    copy: tuple[str, ...] = ()
    group: str = ""


def _markers(name: str) -> tuple[re.Pattern[str], re.Pattern[str]]:
    return (re.compile(rf'^<!-- {re.escape(name)}:begin(?: [a-z]+="[^"]*")* -->$', flags=re.MULTILINE),
            re.compile(rf"^<!-- {re.escape(name)}:end -->$", flags=re.MULTILINE))


def block_names(text: str) -> list[str]:
    """Names of the generated blocks in ``text``, in order (a marker is a line of its own: a page
    that quotes a marker, as MyST's ``{include}`` options do, holds no block)."""
    return [m.group(1) for m in _BEGIN.finditer(text)]


def blocks(root: Path = ROOT) -> list[Block]:
    """Every generated block of the pages, with its markers' attributes, in page order."""
    out = []
    for page in pages(root):
        for m in _BEGIN.finditer(page.read_text()):
            attrs = dict(re.findall(r'([a-z]+)="([^"]*)"', m.group(2)))
            unknown = set(attrs) - {"cmd", "table", "copy", "group"}
            if unknown:
                raise ValueError(f"{page}: block {m.group(1)!r} has unknown attributes {sorted(unknown)}; "
                                 "allowed: cmd, table, copy, group")
            out.append(Block(m.group(1), page, attrs.get("cmd", ""), attrs.get("table", ""),
                             tuple(attrs.get("copy", "").split()), attrs.get("group", "")))
    return out


def pages(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown page of the docs site (``docs/**/*.md``), in a fixed order."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def find_block(name: str, root: Path = ROOT) -> Path:
    """The page holding generated block ``name``. Raises ``ValueError`` naming the pages when no
    page or more than one holds it."""
    holders = [p for p in pages(root) if name in block_names(p.read_text())]
    if len(holders) != 1:
        known = sorted({n for p in pages(root) for n in block_names(p.read_text())})
        where = ", ".join(str(p.relative_to(root)) for p in holders) or "no page"
        raise ValueError(f"generated block {name!r} must be in exactly one page, found in {where}; blocks: {known}")
    return holders[0]


def _span(text: str, name: str) -> tuple[int, int] | None:
    """Where the body of block ``name`` starts and ends in ``text``; None without both markers in order."""
    begin, end = (m.search(text) for m in _markers(name))
    if begin is None or end is None or end.start() < begin.end():
        return None
    return begin.end(), end.start()


def block_body(path: Path, name: str) -> str:
    """The current text of block ``name`` in ``path`` (empty when the page or the block is missing),
    so that a page rewritten whole keeps the blocks other commands generate."""
    path = Path(path)
    text = path.read_text() if path.exists() else ""
    span = _span(text, name)
    return "" if span is None else text[span[0] : span[1]].strip()


def replace_body(text: str, name: str, content: str, source: str | None = None, where: str = "the page") -> str:
    """``text`` with the body of block ``name`` replaced by ``content`` (and, when ``source`` is
    given, a line naming the command and the version and commit it ran at). Raises ``ValueError``
    (naming ``where``) when the block's markers are missing or out of order."""
    span = _span(text, name)
    if span is None:
        raise ValueError(f"{where}: no generated block {name!r} (<!-- {name}:begin ... --> ... <!-- {name}:end -->); "
                         f"blocks: {block_names(text)}")
    i, j = span
    body = content.strip()
    if source:
        body += f"\n\n<sub>Generated by `{source}` at {provenance()}.</sub>"
    return text[:i] + "\n" + body + "\n" + text[j:]


def replace_block(path: Path, name: str, content: str, source: str | None = None) -> None:
    """Replace the body of block ``name`` in ``path`` (:func:`replace_body`)."""
    path = Path(path)
    path.write_text(replace_body(path.read_text(), name, content, source, where=str(path)))


def first_table(text: str) -> list[str]:
    """The lines of the first Markdown table in ``text`` (consecutive lines starting with ``|``)."""
    lines = [line.strip() for line in text.splitlines()]
    start = next((i for i, line in enumerate(lines) if line.startswith("|")), None)
    if start is None:
        return []
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    return lines[start:end]


def check_block(name: str, text: str, root: Path = ROOT) -> list[str]:
    """The differences between the first table of ``text`` (a command's fresh output) and the first
    table of generated block ``name``: ``[]`` when they agree line for line."""
    page = find_block(name, root)
    committed, fresh = first_table(block_body(page, name)), first_table(text)
    if not fresh:
        return [f"the new output has no table (block {name!r} of {page.relative_to(root)})"]
    import difflib

    return list(difflib.unified_diff(committed, fresh, f"{page.relative_to(root)} ({name})", "this run", lineterm=""))


def _selected(only: list[str] | None, root: Path) -> list[Block]:
    """The refreshable blocks (those naming a command) whose name or group is in ``only`` (all
    without it); an unknown name is an error that lists the known ones."""
    known = [b for b in blocks(root) if b.cmd]
    names = {b.name for b in known} | {b.group for b in known if b.group}
    unknown = sorted(set(only or ()) - names)
    if unknown:
        raise ValueError(f"--only {' '.join(unknown)}: no such block or group; valid: {', '.join(sorted(names))}")
    return [b for b in known if not only or b.name in only or b.group in only]


def refresh(only: list[str] | None = None, root: Path = ROOT, dry_run: bool = False) -> list[str]:
    """Run each distinct command of the selected blocks once, by :data:`GROUP_ORDER` and one at a time, then
    splice each block's table and copy its figures; the blocks of a command that failed, or left a
    table or figure it did not write this time, stay as they are. Returns the commands that failed."""
    by_cmd: dict[str, list[Block]] = {}
    rank = {group: i for i, group in enumerate(GROUP_ORDER)}
    for b in sorted(_selected(only, root), key=lambda b: rank.get(b.group, len(rank))):  # stable: page order within
        by_cmd.setdefault(b.cmd, []).append(b)
    failed = []
    for cmd, members in by_cmd.items():
        print(f"paper.pages: {cmd}  ->  {', '.join(b.name for b in members)}", flush=True)
        if dry_run:
            continue
        env = dict(os.environ, PATH=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]))
        start = time.time() - 1  # file times have a coarse clock on some file systems
        # lawn and python are this environment's
        ran = subprocess.run(["bash", "-c", cmd], cwd=root, env=env, check=False).returncode == 0
        wanted = [root / b.table for b in members if b.table] + [root / src for b in members for src in b.copy[::2]]
        if not ran or not all(p.exists() and p.stat().st_mtime >= start for p in wanted):  # failed, or a stale file
            failed.append(cmd)
            continue
        for b in members:
            if b.table:
                replace_block(b.page, b.name, (root / b.table).read_text(), source=cmd)
            for src, dest in zip(b.copy[::2], b.copy[1::2], strict=True):
                shutil.copy2(root / src, root / dest)
    return failed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m paper.pages", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="action", required=True)
    rf = sub.add_parser("refresh", help="run the blocks' commands and splice their tables")
    rf.add_argument("--only", nargs="+", default=None, metavar="NAME", help="blocks or groups (default: all)")
    rf.add_argument("--dry-run", action="store_true", help="list the commands and their blocks, run nothing")
    for action in ("check", "splice"):
        sp = sub.add_parser(action, help="compare FILE's first table with the block's" if action == "check"
                            else "splice FILE into the block")
        sp.add_argument("name", help="the block's name (<!-- NAME:begin ... -->)")
        sp.add_argument("file", help="the Markdown a command wrote")
        if action == "splice":
            sp.add_argument("--source", required=True, help="the command that produced FILE")
    args = parser.parse_args(argv)
    try:
        if args.action == "refresh":
            failed = refresh(args.only, dry_run=args.dry_run)
            for cmd in failed:
                print(f"paper.pages: failed, its blocks left as they were: {cmd}", file=sys.stderr)
            return 1 if failed else 0
        if args.action == "splice":
            replace_block(find_block(args.name), args.name, Path(args.file).read_text(), args.source)
            return 0
        diff = check_block(args.name, Path(args.file).read_text())
        if diff:
            print(f"paper.pages: block {args.name!r} is not what the code produces now:", file=sys.stderr)
            print("\n".join(diff), file=sys.stderr)
            return 1
        print(f"paper.pages: block {args.name!r} holds the table {args.file} has")
        return 0
    except (OSError, ValueError) as exc:
        print(f"paper.pages: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
