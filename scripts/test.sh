#!/usr/bin/env bash
# Set up the full environment (.venv) and run the test suite on two pytest-xdist workers. Extra arguments go to pytest,
# e.g. `bash scripts/test.sh -m slow` for the slow tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh full
exec .venv/bin/python -m pytest -q -n 2 "$@"  # the two cores; tests that use a process pool still do
