#!/usr/bin/env bash
# Build the documentation site into site/ (open site/index.html): set up .venv with the docs extra,
# then Sphinx (Furo theme, MyST Markdown) in strict mode: any warning, a broken cross-reference or
# link to a missing page, fails the build. Extra arguments go to sphinx-build.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh docs
exec .venv/bin/python -m sphinx -W --keep-going -b html -q docs site "$@"
