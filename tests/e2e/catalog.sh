#!/usr/bin/env bash
# End-to-end test of `lensopt catalog`: the built-in Ohara catalog as JSON and as a table,
# several wavelengths, an unsupported formula (null indices, a warning), a malformed file (an
# error naming file and line), and the vendor files of ../shared when present.
# Usage: catalog.sh path/to/lensopt. Exit 0 pass, 1 fail, 77 skipped part (../shared absent).
set -u
lensopt=${1:?usage: catalog.sh path/to/lensopt}
shared=${LENSOPT_SHARED_DIR:-../shared}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failures=0

fail() {
  echo "FAIL: $*" >&2
  failures=$((failures + 1))
}

# 1. The built-in catalog as JSON: 65 glasses, every index present and near nd.
if "$lensopt" catalog ohara --json >"$tmp/ohara.json" 2>"$tmp/ohara.err"; then
  python3 -c '
import json, sys
glasses = json.load(open(sys.argv[1]))
assert isinstance(glasses, list), "not a JSON array"
assert len(glasses) == 65, "%d glasses, expected 65" % len(glasses)
for g in glasses:
    for key in ("name", "formula", "status", "nd", "vd", "n"):
        assert key in g, "%s lacks %s" % (g.get("name"), key)
    assert g["formula"] == "Sellmeier 1", g
    assert len(g["n"]) == 1 and g["n"][0] is not None, g
    assert abs(g["n"][0] - g["nd"]) < 2e-5, g
' "$tmp/ohara.json" || fail "catalog ohara --json: bad output"
else
  fail "catalog ohara --json exited with an error: $(cat "$tmp/ohara.err")"
fi

# 2. Several wavelengths; the readable table.
if "$lensopt" catalog ohara --json --wavelengths-nm 486.1327,587.5618,656.2725 >"$tmp/three.json"; then
  python3 -c '
import json, sys
glasses = json.load(open(sys.argv[1]))
for g in glasses:
    nf, nd, nc = g["n"]
    assert nf > nd > nc, g
' "$tmp/three.json" || fail "catalog --wavelengths-nm: bad output"
else
  fail "catalog --wavelengths-nm exited with an error"
fi
if "$lensopt" catalog ohara >"$tmp/table.txt"; then
  grep -q "S-BAH10" "$tmp/table.txt" || fail "table lacks S-BAH10"
  grep -qF "n(587.5618 nm)" "$tmp/table.txt" || fail "table lacks the index column header"
  [ "$(grep -c '^S-' "$tmp/table.txt")" -eq 65 ] || fail "table does not list 65 S- glasses"
else
  fail "catalog ohara (table) exited with an error"
fi

# 3. An unsupported formula: listed, null indices, a warning on stderr naming file:line.
cat >"$tmp/odd.agf" <<'EOF'
CC a glass with a formula id no vendor uses
NM GOOD 2 1 1.5168 64.17 0 1
CD 1.03961212 6.00069867E-03 2.31792344E-01 2.00179144E-02 1.01046945 1.03560653E+02
NM ODD 42 1 1.6 40 0 0
CD 1 2 3 4 5 6
EOF
if "$lensopt" catalog "$tmp/odd.agf" --json >"$tmp/odd.json" 2>"$tmp/odd.err"; then
  python3 -c '
import json, sys
glasses = json.load(open(sys.argv[1]))
assert [g["name"] for g in glasses] == ["GOOD", "ODD"], glasses
assert glasses[0]["n"][0] is not None
assert glasses[1]["n"] == [None], glasses[1]
assert glasses[1]["supported"] is False, glasses[1]
' "$tmp/odd.json" || fail "unsupported formula: bad JSON"
  grep -q "odd.agf:4" "$tmp/odd.err" || fail "no warning naming odd.agf:4: $(cat "$tmp/odd.err")"
else
  fail "catalog with an unsupported formula exited with an error"
fi

# 4. A malformed file fails with a message naming file and line.
printf 'CC broken\nNM G 2 1 1.5 60 0 0\nCD 1.0 0.006 oops 0.02 1.0 103\n' >"$tmp/broken.agf"
if "$lensopt" catalog "$tmp/broken.agf" >"$tmp/broken.out" 2>"$tmp/broken.err"; then
  fail "a malformed AGF was accepted"
else
  grep -q "broken.agf:3" "$tmp/broken.err" || fail "error does not name broken.agf:3: $(cat "$tmp/broken.err")"
fi
if "$lensopt" catalog no_such_catalog_name >/dev/null 2>"$tmp/missing.err"; then
  fail "an unknown catalog name was accepted"
else
  grep -q "catalogs" "$tmp/missing.err" || fail "missing-catalog error names no folder"
fi

# 5. Every shipped catalog searched by name part and nd / vd window; Zemax names; the glass map.
"$lensopt" catalog all --nd 1.882,1.884 --vd 40.6,40.8 >"$tmp/all.txt" 2>"$tmp/all.err" ||
  fail "catalog all --nd --vd exited with an error: $(cat "$tmp/all.err")"
grep -q "^J-LASF08A " "$tmp/all.txt" || fail "catalog all --nd --vd lacks Hikari J-LASF08A"
if grep -q "^N-BK7 " "$tmp/all.txt"; then fail "catalog all --nd --vd lists N-BK7 (nd 1.5168)"; fi
"$lensopt" catalog NIKON-HIKARI --name lasf08 | grep -q "^J-LASF08A " ||
  fail "catalog NIKON-HIKARI --name lasf08 lacks J-LASF08A"
for glass in GERMANIUM ZNSE SILICON CAF2; do
  "$lensopt" catalog INFRARED --wavelengths-nm 10000 | grep -q "^$glass " || fail "INFRARED lacks $glass"
done
"$lensopt" catalog all --vd 90,100 --plot "$tmp/map.svg" >/dev/null 2>"$tmp/map.err" ||
  fail "catalog --plot exited with an error: $(cat "$tmp/map.err")"
grep -q "<svg" "$tmp/map.svg" || fail "catalog --plot wrote no SVG"
grep -q "NICF-V" "$tmp/map.svg" || fail "the glass map of a few glasses lacks the label NICF-V"
if "$lensopt" catalog all --nd 2,1 >/dev/null 2>"$tmp/bad.err"; then
  fail "catalog --nd 2,1 (an empty window) exited 0"
fi
grep -q "LO <= HI" "$tmp/bad.err" || fail "catalog --nd 2,1: no clear message: $(cat "$tmp/bad.err")"

# 6. The vendor files (need ../shared).
skipped=0
if [ -d "$shared/data/agf" ]; then
  for file in SCHOTT_202002.AGF OHARA_20200623.AGF; do
    if "$lensopt" catalog "$shared/data/agf/$file" --json >"$tmp/vendor.json" 2>"$tmp/vendor.err"; then
      python3 -c '
import json, sys
glasses = json.load(open(sys.argv[1]))
assert len(glasses) > 100, len(glasses)
off = [g["name"] for g in glasses if g["n"][0] is None or abs(g["n"][0] - g["nd"]) > 2e-5]
assert not off, off
print("%s: %d glasses, all within 2e-5 of nd" % (sys.argv[2], len(glasses)))
' "$tmp/vendor.json" "$file" || fail "catalog $file: bad output"
    else
      fail "catalog $file exited with an error: $(cat "$tmp/vendor.err")"
    fi
  done
  "$lensopt" catalog "$shared/data/agf/SCHOTT_202002.AGF" | grep -q "N-BK7" ||
    fail "SCHOTT table lacks N-BK7"
else
  echo "skipped: $shared is absent (vendor AGF files not available)"
  skipped=1
fi

if [ "$failures" -gt 0 ]; then
  echo "$failures failure(s)" >&2
  exit 1
fi
[ "$skipped" -eq 1 ] && exit 77
echo "catalog: all checks passed"
exit 0
