"""Where a generated figure or table came from: the package version and lawn's git commit.

The commit is lawn's own, never that of a repository that merely contains the install:

* in a checkout of lawn (the source tree, or an editable install of it), git is asked, but only
  when this package's parent folder is the top of a git work tree that tracks this file;
* in an installed wheel, the commit recorded when the wheel was built (``_build_info.json`` beside
  this file, written by ``setup.py``'s build step from the checkout it was built from);
* otherwise ``commit unknown``.

This module imports nothing of lawn at its top: ``setup.py`` loads it by path at build time, before
lawn's dependencies are installed.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import TypedDict

__all__ = ["provenance", "source_stamp", "BUILD_INFO"]

_ROOT = Path(__file__).resolve().parent.parent
#: The build stamp of an installed wheel: {"commit": ..., "dirty": ...}.
BUILD_INFO = Path(__file__).resolve().with_name("_build_info.json")
#: The generated outputs themselves (README, docs/, the exported agents) do not change a number.
_GENERATED = (":(exclude)README.md", ":(exclude)docs", ":(exclude)agents/zoo")


def _git(root: Path, *args: str) -> str:
    done = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, check=True, timeout=10)
    return done.stdout.strip()


class Stamp(TypedDict):
    """The commit a checkout or a wheel was made from, and whether tracked files differed from it."""

    commit: str
    dirty: bool


def source_stamp(root: Path = _ROOT) -> Stamp | None:
    """``{"commit", "dirty"}`` of the lawn checkout at ``root`` (``dirty``: a tracked file other than
    the generated outputs differs from the commit); None when ``root`` is not the top of a git work
    tree that tracks ``evaluation/provenance.py`` (an install inside someone else's repository)."""
    root = Path(root).resolve()
    try:
        if Path(_git(root, "rev-parse", "--show-toplevel")).resolve() != root:
            return None
        _git(root, "ls-files", "--error-unmatch", "evaluation/provenance.py")
        commit = _git(root, "rev-parse", "--short=10", "HEAD")
        dirty = _git(root, "status", "--porcelain", "--untracked-files=no", "--", ".", *_GENERATED)
    except (OSError, subprocess.SubprocessError):
        return None
    return {"commit": commit, "dirty": bool(dirty)}


def _build_stamp() -> Stamp | None:
    try:
        stamp = json.loads(BUILD_INFO.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(stamp, dict) or not isinstance(stamp.get("commit"), str):
        return None
    return {"commit": stamp["commit"], "dirty": bool(stamp.get("dirty", False))}


def provenance() -> str:
    """``"lawn 0.1.0, commit abc1234"`` (``+ uncommitted changes`` when the checkout or the tree the
    wheel was built from differed from its commit; ``commit unknown`` when neither is known)."""
    import lawn_env

    stamp = source_stamp() or _build_stamp()
    if stamp is None:
        return f"lawn {lawn_env.__version__}, commit unknown"
    dirty = " + uncommitted changes" if stamp["dirty"] else ""
    return f"lawn {lawn_env.__version__}, commit {stamp['commit']}{dirty}"
