#!/usr/bin/env bash
# ThreadSanitizer run of the render and joint unit tests (issue 13; docs/tsan.md).
#
# GCC's OpenMP runtime (libgomp) is not instrumented, so TSan built with GCC reports libgomp's own
# barriers as races. This build uses clang with LLVM's OpenMP runtime (libomp) and its TSan tool
# Archer (libarcher.so, Debian package libomp-14-dev), which tells TSan about OpenMP's
# synchronisation: the OpenMP regions run on several threads and are checked too.
# The kernels' function multiversioning (GCC target_clones: an ifunc resolver picks the x86-64
# level at load time) is turned off here: the dynamic loader runs the resolvers before TSan's
# runtime is initialised, and their instrumented entry crashes the process (and clang does not
# multiversion templates). `-Dtarget_clones(...)=unused` turns each such attribute into
# __attribute__((unused)), so the baseline build of every kernel is what runs under TSan.
# The run-time modules (liblensopt_oiio.so) are linked without --no-undefined here
# (CMakeLists.txt): TSan's runtime symbols are resolved by the executable.
# Usage: tools/tsan.sh [doctest filter, default 'render*,joint*']; JOBS=N for the build.
set -euo pipefail
cd "$(dirname "$0")/.."
filter="${1:-render*,joint*}"
archer=/usr/lib/llvm-14/lib/libarcher.so
[ -f "$archer" ] || { echo "tsan: $archer missing (apt-get install libomp-14-dev clang)" >&2; exit 2; }
# -O1 with line tables only: TSan's reports keep file:line, and the build takes about half the
# time of -O2 -g (the Jet-heavy sources are slow to compile with instrumentation).
cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only -DNDEBUG" \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_CXX_FLAGS="-fsanitize=thread '-Dtarget_clones(...)=unused'" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=thread" \
  -DLENSOPT_WITH_PYTHON=OFF -DLENSOPT_WITH_TORCH=OFF >/dev/null
cmake --build build-tsan -j "${JOBS:-2}" --target lensopt_tests_threads
export OMP_TOOL_LIBRARIES="$archer"
export TSAN_OPTIONS="halt_on_error=0 second_deadlock_stack=1 ignore_noninstrumented_modules=1 ${TSAN_OPTIONS:-}"
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-2}"
log=build-tsan/tsan.log
set +e
build-tsan/lensopt_tests_threads --no-intro -tc="$filter" 2>&1 | tee "$log"
status=${PIPESTATUS[0]}
set -e
races=$(grep -c "WARNING: ThreadSanitizer" "$log" || true)
echo "tsan: exit $status, $races ThreadSanitizer warnings (log: $log)"
[ "$status" -eq 0 ] && [ "$races" -eq 0 ]
