"""The main job (``lawn benchmark --episodes 20 --seed 0``, scripts/run.sh) in whichever tree runs
this script, into a temporary folder: what ``benchmarks/side_by_side.py`` times against a commit from
before the command line moved to ``lawn_cli`` (that tree's ``training.cli``) as well as after.

    python benchmarks/side_by_side.py --commit C -- python benchmarks/main_job.py [ARG ...]
"""

from __future__ import annotations

import importlib
import sys
import tempfile


def main(argv: list[str] | None = None) -> int:
    try:
        cli = importlib.import_module("lawn_cli")
    except ModuleNotFoundError:  # a tree from before the command line had a package of its own
        cli = importlib.import_module("training.cli")
    with tempfile.TemporaryDirectory() as out:
        args = ["benchmark", "--episodes", "20", "--seed", "0", "--out", out, "--overwrite", "--quiet", *(argv or [])]
        return int(cli.main(args))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
