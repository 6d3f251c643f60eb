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
. "$(dirname "$0")/_apt.sh"
apt_install setup-browser chromium fonts-dejavu-core
command -v chromium
