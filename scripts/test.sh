#!/usr/bin/env bash
# Install dicetrace with its test extras into .venv and run the test suite (its CI tier; --all: every test).
# As root on Debian it also installs Xvfb and Mesa's software Vulkan, so the
# test that renders a recording with the real Rerun viewer runs (it is skipped
# where xvfb-run is missing; it counts the faces' pips on the screenshot).
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v xvfb-run >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
        xvfb xauth mesa-vulkan-drivers libgl1-mesa-dri libegl1 libxkbcommon-x11-0 >/dev/null) \
        || echo "note: could not install xvfb/mesa; the viewer test will be skipped"
fi
# Debian's chromium for the explorer's headless-browser tests (skipped where it is missing).
if ! command -v chromium >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium >/dev/null) \
        || echo "note: could not install chromium; the explorer's browser tests will be skipped"
fi
python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test]"
.venv/bin/lint-imports
# Compile the numba kernels into numba's cache once, on every CPU, before pytest's workers would
# each compile the ones they meet first (a few seconds when the cache is warm).
.venv/bin/python tests/compile_kernels.py
# The CI tier leaves out the tests marked `long` (end-to-end checks of 5 s to minutes each, ~12 min more on
# 2 cores); `scripts/test.sh --all` runs them too. Other arguments go to pytest.
if [ "${1:-}" = "--all" ]; then
    shift
    .venv/bin/python -m pytest -n 2 "$@"
else
    .venv/bin/python -m pytest -n 2 -m "not long" "$@"
fi
