#!/usr/bin/env bash
# Static checks of the packages: ruff check and mypy, both configured in pyproject.toml.
#   scripts/lint.sh             lawn_env, agents and training
#   scripts/lint.sh PATH ...    only these files or packages
# Runs both tools whatever the first finds; exits non-zero if either reports a finding.
# Needs the test extra (scripts/setup.sh full installs it into .venv).
set -uo pipefail
cd "$(dirname "$0")/.."
bin=.venv/bin
[ -x "$bin/ruff" ] && [ -x "$bin/mypy" ] || bin="$(dirname "$(command -v ruff || echo /nonexistent/ruff)")"
if [ ! -x "$bin/ruff" ] || [ ! -x "$bin/mypy" ]; then
  echo "lint: ruff and mypy not found; install the test extra (bash scripts/setup.sh full)" >&2
  exit 2
fi
if [ "$#" -gt 0 ]; then paths=("$@"); else paths=(lawn_env agents evaluation training paper lawn_cli); fi
status=0
echo "== ruff check ${paths[*]}"
"$bin/ruff" check "${paths[@]}" || status=1
echo "== mypy ${paths[*]}"
"$bin/mypy" "${paths[@]}" || status=1
exit "$status"
