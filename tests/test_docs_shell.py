"""Docs whose commands run: every shell block (``bash``, ``sh``, ``console``) of README.md and of the
docs site's pages is run by the test suite, or marked as not run with its reason.

A fence's words after the language are its marker:

* none: every line runs as written;
* ``small``: every line runs on a small budget (:data:`SMALL`: the episodes, training steps and seeds
  a line asks for, cut down; the scenario and the flags as written);
* ``slow``: as ``small``, in the slow run only (``pytest -m slow``): what takes minutes even then;
* ``norun:REASON``: not run, for one of the reasons of :data:`NOT_RUN`.

The blocks of a page run in order in one fresh working directory (a block may read what an earlier
one wrote), with the repository's ``docs`` and ``examples`` beside it. A ``lawn`` line runs in this
process (``lawn_cli.main``) and must exit 0; a ``python`` line runs in a subprocess. A line that
fails is a failing test naming its page and line.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from markdown_it import MarkdownIt

from paper.pages import pages

ROOT = Path(__file__).resolve().parent.parent
SHELLS = ("bash", "sh", "console")
#: Why a block is not run by the tests.
NOT_RUN = {
    "ci": "CI runs it: .ci/run calls the README's two commands on a fresh clone",
    "install": "it installs into the reader's environment; tests/test_install.py builds and installs the wheel",
    "docs": "it rewrites the repository's own pages (what scripts/refresh_docs.sh is for); the commands it runs "
            "are the generated blocks' own, named in each block",
    "placeholder": "it shows a command's form, with placeholders for the reader's own files (SPEC, TABLE, a run)",
}
#: The small budget: flag -> the value it gets (a list keeps only the first value), per command.
SMALL = {
    "lawn evaluate": {"--episodes": "1"},
    "lawn benchmark": {"--episodes": "1"},
    "lawn dataset": {"--episodes": "2"},
    "lawn train": {"--timesteps": "256", "--seeds": None, "--eval-episodes": "1"},
    "lawn sweep": {},
    "lawn render": {},
    "lawn figures": {},
    "lawn zoo": {},
    "python examples/ppo_lawn.py": {"--total-timesteps": "256", "--num-envs": "2", "--eval-episodes": "1"},
}
#: Flags a small budget adds where a line does not give them: lawn benchmark's episodes (the learned
#: protocol's and the suite's 100 seeds), lawn train's validation episodes and DAgger rounds.
ADDED = {"lawn benchmark": [("--episodes", "1")],
         "lawn train": [("--eval-episodes", "1"), ("--hp", "dagger_iterations=1"), ("--hp", "dagger_timesteps=64")]}


@dataclass(frozen=True)
class ShellBlock:
    page: Path
    line: int  # 1-based line of the fence
    commands: tuple[tuple[int, str], ...]  # (line, command) with continuation lines joined, comments dropped
    mode: str  # "run", "small", "slow" or "norun"
    reason: str = ""


def shell_blocks(page: Path) -> list[ShellBlock]:
    """The shell fences of a page with their markers. Raises ``ValueError`` on an unknown marker."""
    found = []
    for token in MarkdownIt("commonmark").parse(page.read_text()):
        words = token.info.split() if token.type == "fence" else []
        if not words or words[0] not in SHELLS:
            continue
        where = f"{page}:{token.map[0] + 1}"
        options = words[1:]
        if len(options) > 1 or (options and options[0] not in ("small", "slow")
                                and not options[0].startswith("norun:")):
            raise ValueError(f"{where}: unknown shell fence marker {' '.join(options)!r}; valid: small, slow, "
                             f"norun:REASON with REASON one of {', '.join(NOT_RUN)}")
        mode, reason = (options[0] if options else "run"), ""
        if mode.startswith("norun:"):
            mode, reason = "norun", mode.partition(":")[2]
            if reason not in NOT_RUN:
                raise ValueError(f"{where}: unknown reason {reason!r} for norun; valid: {', '.join(NOT_RUN)}")
        commands, start = [], token.map[0] + 2
        for offset, raw in enumerate(token.content.replace("\\\n", "  ").split("\n")):
            text = " ".join(shlex.split(raw, comments=True))
            if text:
                commands.append((start + offset, text))
        found.append(ShellBlock(page, token.map[0] + 1, tuple(commands), mode, reason))
    return found


def _label(page: Path) -> str:
    return str(page.relative_to(ROOT)) if page.is_relative_to(ROOT) else page.name


def small(command: str) -> str:
    """``command`` on the small budget of :data:`SMALL` (a command it does not know is an error)."""
    words, text = shlex.split(command), command
    key = next((k for k in SMALL if words[: len(k.split())] == k.split()), None)
    if key is None:
        raise ValueError(f"no small budget for {command!r}; give the command one in SMALL")
    out, i = [], 0
    while i < len(words):
        word = words[i]
        flag, eq, _ = word.partition("=")
        if flag in SMALL[key]:
            value = SMALL[key][flag]
            values = [] if eq else list(_values(words, i + 1))
            out += [flag, value if value is not None else (values[0] if values else word.partition("=")[2])]
            i += 1 + len(values)
            continue
        out.append(word)
        i += 1
    dagger = key == "lawn train" and any(f"--algo {a}" in shlex.join(out) for a in ("bc", "fleet"))
    for flag, value in ADDED.get(key, []):
        wanted = (dagger and value.split("=")[0] not in text) if flag == "--hp" else flag not in out
        if wanted:
            out += [flag, value]
    return shlex.join(out)


def _values(words: list[str], start: int):
    for word in words[start:]:
        if word.startswith("--"):
            return
        yield word


def run_block(block: ShellBlock, workdir: Path, budget: bool) -> int:
    """Run a block's commands in ``workdir``; returns how many ran. ``budget``: on the small budget."""
    from lawn_cli import main

    ran = 0
    for line, command in block.commands:
        text = small(command) if budget else command
        words = shlex.split(text)
        where = f"{_label(block.page)}:{line}: {text}"
        if words[0] == "lawn":
            err = io.StringIO()
            with contextlib.redirect_stderr(err):
                code = main(words[1:])
            assert code == 0, f"{where}: exit {code}: {err.getvalue()[-2000:]}"
        elif words[0] == "python":
            done = subprocess.run([sys.executable, *words[1:]], cwd=workdir, capture_output=True, text=True,
                                  timeout=600, check=False)
            assert done.returncode == 0, f"{where}: exit {done.returncode}: {done.stderr[-2000:]}"
        else:
            raise AssertionError(f"{where}: the tests run lawn and python lines; mark this block norun:REASON")
        ran += 1
    return ran


def _workdir(tmp_path: Path) -> Path:
    for name in ("docs", "examples"):
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    return tmp_path


BLOCKS = [b for p in pages(ROOT) for b in shell_blocks(p)]
RUN_PAGES = sorted({b.page for b in BLOCKS if b.mode in ("run", "small")})
SLOW_PAGES = sorted({b.page for b in BLOCKS if b.mode == "slow"})


def _ids(paths: list[Path]) -> list[str]:
    return [_label(p) for p in paths]


def _run_page(page: Path, modes: tuple[str, ...], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> int:
    workdir = _workdir(tmp_path)
    monkeypatch.chdir(workdir)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(workdir / "minari"))
    ran = 0
    for block in shell_blocks(page):
        if block.mode in modes:
            ran += run_block(block, workdir, budget=block.mode != "run")
    return ran


def test_every_shell_block_is_run_or_says_why_not():
    """Every shell block of the pages carries a known marker; a norun block names a known reason."""
    assert {_label(b.page) for b in BLOCKS} >= {"README.md", "docs/training.md", "docs/policies.md"}
    for block in BLOCKS:
        assert block.commands, f"{_label(block.page)}:{block.line}: an empty shell block"
        if block.mode != "norun":
            for _, command in block.commands:
                small(command)  # a known command with a small budget
    assert {b.reason for b in BLOCKS if b.mode == "norun"} == set(NOT_RUN)  # no reason kept for nothing
    assert any(b.mode in ("run", "small") for b in BLOCKS if b.page.name == "README.md")


def test_a_bad_marker_is_refused(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("```bash quick\nlawn zoo\n```\n")
    with pytest.raises(ValueError, match="unknown shell fence marker 'quick'"):
        shell_blocks(page)
    page.write_text("```bash norun:later\nlawn zoo\n```\n")
    with pytest.raises(ValueError, match="unknown reason 'later' for norun; valid: ci, install"):
        shell_blocks(page)


def test_the_small_budget_cuts_counts_and_keeps_the_rest():
    assert small("lawn train --algo ppo --timesteps 300000 --seeds 0 1 2 --out runs/x") == \
        "lawn train --algo ppo --timesteps 256 --seeds 0 --out runs/x --eval-episodes 1"
    assert small("lawn train --algo bc --timesteps 6000 --hp dagger_iterations=2") == \
        "lawn train --algo bc --timesteps 256 --hp dagger_iterations=2 --eval-episodes 1 --hp dagger_timesteps=64"
    assert small("lawn benchmark --protocol learned --out runs/learned") == \
        "lawn benchmark --protocol learned --out runs/learned --episodes 1"
    assert small("lawn evaluate --policy epa --episodes=20") == "lawn evaluate --policy epa --episodes 1"
    with pytest.raises(ValueError, match=r"no small budget for 'pip install \.'"):
        small("pip install .")


def test_a_failing_line_names_its_page_and_line(tmp_path, monkeypatch):
    page = tmp_path / "page.md"
    page.write_text("text\n\n```bash\nlawn evaluate --policy nope\n```\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit):  # argparse refuses the name before any episode
        run_block(shell_blocks(page)[0], tmp_path, budget=False)
    page.write_text("```bash\nls -l\n```\n")
    with pytest.raises(AssertionError, match=r"page.md:2: ls -l: the tests run lawn and python lines"):
        run_block(shell_blocks(page)[0], tmp_path, budget=False)


@pytest.mark.parametrize("page", RUN_PAGES, ids=_ids(RUN_PAGES))
def test_page_commands_run(page, tmp_path, monkeypatch):
    assert _run_page(page, ("run", "small"), tmp_path, monkeypatch) > 0


@pytest.mark.slow
@pytest.mark.parametrize("page", SLOW_PAGES, ids=_ids(SLOW_PAGES))
def test_page_commands_run_with_the_slow_blocks(page, tmp_path, monkeypatch):
    assert _run_page(page, ("run", "small", "slow"), tmp_path, monkeypatch) > 0


def test_the_docs_name_no_flag_a_small_budget_would_miss():
    """The small budget's flags are the commands' own: a renamed flag would leave a budget uncut."""
    from lawn_cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for key, flags in SMALL.items():
        words = key.split()
        if words[0] != "lawn":
            continue
        known = {o for a in sub.choices[words[1]]._actions for o in a.option_strings}
        assert set(flags) <= known, (key, set(flags) - known)
    example = (ROOT / "examples" / "ppo_lawn.py").read_text()
    for flag in SMALL["python examples/ppo_lawn.py"]:
        assert re.search(rf"^    {flag[2:].replace('-', '_')}: ", example, re.MULTILINE), flag
