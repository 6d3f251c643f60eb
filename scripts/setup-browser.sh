#!/usr/bin/env bash
# Install headless Chromium (Debian's package) for the report and viewer tests, if it is missing.
# The viewer tests drive it through the `playwright` Python package (the dev extra) with
# executable_path=/usr/bin/chromium: never run `playwright install`, no browser download is needed.
set -euo pipefail
for name in chromium chromium-browser google-chrome; do
  if command -v "$name" >/dev/null 2>&1; then
    echo "browser: $(command -v "$name")"
    exit 0
  fi
done
SUDO=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null 2>&1 || { echo "setup-browser: need root or sudo to apt-get install chromium" >&2; exit 1; }
  SUDO="sudo -n"
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends chromium fonts-dejavu-core
command -v chromium
