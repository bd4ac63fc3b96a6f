#!/usr/bin/env bash
# ThreadSanitizer run of the Python tests (issue 29; docs/tsan.md): the extension module
# lensopt._lensopt and every library below it built with clang's -fsanitize=thread and LLVM's
# OpenMP runtime with its TSan tool Archer, as tools/tsan.sh builds the C++ tests. The Python
# interpreter, numpy and torch are not instrumented: the TSan runtime is preloaded into python3
# (GCC's libtsan.so.2, the same runtime interface: clang 14's shared runtime crashes even
# /bin/true on Debian 12's glibc; the extension leaves the __tsan_* symbols to it) and reports
# from modules
# without instrumentation are ignored (ignore_noninstrumented_modules), so what is checked is
# lensopt's own code as Python drives it: field_data, spots, psfs, render, optimize, tolerance.
# The kernels' target_clones are off for the reason tools/tsan.sh gives.
# Usage: tools/tsan-python.sh [unittest pattern, default 'test_*.py']; JOBS=N for the build.
set -euo pipefail
cd "$(dirname "$0")/.."
pattern="${1:-test_*.py}"
archer=/usr/lib/llvm-14/lib/libarcher.so
runtime=/usr/lib/x86_64-linux-gnu/libtsan.so.2
[ -f "$archer" ] || { echo "tsan-python: $archer missing (apt-get install libomp-14-dev clang)" >&2; exit 2; }
[ -f "$runtime" ] || { echo "tsan-python: $runtime missing (apt-get install libtsan2)" >&2; exit 2; }
cmake -S . -B build-tsan-python -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only -DNDEBUG" \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_CXX_FLAGS="-fsanitize=thread '-Dtarget_clones(...)=unused'" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=thread" \
  -DCMAKE_SHARED_LINKER_FLAGS="" -DCMAKE_MODULE_LINKER_FLAGS="" \
  -DLENSOPT_WITH_PYTHON=ON -DLENSOPT_WITH_TORCH=OFF >/dev/null
cmake --build build-tsan-python -j "${JOBS:-2}" --target lensopt_python lensopt
export OMP_TOOL_LIBRARIES="$archer"
export TSAN_OPTIONS="halt_on_error=0 second_deadlock_stack=1 ignore_noninstrumented_modules=1 ${TSAN_OPTIONS:-}"
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-2}"
log=build-tsan-python/tsan.log
set +e
# The CLI the tests compare with (LENSOPT_EXECUTABLE) is built here with the same compiler and
# flags as the module, so the parity tests compare like with like (a GCC -O3 CLI differs from the
# clang -O1 module in the last bits of e.g. a spot radius). It is instrumented too (its threads are
# checked, with clang's runtime linked in statically), so it must not inherit the preloaded GCC
# runtime: a wrapper drops LD_PRELOAD for it. The wrapper is a Python script, not a shell one:
# dash crashes with GCC's TSan runtime preloaded, python3 does not. Python subprocesses of the
# tests keep the preload (they import the instrumented extension).
cli="${LENSOPT_EXECUTABLE:-$PWD/build-tsan-python/lensopt-nopreload}"
if [ -z "${LENSOPT_EXECUTABLE:-}" ]; then
  # The CLI's reports go to build-tsan-python/tsan-cli.PID (the tests capture its stderr).
  cat >"$cli" <<EOF
#!/usr/bin/python3
import os, sys
env = dict(os.environ)
env.pop("LD_PRELOAD", None)
env["TSAN_OPTIONS"] = env.get("TSAN_OPTIONS", "") + " log_path=$PWD/build-tsan-python/tsan-cli"
os.execve("$PWD/build-tsan-python/lensopt", ["$PWD/build-tsan-python/lensopt", *sys.argv[1:]], env)
EOF
  chmod +x "$cli"
  rm -f build-tsan-python/tsan-cli.*
fi
[ -x "$cli" ] || { echo "tsan-python: $cli missing" >&2; exit 2; }
LD_PRELOAD="$runtime" PYTHONPATH=build-tsan-python/python \
  LENSOPT_EXECUTABLE="$cli" LENSOPT_SHARED_DIR="$PWD/../shared" \
  /usr/bin/python3 -m unittest discover -s tests/python -p "$pattern" 2>&1 | tee "$log"
status=${PIPESTATUS[0]}
set -e
races=$(cat "$log" build-tsan-python/tsan-cli.* 2>/dev/null | grep -c "WARNING: ThreadSanitizer" || true)
echo "tsan-python: exit $status, $races ThreadSanitizer warnings (log: $log)"
[ "$status" -eq 0 ] && [ "$races" -eq 0 ]
