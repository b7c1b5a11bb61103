"""The task suite's pages: the blocks of docs/LEADERBOARD.md (the board, the references, the cost
structure, every task) and docs/LEARNED.md's fleet-size table, spliced from the tables of one suite
run (``lawn benchmark --suite --docs DIR``; :func:`evaluation.protocols.suite_protocol` declares what
it plays)."""

from __future__ import annotations

import shutil
from pathlib import Path

from evaluation.protocols import SUITE_BLOCKS, Protocol

from .pages import block_names, replace_block

__all__ = ["check_suite_pages", "write_suite_pages"]

#: The fleet-size table's block of LEARNED.md and the file of the suite run it comes from.
FLEET_BLOCK = ("fleet-generalization", "fleet_sizes.md")


def _suite_pages(protocol: Protocol) -> dict[str, list[tuple[str, str]]]:
    """The pages a suite run writes: page -> its (block, table file) pairs (LEARNED.md only when the
    run plays fleet networks on the fleet sizes)."""
    pages = {"LEADERBOARD.md": [(block, f"{name}.md") for name, block in SUITE_BLOCKS.items()]}
    if protocol.then:
        pages["LEARNED.md"] = [FLEET_BLOCK]
    return pages


def check_suite_pages(protocol: Protocol, docs: Path) -> None:
    """Refuse, before any episode, a ``docs`` folder whose pages lack a block the suite writes."""
    for page, blocks in _suite_pages(protocol).items():
        path = docs / page
        present = block_names(path.read_text() if path.exists() else "")
        missing = [block for block, _ in blocks if block not in present]
        if missing:
            raise ValueError(f"--docs {docs}: {path} has no generated block {', '.join(missing)}")


def write_suite_pages(protocol: Protocol, tables: dict[str, str], out: Path, docs: Path) -> None:
    """Splice a suite run's tables (by file, as :func:`evaluation.protocols.execute` returns them) into
    the blocks of ``docs`` and copy its per-slot figure (``out/per_slot.png``) to
    ``docs/figures/suite-per-slot.png``; every block and the figure are checked before a page is changed."""
    check_suite_pages(protocol, docs)
    if not (out / "per_slot.png").exists():
        raise ValueError(f"{out}: no per_slot.png (the suite run writes it); the docs are left as they were")
    source = f"lawn benchmark --suite --docs {docs}"
    for page, blocks in _suite_pages(protocol).items():
        for block, file in blocks:
            replace_block(docs / page, block, tables[file], source=source)
    (docs / "figures").mkdir(parents=True, exist_ok=True)
    shutil.copy2(out / "per_slot.png", docs / "figures" / "suite-per-slot.png")
