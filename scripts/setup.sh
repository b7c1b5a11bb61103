#!/usr/bin/env bash
# Create .venv and install lawn into it.
#   scripts/setup.sh        core install (lawn_env, agents, training; no torch)
#   scripts/setup.sh full   + the CPU build of torch, stable-baselines3, minari, the test and docs tools
#   scripts/setup.sh docs   core + the documentation tools (Sphinx, Furo, MyST; scripts/docs.sh)
# torch is installed first, pinned to the CPU build, so nothing that depends on it pulls the
# CUDA wheels. Idempotent: rerunning only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-core}"
python="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  "$python" -m venv .venv
fi
pip=(.venv/bin/python -m pip install --quiet --disable-pip-version-check)
case "$mode" in
  core) "${pip[@]}" -e . ;;
  docs) "${pip[@]}" -e ".[docs]" ;;
  full)
    "${pip[@]}" "torch==2.13.0"
    "${pip[@]}" -e ".[rl,test,data,docs]"
    ;;
  *) echo "usage: scripts/setup.sh [core|full|docs]" >&2; exit 2 ;;
esac
