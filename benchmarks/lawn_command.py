"""The ``lawn`` command of whichever tree runs this script: ``python benchmarks/lawn_command.py ARG ...``
is ``lawn ARG ...`` there, in a tree from before the command line moved to ``lawn_cli`` (that tree's
``training.cli``) as after. What ``benchmarks/side_by_side.py`` times against such a commit:

    python benchmarks/side_by_side.py --commit C -- python benchmarks/lawn_command.py benchmark --episodes 20 ...

Without arguments, the main job (``lawn benchmark --episodes 20 --seed 0``, scripts/run.sh) into a
temporary folder.
"""

from __future__ import annotations

import importlib
import sys
import tempfile


def main(argv: list[str]) -> int:
    try:
        cli = importlib.import_module("lawn_cli")
    except ModuleNotFoundError:  # a tree from before the command line had a package of its own
        cli = importlib.import_module("training.cli")
    if argv:
        return int(cli.main(argv))
    with tempfile.TemporaryDirectory() as out:
        return int(cli.main(["benchmark", "--episodes", "20", "--seed", "0", "--out", out, "--overwrite", "--quiet"]))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
