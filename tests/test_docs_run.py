"""Docs that run: every Python block of README.md and of the docs site's pages (``docs/**/*.md``)
is executed, in order within its page, in one namespace per page (as a reader pastes them one
after the other), in a fresh working directory.

A fence's words after ``python`` are options: ``python slow`` marks a block that needs the ``rl``
extra or takes long; the default run skips it (so no fast block may depend on it), and the slow
test runs the whole page, slow blocks included (``pytest -m slow``). No other option exists: every
Python block runs somewhere.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pytest
from markdown_it import MarkdownIt

from paper.pages import pages

ROOT = Path(__file__).resolve().parent.parent
OPTIONS = {"slow"}


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # 1-based line of the fence in the page
    code: str
    slow: bool


def python_blocks(page: Path) -> list[Block]:
    """The Python fences of a Markdown page, in order. Raises ``ValueError`` on an unknown option."""
    blocks = []
    for token in MarkdownIt("commonmark").parse(page.read_text()):
        words = token.info.split() if token.type == "fence" else []
        if not words or words[0] not in ("python", "py", "python3"):
            continue
        unknown = set(words[1:]) - OPTIONS
        if unknown:
            raise ValueError(f"{page}:{token.map[0] + 1}: unknown fence option(s) {sorted(unknown)}; "
                             f"valid: {sorted(OPTIONS)}")
        blocks.append(Block(page, token.map[0] + 1, token.content, "slow" in words[1:]))
    return blocks


PAGES = [p for p in pages(ROOT) if python_blocks(p)]
SLOW_PAGES = [p for p in PAGES if any(b.slow for b in python_blocks(p))]


def _ids(paths: list[Path]) -> list[str]:
    return [str(p.relative_to(ROOT)) for p in paths]


def _label(page: Path) -> str:
    return str(page.relative_to(ROOT)) if page.is_relative_to(ROOT) else page.name


def run_page(page: Path, with_slow: bool, workdir: Path) -> int:
    """Execute the page's blocks in order in one namespace; returns how many ran. A failing block
    is reported with its page and line."""
    namespace: dict = {"__name__": "__main__"}
    ran = 0
    cwd, environ = os.getcwd(), dict(os.environ)  # a page may set variables (MINARI_DATASETS_PATH): undone
    os.chdir(workdir)
    try:
        for block in python_blocks(page):
            if block.slow and not with_slow:
                continue
            code = compile("\n" * block.line + block.code, _label(page), "exec")
            try:
                exec(code, namespace)
            except Exception as exc:
                raise AssertionError(f"{_label(page)}, the block at line {block.line} failed: "
                                     f"{type(exc).__name__}: {exc}") from exc
            ran += 1
    finally:
        os.chdir(cwd)
        os.environ.clear()
        os.environ.update(environ)
    return ran


def test_the_pages_have_python_blocks_and_only_known_options():
    names = _ids(PAGES)
    assert "README.md" in names and "docs/clients.md" in names and "docs/envs/vector.md" in names, names
    for page in pages(ROOT):
        python_blocks(page)  # raises on an unknown option


def test_an_unknown_fence_option_is_refused(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("```python notest\nprint(1)\n```\n")
    with pytest.raises(ValueError, match=r"unknown fence option\(s\) \['notest'\]"):
        python_blocks(page)


def test_blocks_share_a_namespace_and_a_failing_block_names_its_page_and_line(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text\n\n```python\nx = 1\n```\n\n```python slow\nx = 2\n```\n\n"
                    "```python\nif x == 1:\n    raise RuntimeError('boom')\n```\n")
    assert run_page(page, True, tmp_path) == 3  # the slow block set x = 2
    with pytest.raises(AssertionError, match=r"page.md, the block at line 11 failed: RuntimeError: boom"):
        run_page(page, False, tmp_path)


@pytest.mark.parametrize("page", PAGES, ids=_ids(PAGES))
def test_page_runs(page, tmp_path):
    fast = [b for b in python_blocks(page) if not b.slow]
    assert run_page(page, with_slow=False, workdir=tmp_path) == len(fast)


@pytest.mark.slow
@pytest.mark.parametrize("page", SLOW_PAGES, ids=_ids(SLOW_PAGES))
def test_page_runs_with_its_slow_blocks(page, tmp_path):
    assert run_page(page, with_slow=True, workdir=tmp_path) == len(python_blocks(page))


def lawn_commands(page: Path) -> list[tuple[int, str]]:
    """The ``lawn ...`` command lines of a page's shell fences (continuation lines joined)."""
    found = []
    for token in MarkdownIt("commonmark").parse(page.read_text()):
        if token.type != "fence" or token.info.split()[:1] not in (["bash"], ["sh"], ["console"]):
            continue
        text = token.content.replace("\\\n", " ")
        for offset, line in enumerate(text.splitlines()):
            if line.strip().startswith("lawn "):
                found.append((token.map[0] + 2 + offset, line.strip()))
    return found


def test_every_lawn_command_of_the_docs_parses():
    """Every ``lawn`` command a page shows is one the command line accepts as written (flags,
    choices, policy names, counts): a renamed flag cannot leave a stale page behind."""
    import contextlib
    import io
    import shlex

    from lawn_cli import build_parser

    parser, bad, seen = build_parser(), [], 0
    for page in pages(ROOT):
        for line, command in lawn_commands(page):
            seen += 1
            err = io.StringIO()
            try:
                with contextlib.redirect_stderr(err):
                    parser.parse_args(shlex.split(command, comments=True)[1:])
            except SystemExit:
                bad.append(f"{_label(page)}:{line}: {command}: {err.getvalue().strip().splitlines()[-1]}")
    assert seen >= 20 and not bad, bad


def test_the_spawn_block_runs_saved_as_a_script(tmp_path):
    """The AsyncVectorEnv block of the clients page, saved as a file and run with ``python``: spawn
    workers import the file, so it needs its ``if __name__ == "__main__":`` guard."""
    import subprocess
    import sys

    block = next(b for b in python_blocks(ROOT / "docs" / "clients.md") if 'context="spawn"' in b.code)
    script = tmp_path / "spawn_envs.py"
    script.write_text(block.code)
    subprocess.run([sys.executable, str(script)], cwd=tmp_path, check=True, capture_output=True, timeout=300)
