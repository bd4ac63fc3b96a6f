#!/usr/bin/env bash
# End-to-end test of `lensopt convert` and .zmx input: tessar.toml -> .zmx -> .toml analyses to
# the same mean spot as the original; a textbook .zmx analyses directly; writing .yml is refused;
# a .zmx with an unsupported surface type (toroidal) fails with one line naming it, file and line.
# Usage: convert.sh path/to/lensopt (run from the project folder). Exit 0 pass, 1 fail.
set -u
lensopt=${1:?usage: convert.sh path/to/lensopt}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failures=0

fail() {
  echo "FAIL: $*" >&2
  failures=$((failures + 1))
}

# 1. TOML -> ZMX -> TOML; the three analyse to the same mean RMS spot.
"$lensopt" convert lenses/tessar.toml "$tmp/tessar.zmx" >/dev/null 2>"$tmp/c1.err" ||
  fail "convert tessar.toml -> .zmx: $(cat "$tmp/c1.err")"
"$lensopt" convert "$tmp/tessar.zmx" "$tmp/tessar.toml" >/dev/null 2>"$tmp/c2.err" ||
  fail "convert tessar.zmx -> .toml: $(cat "$tmp/c2.err")"
grep -q "^SURF 9" "$tmp/tessar.zmx" || fail "tessar.zmx lacks its image surface (SURF 9)"
for lens in lenses/tessar.toml "$tmp/tessar.zmx" "$tmp/tessar.toml"; do
  name=$(basename "$lens" | tr . _)
  "$lensopt" analyze --json --rings 8 --fields 5 "$lens" >"$tmp/$name.json" 2>"$tmp/$name.err" ||
    fail "analyze $lens: $(cat "$tmp/$name.err")"
done
python3 - "$tmp/tessar_toml.json" "$tmp/tessar_zmx.json" <<'EOF' || fail "mean spots differ"
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
def mean_spot(report):
    for key in ("mean_rms_spot_um", "mean_spot_um"):
        if key in report:
            return report[key]
    raise SystemExit("no mean spot in the report: %s" % sorted(report))
sa, sb = mean_spot(a), mean_spot(b)
assert sa is not None and sb is not None, (sa, sb)
assert abs(sa - sb) <= 1e-9 * max(abs(sa), 1e-12), (sa, sb)
print("mean RMS spot: toml %.9g um, zmx %.9g um" % (sa, sb))
EOF

# 2. A textbook .zmx analyses directly (the Cooke triplet, f = 50 mm).
if "$lensopt" analyze --json --no-scale --rings 8 --fields 5 lenses/zmx/cooke_triplet_50.zmx \
  >"$tmp/cooke.json" 2>"$tmp/cooke.err"; then
  python3 -c '
import json, sys
r = json.load(open(sys.argv[1]))
assert abs(r["efl_mm"] - 50.0) < 0.05, r["efl_mm"]
' "$tmp/cooke.json" || fail "cooke_triplet_50.zmx: EFL is not 50 mm"
  grep -q "flat stop surface is inserted" "$tmp/cooke.err" ||
    fail "analyze of a .zmx does not print its warnings on stderr"
else
  fail "analyze cooke_triplet_50.zmx: $(cat "$tmp/cooke.err")"
fi

# 3. Writing the paper's YAML is refused with a clear message.
if "$lensopt" convert lenses/tessar.toml "$tmp/tessar.yml" >/dev/null 2>"$tmp/yml.err"; then
  fail "convert to .yml succeeded"
else
  grep -q "YAML" "$tmp/yml.err" || fail "convert to .yml: unclear message: $(cat "$tmp/yml.err")"
fi
[ -e "$tmp/tessar.yml" ] && fail "convert to .yml left a file"

# 4. A bad .zmx (a toroidal surface on line 14) fails naming the file, line and type.
cat >"$tmp/bad.zmx" <<'EOF'
VERS 190513 80 123457 L123457
MODE SEQ
UNIT MM X W X CM MR CPMM
FNUM 4 0
WAVM 1 0.4861327 1
WAVM 2 0.6562725 1
SURF 0
  TYPE STANDARD
  CURV 0
  DISZ INFINITY
SURF 1
  STOP
SURF 2
  TYPE TOROIDAL
  CURV 0.02
  DISZ 3
SURF 3
SURF 4
EOF
for command in "convert $tmp/bad.zmx $tmp/bad.toml" "analyze $tmp/bad.zmx"; do
  # shellcheck disable=SC2086
  if "$lensopt" $command >/dev/null 2>"$tmp/bad.err"; then
    fail "lensopt $command accepted a toroidal surface"
  else
    grep -q "bad.zmx:14" "$tmp/bad.err" ||
      fail "lensopt $command: message lacks file:line: $(cat "$tmp/bad.err")"
    grep -q "TOROIDAL" "$tmp/bad.err" ||
      fail "lensopt $command: message does not name the type: $(cat "$tmp/bad.err")"
  fi
done
[ -e "$tmp/bad.toml" ] && fail "a failed convert left its output"

# `convert IN -o OUT` as the other commands take their output (issue 29: the README's
# `convert ... -o dg.toml` exited 109); the same file as `convert IN OUT`; two outputs or none
# are an error.
"$lensopt" convert lenses/zmx/double_gauss_100.zmx -o "$tmp/dg-o.toml" >/dev/null 2>&1 ||
  fail "convert IN -o OUT failed"
"$lensopt" convert lenses/zmx/double_gauss_100.zmx "$tmp/dg-pos.toml" >/dev/null 2>&1 ||
  fail "convert IN OUT failed"
cmp -s "$tmp/dg-o.toml" "$tmp/dg-pos.toml" || fail "convert -o OUT and convert OUT differ"
if "$lensopt" convert lenses/zmx/double_gauss_100.zmx "$tmp/a.toml" -o "$tmp/b.toml" \
  >/dev/null 2>"$tmp/two.err"; then
  fail "convert accepted two outputs"
fi
grep -q "two outputs" "$tmp/two.err" || fail "two outputs: $(cat "$tmp/two.err")"
if "$lensopt" convert lenses/zmx/double_gauss_100.zmx >/dev/null 2>"$tmp/none.err"; then
  fail "convert without an output exited 0"
fi
grep -q "give the output lens" "$tmp/none.err" || fail "no output: $(cat "$tmp/none.err")"

if [ "$failures" -gt 0 ]; then
  echo "convert.sh: $failures failure(s)" >&2
  exit 1
fi
echo "convert.sh: all passed"
