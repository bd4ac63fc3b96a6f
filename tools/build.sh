#!/usr/bin/env bash
# Configures and builds lensopt in ./build (Release). Usage: tools/build.sh [extra cmake args]
# LENSOPT_TARGETS="lensopt ..." builds only those targets (and what they need) instead of all:
# tools/run-main.sh builds the command-line tool and its modules, not the unit tests and the
# Python package (about half of the whole build's CPU; BENCHMARKS.md "Build time, second round").
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
targets=()
for target in ${LENSOPT_TARGETS:-}; do targets+=(--target "$target"); done
cmake --build build -j "$(nproc)" "${targets[@]}"
