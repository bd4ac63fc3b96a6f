#!/usr/bin/env bash
# README's test command: installs dependencies, builds, runs every unit and end-to-end test.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/install-deps.sh
tools/build.sh
ctest --test-dir build --output-on-failure -j 2
