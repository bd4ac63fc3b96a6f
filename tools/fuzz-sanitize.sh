#!/usr/bin/env bash
# Builds lensopt with AddressSanitizer and UndefinedBehaviorSanitizer in ./build-sanitize (a
# separate tree; Debug-level checks with -O1, without libtorch) and runs the fuzz test
# (tests/e2e/fuzz.sh) and the unit tests of the readers under it. Run before each release; any
# sanitizer report fails the run (halt_on_error). Usage: tools/fuzz-sanitize.sh [cases] [seed]
set -euo pipefail
cd "$(dirname "$0")/.."
cases="${1:-1000}"
seed="${2:-15}"
flags="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer -g -O1"
cmake -S . -B build-sanitize -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="$flags" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" -DLENSOPT_WITH_TORCH=OFF >/dev/null
cmake --build build-sanitize -j "$(nproc)" --target lensopt lensopt_tests
export ASAN_OPTIONS="halt_on_error=1:detect_leaks=0:abort_on_error=0:exitcode=86"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:exitcode=87"
build-sanitize/lensopt_tests --no-intro \
  -sf="*/test_zmx*.cpp,*/test_lens*.cpp,*/test_glass*.cpp,*/test_robustness*.cpp"
LENSOPT_FUZZ_CASES="$cases" LENSOPT_FUZZ_SEED="$seed" bash tests/e2e/fuzz.sh build-sanitize/lensopt
echo "fuzz-sanitize: $cases cases (seed $seed) under ASan + UBSan: no report"
