#!/usr/bin/env bash
# Browser test of `fairgrasp view`: headless Chromium driven over the DevTools protocol checks
# by pixels that the arm is drawn, that Step changes the scene and that joint slider 1 moves the
# arm. Installs Debian's chromium when root under CI=true; otherwise skips if it is missing.
# Usage: scripts/browser_test.sh [SCREENSHOT.png]   (FAIRGRASP=path/to/fairgrasp to skip the build)
set -euo pipefail
cd "$(dirname "$0")/.."

chrome=$(command -v chromium || command -v chromium-browser || command -v google-chrome || true)
if [ -z "$chrome" ]; then
  if [ "$(id -u)" = 0 ] && [ "${CI:-}" = true ]; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium >/dev/null
    chrome=$(command -v chromium)
  else
    echo "browser_test: SKIPPED — no chromium (install it, or run as root with CI=true)"
    exit 0
  fi
fi

# The venv below needs ensurepip (Debian's python3-venv).
if ! python3 -c 'import ensurepip' 2>/dev/null && [ "$(id -u)" = 0 ] && [ "${CI:-}" = true ]; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends python3-venv >/dev/null
fi

target_dir=$(cargo metadata --format-version 1 --no-deps | python3 -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')
venv=${BROWSER_TEST_VENV:-$target_dir/browser-test-venv}
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "websocket-client==1.8.0"
fi

bin=${FAIRGRASP:-}
if [ -z "$bin" ]; then
  cargo build -q --locked -p fairgrasp-cli
  bin=$target_dir/debug/fairgrasp
fi

exec "$venv/bin/python" scripts/browser_test.py "$chrome" "$bin" "${1:-}"
