"""Where a generated figure or table came from: the package version and the git commit."""

from __future__ import annotations

import subprocess
from pathlib import Path

import lawn_env

__all__ = ["provenance"]

_ROOT = Path(__file__).resolve().parent.parent
_GENERATED = (":(exclude)README.md", ":(exclude)docs", ":(exclude)agents/zoo")


def provenance() -> str:
    """``"lawn 0.1.0, commit abc1234"`` (``+ uncommitted changes`` when a tracked file other than the
    generated outputs differs from the commit; ``commit unknown`` outside a git checkout)."""
    try:
        commit = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], cwd=_ROOT, capture_output=True, text=True,
                                check=True, timeout=10).stdout.strip()
        # the generated outputs themselves (README, docs/, the exported agents) do not change a number
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".", *_GENERATED],
                               cwd=_ROOT, capture_output=True, text=True, check=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return f"lawn {lawn_env.__version__}, commit unknown"
    return f"lawn {lawn_env.__version__}, commit {commit}" + (" + uncommitted changes" if dirty else "")
