#!/usr/bin/env bash
# End-to-end: optimize and tolerance trace a lens with its own system data at its own
# wavelengths, fields and weights (the lenses/zmx files: F, d, C and three written fields), and
# the paper's lenses at the paper's sampling (fields 0..hfov). The wavelengths and fields are
# read from the .zmx text here, independently of lensopt's reader.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

quick=(--rings 3 --fields 3 --max-iterations 1 --glass-search none --threads 2)
for zmx in lenses/zmx/*.zmx; do
  name=$(basename "$zmx" .zmx)
  # Unequal field weights, so the weights shown are the file's and not a default.
  sed -e 's/^FWGN .*/FWGN 1 2 0.5/' "$zmx" > "$tmp/$name.zmx"
  grep -q '^FWGN 1 2 0.5' "$tmp/$name.zmx" || sed -i '/^YFLN/a FWGN 1 2 0.5' "$tmp/$name.zmx"
  "$lensopt" optimize "$tmp/$name.zmx" -o "$tmp/$name.toml" "${quick[@]}" --json > "$tmp/$name.json" \
    2> "$tmp/$name.err" || fail "optimize $zmx: $(tail -3 "$tmp/$name.err")"
  line=$(grep "design sampling" "$tmp/$name.err") || fail "optimize $zmx printed no sampling"
  python3 - "$tmp/$name.zmx" "$line" <<'PY' || fail "optimize $zmx sampling: $line"
import re, sys
text = open(sys.argv[1]).read().splitlines()
line = sys.argv[2]
waves = [float(l.split()[2]) * 1000 for l in text if l.startswith("WAVM")]
fields = [float(v) for v in next(l for l in text if l.startswith("YFLN")).split()[1:]]
weights = [float(v) for v in next(l for l in text if l.startswith("FWGN")).split()[1:]]
n = int(next(l for l in text if l.startswith("FTYP")).split()[3])
fields, weights = fields[:n], weights[:n]
m = re.search(r"design sampling \(as written\): wavelengths (.*) nm \(weights (.*)\); "
              r"spot fields (.*) deg \(weights (.*)\) among (\d+) traced", line)
assert m, line
nums = lambda s: [float(v) for v in s.split(", ")]
got_waves = nums(m.group(1))
assert len(got_waves) == len(waves) and all(abs(a - b) < 1e-3 for a, b in zip(got_waves, waves)), (got_waves, waves)
order = sorted(range(n), key=lambda i: abs(fields[i]))
assert nums(m.group(3)) == [abs(fields[i]) for i in order], (m.group(3), fields)
assert nums(m.group(4)) == [weights[i] for i in order], (m.group(4), weights)
assert int(m.group(5)) >= 21
PY
  # The report's spots are the weighted ones at the file's fields, as analyze reports them.
  "$lensopt" analyze "$tmp/$name.zmx" --json > "$tmp/$name.analyze.json" ||
    fail "analyze $zmx"
  python3 - "$tmp/$name.json" "$tmp/$name.analyze.json" <<'PY' || fail "optimize $zmx start spot"
import json, sys
o = json.load(open(sys.argv[1]))
a = json.load(open(sys.argv[2]))
assert abs(o["start_mean_rms_spot_um"] - a["mean_rms_spot_um"]) <= 1e-9 * a["mean_rms_spot_um"], (o["start_mean_rms_spot_um"], a["mean_rms_spot_um"])
PY
  # tolerance: the file's fields (chief-ray angles, deg), not 0..hfov.
  "$lensopt" tolerance "$tmp/$name.zmx" --trials 4 --rings 3 --no-sensitivity --quiet --json \
    > "$tmp/$name.tol.json" 2> "$tmp/$name.tol.err" || fail "tolerance $zmx: $(cat "$tmp/$name.tol.err")"
  python3 - "$tmp/$name.zmx" "$tmp/$name.tol.json" <<'PY' || fail "tolerance $zmx fields"
import json, sys
text = open(sys.argv[1]).read().splitlines()
n = int(next(l for l in text if l.startswith("FTYP")).split()[3])
fields = sorted(abs(float(v)) for v in next(l for l in text if l.startswith("YFLN")).split()[1:n + 1])
t = json.load(open(sys.argv[2]))
assert t["fields_deg"] == fields, (t["fields_deg"], fields)
PY
  echo "ok: $zmx: optimize and tolerance at the file's wavelengths, fields and weights"
done

# The paper's lens: the paper's sampling, fields 0..hfov.
"$lensopt" optimize lenses/cooke.toml -o "$tmp/cooke.toml" "${quick[@]}" > /dev/null \
  2> "$tmp/cooke.err" || fail "optimize cooke"
grep -q "design sampling (paper):.*spot fields 0, 12.5, 25 deg" "$tmp/cooke.err" ||
  fail "the paper's lens: $(grep "design sampling" "$tmp/cooke.err")"
echo "PASS"
