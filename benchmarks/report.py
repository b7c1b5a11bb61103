"""The end of a benchmark script: its checks and targets printed, and its README table written.

A *check* is a correctness condition (answers equal to the oracle's, episodes as recorded): a failed
one is ``[FAIL]`` and the script exits 1. A *target* is a speed figure an issue asked for: ``[PASS]``
when met, ``[MISS]`` when not, printed beside the measured figure, and the script still exits 0 (the
figure is the result; a machine slower than the one a target was set on misses it without anything
being wrong).
"""

from __future__ import annotations


def marks(checks: list[tuple[str, bool]], targets: list[tuple[str, bool]] = ()) -> list[str]:
    """The lines ``[PASS] name`` / ``[FAIL] name`` of the checks and ``[PASS]`` / ``[MISS]`` of the targets."""
    return ([f"[{'PASS' if ok else 'FAIL'}] {name}" for name, ok in checks]
            + [f"[{'PASS' if ok else 'MISS'}] {name}" for name, ok in targets])


def finish(checks: list[tuple[str, bool]], markdown: str | None, lines: list[str],
           targets: list[tuple[str, bool]] = ()) -> int:
    """Print the ``checks`` and ``targets`` (name, passed); with ``markdown``, write ``lines`` and
    them there as the README block's body. Returns the script's exit code: 0 when every check passed
    (a missed target is reported, not an error)."""
    lines_out = marks(checks, targets)
    for mark in lines_out:
        print(mark)
    if markdown:
        with open(markdown, "w") as fh:
            fh.write("\n".join(lines + [""] + [f"* {mark}" for mark in lines_out]) + "\n")
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
