#!/usr/bin/env bash
# End-to-end test of `lensopt plot`: every kind for one lens as SVG and as PNG (non-empty, an SVG
# root / a PNG signature and the page size the command reports), a compare layout, and clear
# errors for a bad --kind, a bad extension and a missing lens; no file is left behind on errors.
# Usage: plot.sh path/to/lensopt. Exit 0 pass, 1 fail.
set -u
lensopt=${1:?usage: plot.sh path/to/lensopt}
root=$(cd "$(dirname "$0")/../.." && pwd)
lens="$root/lenses/tessar.toml"
other="$root/lenses/doublet.toml"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failures=0

fail() {
  echo "FAIL: $*" >&2
  failures=$((failures + 1))
}

# 1. Every kind, both formats.
for kind in layout spot fan field psf report; do
  for ext in svg png; do
    out="$tmp/$kind.$ext"
    if ! "$lensopt" plot "$lens" --kind "$kind" -o "$out" 2>"$tmp/err"; then
      fail "plot --kind $kind -o $kind.$ext exited non-zero: $(cat "$tmp/err")"
      continue
    fi
    [ -s "$out" ] || { fail "$kind.$ext is empty or missing"; continue; }
    grep -q "warning" "$tmp/err" && fail "$kind.$ext: unexpected warning: $(cat "$tmp/err")"
    # The size the command reports ("1200 x 836 px").
    size=$(sed -n 's/.*page, \([0-9]*\) x \([0-9]*\) px.*/\1 \2/p' "$tmp/err")
    [ -n "$size" ] || fail "$kind.$ext: no page size reported: $(cat "$tmp/err")"
    if [ "$ext" = svg ]; then
      head -c 200 "$out" | grep -q "<svg" || fail "$kind.svg has no <svg> root"
      tail -c 20 "$out" | grep -q "</svg>" || fail "$kind.svg does not end with </svg>"
      python3 -c 'import sys, xml.dom.minidom; xml.dom.minidom.parse(sys.argv[1])' "$out" 2>"$tmp/xml" ||
        fail "$kind.svg is not well-formed XML: $(cat "$tmp/xml")"
    else
      sig=$(head -c 8 "$out" | od -An -tx1 | tr -d ' \n')
      [ "$sig" = "89504e470d0a1a0a" ] || fail "$kind.png has no PNG signature ($sig)"
      # Width and height from the IHDR chunk match the reported page size.
      dims=$(python3 -c '
import struct, sys
d = open(sys.argv[1], "rb").read(24)
print(*struct.unpack(">II", d[16:24]))' "$out")
      [ "$dims" = "$size" ] || fail "$kind.png is $dims px, the command said $size"
    fi
  done
done

# 2. A compare layout and compare spots (two rows on one scale).
"$lensopt" plot "$lens" --kind layout --compare "$other" -o "$tmp/compare.svg" 2>"$tmp/err" ||
  fail "compare layout failed: $(cat "$tmp/err")"
grep -q "doublet (dashed)" "$tmp/compare.svg" || fail "compare layout has no legend for the second lens"
"$lensopt" plot "$lens" --kind spot --compare "$other" --spot-box-um 400 -o "$tmp/cspot.png" \
  2>"$tmp/err" || fail "compare spots failed: $(cat "$tmp/err")"
grep -q "spot boxes 400 um" "$tmp/err" || fail "the spot box option was not used: $(cat "$tmp/err")"

# 3. Bad input: clear errors, non-zero exit, nothing written.
if "$lensopt" plot "$lens" --kind spots -o "$tmp/bad.svg" 2>"$tmp/err"; then
  fail "a bad --kind was accepted"
fi
grep -q "unknown plot kind 'spots'" "$tmp/err" || fail "bad --kind message: $(cat "$tmp/err")"
grep -q "layout, spot, fan, field, psf, report" "$tmp/err" || fail "bad --kind does not list the kinds"
[ -e "$tmp/bad.svg" ] && fail "a bad --kind left a file"

if "$lensopt" plot "$lens" --kind layout -o "$tmp/bad.jpg" 2>"$tmp/err"; then
  fail "a .jpg output was accepted"
fi
grep -q "use .svg or .png" "$tmp/err" || fail "bad extension message: $(cat "$tmp/err")"

if "$lensopt" plot "$tmp/missing.toml" --kind layout -o "$tmp/m.svg" 2>"$tmp/err"; then
  fail "a missing lens was accepted"
fi
grep -q "missing.toml" "$tmp/err" || fail "missing lens message does not name the file: $(cat "$tmp/err")"
ls -A "$tmp" | grep -q "\.tmp" && fail "temporary files left behind: $(ls -A "$tmp")"

if [ "$failures" -gt 0 ]; then
  echo "plot.sh: $failures failure(s)" >&2
  exit 1
fi
echo "plot.sh: all checks passed"
