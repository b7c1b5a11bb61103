"""The end of a benchmark script: its PASS/FAIL lines printed, and its README table written."""

from __future__ import annotations


def finish(checks: list[tuple[str, bool]], markdown: str | None, lines: list[str]) -> int:
    """Print ``checks`` (name, passed); with ``markdown``, write ``lines`` and the checks there as the
    README block's body. Returns the script's exit code: 0 when every check passed."""
    marks = [f"[{'PASS' if ok else 'FAIL'}] {name}" for name, ok in checks]
    for mark in marks:
        print(mark)
    if markdown:
        with open(markdown, "w") as fh:
            fh.write("\n".join(lines + [""] + [f"* {mark}" for mark in marks]) + "\n")
    return 0 if all(ok for _, ok in checks) else 1


def worktree(path, commit: str):
    """``path``, a checkout of ``commit`` made with ``git worktree add`` when it has no package yet
    (the tree a side-by-side benchmark compares with)."""
    import subprocess
    from pathlib import Path

    path = Path(path).resolve()
    if not (path / "lawn_env").is_dir():
        here = Path(__file__).resolve().parents[1]
        subprocess.run(["git", "-C", str(here), "worktree", "add", "--detach", str(path), commit], check=True,
                       capture_output=True)
    return path
