#!/usr/bin/env bash
# Hostile input under resource limits (issue 34): every input kind lensopt reads (TOML, paper
# YAML, .zmx, AGF, PNG / TIFF / EXR, COCO JSON) in forms built to crash it or to make it work
# without bound: nesting that overflowed toml++'s stack, YAML alias bombs, lenses of 100,000
# surfaces, image headers that promise gigapixels in a few bytes, and weights that left nothing to
# trace. Each runs under a 2 GB address-space cap (ulimit -v 2000000) and 60 s of CPU
# (ulimit -t 60) and must end without a signal, with exit 1 and an error that names the file
# (and the line, for text formats), within a few seconds of wall time. A file that is valid but
# large may also succeed (exit 0), with no null / NaN in its JSON. Then the fuzz corpus
# (tests/e2e/fuzz.sh, its default cases and seed) runs under the same limits.
set -euo pipefail
lensopt="$1"
command -v python3 > /dev/null || { echo "skipped: python3 is needed to build the inputs"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
max_seconds="${LENSOPT_HOSTILE_MAX_SECONDS:-10}"
"$lensopt" convert lenses/doublet.toml "$tmp/doublet.zmx" > /dev/null

python3 - "$tmp" <<'PY'
import os, struct, sys, zlib
tmp = sys.argv[1]
def w(name, data):
    with open(os.path.join(tmp, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())
doublet = open("lenses/doublet.toml").read()
parts = ".".join(["a"] * 40000)
# TOML: 40,000-part table header (80 kB), dotted key, inline table key, quoted parts, deep arrays.
w("header.toml", "[" + parts + "]\nx = 1\n" + doublet)
w("dotted.toml", parts + " = 1\n")
w("inline.toml", "x = {" + parts + " = 1}\n")
w("quoted.toml", ".".join(['"a"'] * 40000) + " = 1\n")
w("arrays.toml", "x = " + "[" * 40000 + "]" * 40000 + "\n")
w("tables.toml", "x = " + "{a = " * 40000 + "1" + "}" * 40000 + "\n")
# TOML: 100,000 surfaces (5 MB): the doublet with flat, zero-thickness air surfaces after its stop
# (a valid lens; every ray crosses them all).
stop = doublet.index("stop = true\n") + len("stop = true\n")
w("surfaces.toml", doublet[:stop] + "\n[[surfaces]]\nradius_mm = inf\nthickness_mm = 0\n" * 99996 + doublet[stop:])
# TOML: weights and apertures that left nothing to trace.
head, _, tail = doublet.partition("[[surfaces]]")
w("field_weights.toml", head + "[system]\nfields = [0, 10, 20]\nfield_weights = [0, 0, 0]\n\n[[surfaces]]" + tail)
w("wavelength_weights.toml", head + "[system]\nwavelength_weights = [" + ", ".join(["0"] * 15) + "]\n\n[[surfaces]]" + tail)
w("f_number.toml", head.replace("f_number = 2.0\n", "") + "[system]\naperture = \"f-number\"\n\n[[surfaces]]" + tail)
# YAML: 9 levels of 10 aliases (10^9 nodes expanded), deep nesting, many aliases.
lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
for i in range(1, 10):
    lines.append("a%d: &a%d [%s]" % (i, i, ", ".join(["*a%d" % (i - 1)] * 10)))
w("laughs.yml", "\n".join(lines) + "\n")
w("deep.yml", "a: " + "[" * 100000 + "]" * 100000 + "\n")
w("deep_block.yml", "".join(" " * i + "- \n" for i in range(3000)))
w("aliases.yml", "a: &a 1\nb: [" + ", ".join(["*a"] * 100000) + "]\n")
w("sequence.yml", "stop_idx: [0]\nsequence: [" + "A" * 1000000 + "]\nhfov: [25]\nf_number: [2]\n")
# .zmx: 100,000 surfaces; FWGN all 0.
zmx = open(os.path.join(tmp, "doublet.zmx")).read()
blocks = zmx.split("SURF ")
stop = next(k for k, b in enumerate(blocks) if "\n  STOP" in b)
blocks = blocks[:stop + 1] + ["0\n  TYPE STANDARD\n  CURV 0\n  DISZ 0\n"] * 99994 + blocks[stop + 1:]
w("surfaces.zmx", blocks[0] + "".join("SURF %d\n" % (k - 1) + b.split("\n", 1)[1] for k, b in enumerate(blocks) if k > 0))
w("fwgn.zmx", zmx.replace("FWGN 1 1 1", "FWGN 0 0 0"))
w("numbers.zmx", zmx.replace("YFLN 0 17.5 25", "YFLN" + " 1" * 200000))
# AGF: 5,000 glasses (a 7 MB catalog), a line of a million numbers, binary junk.
agf = open("catalogs/ohara65.agf", "rb").read().split(b"\n")
start = next(i for i, l in enumerate(agf) if l.startswith(b"NM "))
end = next(i for i, l in enumerate(agf) if i > start and l.startswith(b"NM "))
block = agf[start:end]
body = b"\n".join(b"\n".join([block[0].replace(block[0].split()[1], b"G%d" % i, 1)] + block[1:]) for i in range(5000))
w("many.agf", b"\n".join(agf[:start]) + b"\n" + body + b"\n")
w("long_line.agf", b"\n".join(agf[:start]) + b"\n" + block[0] + b"\nCD" + b" 1.5" * 1000000 + b"\n")
w("junk.agf", bytes(range(256)) * 4000)
# PNG: headers of 20000^2 and 50000^2 pixels over 8 x 8 pixels of data (138 and 225 bytes).
def chunk(t, d):
    return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
def png(wd, ht, data):
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", wd, ht, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(data)) + chunk(b"IEND", b""))
os.makedirs(os.path.join(tmp, "png20k"))
os.makedirs(os.path.join(tmp, "png50k"))
w("png20k/big.png", png(20000, 20000, b"\0" * 64))
w("png50k/big.png", png(50000, 50000, b"\0" * 5000))
# TIFF: a 50000 x 50000 8-bit grey header over 64 bytes of strip.
os.makedirs(os.path.join(tmp, "tiff"))
entries = [(256, 4, 1, 50000), (257, 4, 1, 50000), (258, 3, 1, 8), (259, 3, 1, 1), (262, 3, 1, 1),
           (273, 4, 1, 8 + 2 + 12 * 10 + 4), (277, 3, 1, 1), (278, 4, 1, 50000), (279, 4, 1, 64),
           (284, 3, 1, 1)]
ifd = struct.pack("<H", len(entries)) + b"".join(
    struct.pack("<HHI", tag, typ, count) + (struct.pack("<HH", value, 0) if typ == 3 else struct.pack("<I", value))
    for tag, typ, count, value in entries) + struct.pack("<I", 0)
w("tiff/big.tif", b"II*\0" + struct.pack("<I", 8) + ifd + b"\0" * 64)
# COCO JSON: nesting 1,000,000 deep, and a valid file with 50,000 annotations of no image.
w("deep.json", "[" * 1000000 + "]" * 1000000)
annotations = ",".join('{"id": %d, "image_id": 999999, "category_id": 1, "bbox": [1, 2, 3, 4]}' % i
                       for i in range(50000))
w("many.json", '{"images": [], "categories": [{"id": 1, "name": "car"}], "annotations": [' + annotations + "]}")
PY

# limited EXPECT FILE COMMAND...: runs lensopt under the limits; it must exit 1 (or 0 when
# EXPECT is "ok-or-error") without a signal, within max_seconds, naming FILE and matching EXPECT.
limited() {
  local expect=$1 file=$2
  shift 2
  local status=0 start end
  start=$(date +%s%N)
  (
    ulimit -v 2000000
    ulimit -t 60
    exec "$lensopt" "$@"
  ) > "$tmp/stdout" 2> "$tmp/stderr" || status=$?
  end=$(date +%s%N)
  local ms=$(((end - start) / 1000000))
  echo "  $file: exit $status in $ms ms: $( (grep -m1 -F "$file" "$tmp/stderr" || head -1 "$tmp/stderr") | cut -c1-200)"
  [ "$status" -lt 128 ] || fail "$* died of signal $((status - 128)): $(tail -c 400 "$tmp/stderr")"
  [ "$status" -ne 2 ] || fail "$*: internal error: $(cat "$tmp/stderr")"
  [ "$ms" -le $((max_seconds * 1000)) ] || fail "$* took $ms ms (bound: $max_seconds s)"
  if [ "$expect" = "ok-or-error" ]; then
    if [ "$status" -eq 0 ]; then
      ! grep -Eqi '(null|nan|inf)[,}\] ]' "$tmp/stdout" || fail "$*: null/NaN at exit 0"
      return
    fi
  else
    [ "$status" -eq 1 ] || fail "$* exited $status, not 1: $(cat "$tmp/stderr")"
  fi
  grep -q "$file" "$tmp/stderr" || fail "$*: the error does not name $file: $(cat "$tmp/stderr")"
  [ "$expect" = "ok-or-error" ] || grep -Eq "$expect" "$tmp/stderr" ||
    fail "$*: the error does not say '$expect': $(cat "$tmp/stderr")"
}

echo "TOML"
for f in header dotted inline quoted; do
  limited "$f.toml:1:[0-9]+: a dotted key of more than 100 parts" "$f.toml" analyze "$tmp/$f.toml"
done
limited "arrays.toml:1:[0-9]+: .*nest more than 100 levels" arrays.toml analyze "$tmp/arrays.toml"
limited "tables.toml:1:[0-9]+: .*nest more than 100 levels" tables.toml analyze "$tmp/tables.toml"
limited "surfaces.toml:[0-9]+:[0-9]+: the lens has 100001 surfaces; lensopt reads at most 1000" \
  surfaces.toml analyze "$tmp/surfaces.toml"
limited "field_weights.toml:[0-9]+:[0-9]+: every field weight is 0" field_weights.toml \
  analyze --json "$tmp/field_weights.toml"
limited "field_weights.toml:[0-9]+:[0-9]+: every field weight is 0" field_weights.toml \
  optimize "$tmp/field_weights.toml" --max-iterations 1 -o "$tmp/o.toml"
limited "wavelength_weights.toml:[0-9]+:[0-9]+: every wavelength weight is 0" \
  wavelength_weights.toml analyze "$tmp/wavelength_weights.toml"
limited "f_number.toml:[0-9]+:[0-9]+: aperture = \"f-number\" needs \[specs\] f_number" \
  f_number.toml analyze "$tmp/f_number.toml"
[ ! -e "$tmp/o.toml" ] || fail "optimize wrote o.toml for a lens without weight"

echo "YAML"
limited "laughs.yml:[0-9]+:[0-9]+: the document expands to more than 100000 nodes" laughs.yml \
  analyze "$tmp/laughs.yml"
limited "deep.yml:1:[0-9]+: lists and maps nest more than 100 levels" deep.yml analyze "$tmp/deep.yml"
limited "deep_block.yml:[0-9]+:[0-9]+: lists and maps nest more than 100 levels" deep_block.yml \
  analyze "$tmp/deep_block.yml"
limited "aliases.yml:2:[0-9]+: more than 1000 aliases" aliases.yml analyze "$tmp/aliases.yml"
limited "sequence.yml:2:[0-9]+: sequence has 1000000 surfaces" sequence.yml analyze "$tmp/sequence.yml"

echo ".zmx"
limited "surfaces.zmx:[0-9]+:[0-9]+: SURF 1002: lensopt reads at most 1000 lens surfaces" \
  surfaces.zmx analyze "$tmp/surfaces.zmx"
limited "fwgn.zmx:[0-9]+:[0-9]+: every active field has weight 0" fwgn.zmx analyze --json "$tmp/fwgn.zmx"
limited "numbers.zmx:[0-9]+:[0-9]+: YFLN has 200000 fields" numbers.zmx analyze "$tmp/numbers.zmx"

echo "AGF"
limited ok-or-error many.agf catalog "$tmp/many.agf" --json
limited ok-or-error long_line.agf catalog "$tmp/long_line.agf" --json
limited ok-or-error junk.agf catalog "$tmp/junk.agf" --json

echo "images"
limited "png20k/big.png: cannot read image: its header says 20000 x 20000 pixels, but the file has" \
  big.png render lenses/doublet.toml "$tmp/png20k" -o "$tmp/r1" -q
limited "png50k/big.png: cannot read image: its header says 50000 x 50000 pixels, but the file has" \
  big.png render lenses/doublet.toml "$tmp/png50k" -o "$tmp/r2" -q
# The pixel limit, on an honest file, and the option that raises it.
mkdir -p "$tmp/chart"
"$lensopt" chart -o "$tmp/chart/c.png" --size 64x48 > /dev/null
limited "chart/c.png: cannot read image: its header says 64 x 48 = 3072 pixels, more than the limit of 3000" \
  c.png render lenses/doublet.toml "$tmp/chart" -o "$tmp/r3" -q --max-image-pixels 3000
if "$lensopt" chart -o "$tmp/probe.tif" --size 64x64 > /dev/null 2>&1; then
  limited "tiff/big.tif: cannot read image: its header says 50000 x 50000" big.tif \
    render lenses/doublet.toml "$tmp/tiff" -o "$tmp/r4" -q
  # EXR: a real 64 x 64 file whose data window then says 50000 x 50000.
  "$lensopt" chart -o "$tmp/c.exr" --size 64x64 > /dev/null
  mkdir -p "$tmp/exr"
  python3 - "$tmp/c.exr" "$tmp/exr/big.exr" <<'PY'
import struct, sys
data = bytearray(open(sys.argv[1], "rb").read())
for name in (b"dataWindow\0box2i\0", b"displayWindow\0box2i\0"):
    at = data.index(name) + len(name) + 4
    data[at:at + 16] = struct.pack("<iiii", 0, 0, 49999, 49999)
open(sys.argv[2], "wb").write(data)
PY
  limited "exr/big.exr: cannot read image" big.exr render lenses/doublet.toml "$tmp/exr" -o "$tmp/r5" -q
else
  echo "  (TIFF and EXR skipped: the OpenImageIO module is not available)"
fi

echo "COCO JSON"
mkdir -p "$tmp/img"
"$lensopt" chart -o "$tmp/img/a.png" --size 64x48 > /dev/null
limited ok-or-error deep.json render lenses/doublet.toml "$tmp/img" -o "$tmp/r6" -q \
  --annotations "$tmp/deep.json"
limited ok-or-error many.json render lenses/doublet.toml "$tmp/img" -o "$tmp/r7" -q \
  --annotations "$tmp/many.json"
echo "fuzz corpus (tests/e2e/fuzz.sh) under the same limits"
(
  ulimit -v 2000000
  ulimit -t 60
  bash tests/e2e/fuzz.sh "$lensopt"
) || fail "the fuzz corpus under ulimit -v 2000000 -t 60"
echo "ok"
