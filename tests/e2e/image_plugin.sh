#!/usr/bin/env bash
# OpenImageIO is a module (liblensopt_oiio.so, src/core/image_plugin.h): the executable does not
# link it, a render of PNG files never loads it, other formats load it on first use, and a module
# that cannot be loaded is a clear error naming the format.
set -u
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() {
  echo "FAIL: $*" >&2
  exit 1
}

if ldd "$lensopt" | grep -qi "OpenImageIO"; then
  fail "lensopt links OpenImageIO: $(ldd "$lensopt" | grep -i OpenImageIO)"
fi

# PNG in, PNG out: the module is not loaded (LD_DEBUG=files lists every object dlopen'ed).
LD_DEBUG=files "$lensopt" chart -o "$tmp/chart.png" --size 160x96 --no-text > /dev/null 2> "$tmp/chart.txt" ||
  fail "chart --no-text: $(grep -v '^ *[0-9]*:' "$tmp/chart.txt" | tail -n 3)"
LD_DEBUG=files "$lensopt" render lenses/doublet.toml "$tmp/chart.png" -o "$tmp/out" -q > /dev/null 2> "$tmp/render.txt" ||
  fail "render of a PNG: $(grep -v '^ *[0-9]*:' "$tmp/render.txt" | tail -n 3)"
[ -s "$tmp/out/chart.png" ] || fail "no rendered PNG"
for log in chart render; do
  if grep -q "liblensopt_oiio\|libOpenImageIO" "$tmp/$log.txt"; then
    fail "$log of a PNG loaded OpenImageIO: $(grep 'liblensopt_oiio\|libOpenImageIO' "$tmp/$log.txt" | head -n 2)"
  fi
done
# ... and needs no module at all.
LENSOPT_OIIO_PLUGIN="$tmp/missing.so" "$lensopt" render lenses/doublet.toml "$tmp/chart.png" \
  -o "$tmp/out2" -q > /dev/null 2> "$tmp/err.txt" ||
  fail "a PNG render needed the module: $(cat "$tmp/err.txt")"
cmp -s "$tmp/out/chart.png" "$tmp/out2/chart.png" || fail "the two PNG renders differ"

# EXR: through the module, loaded on first use.
LD_DEBUG=files "$lensopt" chart -o "$tmp/chart.exr" --size 160x96 --no-text > /dev/null 2> "$tmp/exr.txt" ||
  fail "chart EXR: $(grep -v '^ *[0-9]*:' "$tmp/exr.txt" | tail -n 3)"
grep -q "file=.*liblensopt_oiio.so .*dynamically loaded" "$tmp/exr.txt" ||
  fail "the EXR chart did not load liblensopt_oiio.so"
head -c 4 "$tmp/chart.exr" | od -An -tx1 | grep -q "76 2f 31 01" || fail "chart.exr is not an OpenEXR file"
"$lensopt" render lenses/doublet.toml "$tmp/chart.exr" -o "$tmp/out3" -q > /dev/null 2> "$tmp/err.txt" || fail "render of an EXR: $(cat "$tmp/err.txt")"
[ -s "$tmp/out3/chart.exr" ] || fail "no rendered EXR"

# Without the module: EXR and text are clear errors naming the format and the variable; no file.
if LENSOPT_OIIO_PLUGIN="$tmp/missing.so" "$lensopt" chart -o "$tmp/nope.exr" --size 160x96 \
    --no-text > /dev/null 2> "$tmp/err.txt"; then
  fail "an EXR chart without the module exited 0"
fi
grep -q "EXR" "$tmp/err.txt" || fail "the error does not name EXR: $(cat "$tmp/err.txt")"
grep -q "LENSOPT_OIIO_PLUGIN=$tmp/missing.so" "$tmp/err.txt" ||
  fail "the error does not name the module path: $(cat "$tmp/err.txt")"
[ ! -e "$tmp/nope.exr" ] || fail "an EXR was written without the module"
if LENSOPT_OIIO_PLUGIN="$tmp/missing.so" "$lensopt" render lenses/doublet.toml "$tmp/chart.exr" \
    -o "$tmp/out4" -q > /dev/null 2> "$tmp/err.txt"; then
  fail "an EXR render without the module exited 0"
fi
grep -q "EXR" "$tmp/err.txt" || fail "the render error does not name EXR: $(cat "$tmp/err.txt")"
echo "image_plugin: ok"
