#!/usr/bin/env bash
# The installed package works for another project: installs the build (runtime and development
# components) into a temporary prefix, configures tests/package against it with
# find_package(lensopt), builds and runs it, and checks its paraxial EFL against the thick-lens
# formula. Usage: tests/package/run.sh <build-dir> <source-dir>
set -euo pipefail
build="$(cd "$1" && pwd)"
source="$(cd "$2" && pwd)"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
fail() {
  echo "package: $*" >&2
  exit 1
}

[ -f "$build/liblensopt_trace.a" ] || { echo "package: the libraries are not built; skipped" >&2; exit 77; }
for component in lensopt_runtime lensopt_development; do
  cmake --install "$build" --prefix "$tmp/prefix" --component "$component" > "$tmp/install.log" ||
    fail "cmake --install --component $component: $(cat "$tmp/install.log")"
done
[ -f "$tmp/prefix/lib/cmake/lensopt/lensoptConfig.cmake" ] || fail "no lensoptConfig.cmake installed"
[ -f "$tmp/prefix/include/lensopt/trace/kernel.h" ] || fail "headers not installed"
ls "$tmp/prefix/share/lensopt/catalogs/"*.agf > /dev/null 2>&1 || ls "$tmp/prefix/share/lensopt/catalogs/"*.AGF > /dev/null 2>&1 ||
  fail "no glass catalogs in share/lensopt/catalogs"
[ -x "$tmp/prefix/bin/lensopt" ] || fail "no bin/lensopt installed"
if grep -rq "fftw3.h\|toml++" "$tmp/prefix/include/lensopt"; then
  echo "package: note: a public header includes FFTW or toml++:" >&2
  grep -rl "fftw3.h\|toml++" "$tmp/prefix/include/lensopt" >&2
fi

generator=()
command -v ninja > /dev/null && generator=(-G Ninja)
cmake -S "$source/tests/package" -B "$tmp/build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$tmp/prefix" > "$tmp/configure.log" 2>&1 ||
  fail "configure with find_package(lensopt): $(tail -n 30 "$tmp/configure.log")"
cmake --build "$tmp/build" > "$tmp/build.log" 2>&1 || fail "build: $(tail -n 30 "$tmp/build.log")"
efl_mm="$("$tmp/build/package_test")" || fail "package_test failed"
# Thick biconvex lens in air: 1/f = (n-1) [1/R1 - 1/R2 + (n-1) d / (n R1 R2)].
python3 - "$efl_mm" <<'PY' || fail "EFL $efl_mm mm differs from the thick-lens formula"
import sys
n, r1, r2, d = 1.5168, 50.0, -50.0, 4.0
f = 1.0 / ((n - 1) * (1 / r1 - 1 / r2 + (n - 1) * d / (n * r1 * r2)))
got = float(sys.argv[1])
assert abs(got - f) < 1e-6 * f, (got, f)
PY
# The libtorch module (when built): installed in <libdir>/lensopt, and the installed executable
# loads that copy (found relative to itself), not the build tree's.
if [ -f "$build/liblensopt_torch.so" ]; then
  module=$(find "$tmp/prefix" -name liblensopt_torch.so | head -n 1)
  [ -n "$module" ] || fail "liblensopt_torch.so was not installed"
  LD_DEBUG=files "$tmp/prefix/bin/lensopt" optimize "$source/lenses/doublet.toml" --joint \
    -o "$tmp/joint.toml" --task frobnicate --scenes 2 --scene-width 64 --scene-height 64 --crop 32 \
    --batch 1 --eval-crops 1 --psf-rings 2 --psf-fields 3 --design-rings 2 --design-fields 3 \
    --steps 1 -q > /dev/null 2> "$tmp/joint.txt" && fail "--task frobnicate was accepted"
  grep -q "unknown task 'frobnicate'" "$tmp/joint.txt" ||
    fail "the installed lensopt did not reach the module: $(grep -v '^ *[0-9]*:' "$tmp/joint.txt" | tail -n 5)"
  grep -q "file=$module .*dynamically loaded" "$tmp/joint.txt" ||
    fail "the installed lensopt loaded another module: $(grep 'liblensopt_torch' "$tmp/joint.txt" | head -n 3)"
fi
# The OpenImageIO module (when built): installed in <libdir>/lensopt; the installed lensopt loads
# that copy for an EXR, and links neither OpenImageIO nor the module.
if [ -f "$build/liblensopt_oiio.so" ]; then
  module=$(find "$tmp/prefix" -name liblensopt_oiio.so | head -n 1)
  [ -n "$module" ] || fail "liblensopt_oiio.so was not installed"
  if ldd "$tmp/prefix/bin/lensopt" | grep -qi "OpenImageIO"; then
    fail "the installed lensopt links OpenImageIO"
  fi
  LD_DEBUG=files "$tmp/prefix/bin/lensopt" chart -o "$tmp/chart.exr" --size 64x48 --no-text \
    > /dev/null 2> "$tmp/oiio.txt" || fail "the installed lensopt could not write an EXR: $(grep -v '^ *[0-9]*:' "$tmp/oiio.txt" | tail -n 3)"
  grep -q "file=$module .*dynamically loaded" "$tmp/oiio.txt" ||
    fail "the installed lensopt loaded another OpenImageIO module: $(grep 'liblensopt_oiio' "$tmp/oiio.txt" | head -n 3)"
fi
echo "package: find_package(lensopt) from $tmp/prefix: built and ran (EFL $efl_mm mm)"
