#!/usr/bin/env bash
# Look at the built site as a reader would: headless Chromium screenshots of the landing page and an
# environment page (not part of CI). Needs Chromium (Debian: apt-get install chromium); builds the site
# first (scripts/docs.sh). Writes runs/screenshots/{index,joint,configuration}.png.
#   bash scripts/screenshots.sh [WIDTHxHEIGHT]
set -euo pipefail
cd "$(dirname "$0")/.."
size="${1:-1280x2400}"
browser="$(command -v chromium || command -v chromium-browser || command -v google-chrome || true)"
if [ -z "$browser" ]; then
  echo "screenshots: no Chromium found; on Debian: apt-get install chromium" >&2
  exit 2
fi
bash scripts/docs.sh
mkdir -p runs/screenshots
profile="$(mktemp -d)"
trap 'rm -rf "$profile"' EXIT
for page in index envs/joint configuration; do
  out="runs/screenshots/$(basename "$page").png"
  "$browser" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync --hide-scrollbars \
    --user-data-dir="$profile" --window-size="${size/x/,}" --screenshot="$out" \
    "file://$PWD/site/$page.html" 2>/dev/null
  echo "wrote $out"
done
