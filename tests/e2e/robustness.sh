#!/usr/bin/env bash
# End-to-end regression tests of issue 15 (nothing lost, nothing silently wrong): outputs over
# inputs are refused with a message; unwritable outputs are found before any work; Latin-1 text
# and non-UTF-8 paths give valid JSON; degenerate lenses exit 1 naming file:line; a wavelength
# outside a glass's range warns once per glass and is refused with --strict; `catalog` says why
# a value is missing; duplicate YAML keys are errors; tolerance reports sensitivity progress; a
# folder given for a file is named as one; an input folder with no image is a failed input;
# surfaces that cross are named.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
command -v python3 > /dev/null || { echo "skipped: python3 is needed to check JSON"; exit 77; }

# refused WHAT COMMAND...: exits 1 with "refusing" on stderr.
refused() {
  local what=$1
  shift
  local status=0
  "$lensopt" "$@" > "$tmp/stdout" 2> "$tmp/stderr" || status=$?
  [ "$status" -eq 1 ] || fail "$what: exit $status, expected 1: $(cat "$tmp/stderr")"
  grep -q "refusing" "$tmp/stderr" || fail "$what: no refusal message: $(cat "$tmp/stderr")"
}

cp lenses/doublet.toml "$tmp/L.toml"
cp "$tmp/L.toml" "$tmp/L.orig"
# 1. Outputs over inputs.
refused "tolerance --csv L" tolerance "$tmp/L.toml" --csv "$tmp/L.toml" --trials 5 --quiet
refused "tolerance --histogram L" tolerance "$tmp/L.toml" --histogram "$tmp/./L.toml" --trials 5 --quiet
refused "convert a.toml a.toml" convert "$tmp/L.toml" "$tmp/L.toml"
"$lensopt" convert "$tmp/L.toml" "$tmp/a.zmx" > /dev/null
cp "$tmp/a.zmx" "$tmp/a.orig"
refused "convert a.zmx a.zmx" convert "$tmp/a.zmx" "$tmp/../$(basename "$tmp")/a.zmx"
cmp -s "$tmp/L.toml" "$tmp/L.orig" || fail "the lens was changed"
cmp -s "$tmp/a.zmx" "$tmp/a.orig" || fail "the .zmx was changed"
mkdir -p "$tmp/img"
"$lensopt" chart -o "$tmp/img/c.png" --size 200x120 > /dev/null
cp "$tmp/img/c.png" "$tmp/c.orig"
refused "render img.png -o its folder --force" render "$tmp/L.toml" "$tmp/img/c.png" -o "$tmp/img" --force -q
refused "render DIR -o DIR" render "$tmp/L.toml" "$tmp/img" -o "$tmp/img/" -q
cmp -s "$tmp/img/c.png" "$tmp/c.orig" || fail "the input image was changed"
[ "$(ls -A "$tmp/img")" = "c.png" ] || fail "files written into the input folder: $(ls -A "$tmp/img")"

# 2. Unwritable outputs are found before the work (no progress line printed first).
status=0
"$lensopt" optimize "$tmp/L.toml" -o "$tmp/missing/o.toml" > "$tmp/stdout" 2> "$tmp/stderr" || status=$?
[ "$status" -eq 1 ] && grep -q "missing" "$tmp/stderr" || fail "optimize -o missing/: $(cat "$tmp/stderr")"
[ "$(wc -l < "$tmp/stderr")" -le 1 ] || fail "optimize worked before the check: $(cat "$tmp/stderr")"
status=0
"$lensopt" tolerance "$tmp/L.toml" --csv "$tmp/missing/t.csv" --trials 50 > "$tmp/stdout" 2> "$tmp/stderr" || status=$?
[ "$status" -eq 1 ] && grep -q "t.csv" "$tmp/stderr" || fail "tolerance --csv missing/: $(cat "$tmp/stderr")"
! grep -q "trials" "$tmp/stderr" || fail "tolerance worked before the check: $(cat "$tmp/stderr")"

# 3. Text: a Latin-1 NAME in a .zmx, a Latin-1 glass name in an AGF, a non-UTF-8 path.
sed 's/^NAME .*/NAME Objectif d\xe9mo/' "$tmp/a.zmx" > "$tmp/latin1.zmx"
"$lensopt" analyze "$tmp/latin1.zmx" --json --rings 3 --fields 3 > "$tmp/out.json" 2> "$tmp/stderr" ||
  fail "analyze latin1.zmx --json: $(cat "$tmp/stderr")"
python3 -c 'import json,sys; j=json.load(open(sys.argv[1], encoding="utf-8")); assert j["lens"] == "Objectif d\u00e9mo", j["lens"]' "$tmp/out.json" ||
  fail "the Latin-1 name is not transcoded"
sed 's/^NM S-LAL12 /NM S-LAL12\xf6 /' catalogs/ohara65.agf > "$tmp/latin1.agf"
"$lensopt" catalog "$tmp/latin1.agf" --json > "$tmp/out.json" 2> "$tmp/stderr" || fail "catalog latin1.agf --json: $(cat "$tmp/stderr")"
python3 -c 'import json,sys; j=json.load(open(sys.argv[1], encoding="utf-8")); assert any(g["name"] == "S-LAL12\u00f6" for g in j)' "$tmp/out.json" ||
  fail "the Latin-1 glass name is not transcoded"
sed "s|catalog = \"ohara\"|catalog = \"$tmp/latin1.agf\"|; s/\"S-LAL12\"/\"S-LAL12\xf6\"/" "$tmp/L.toml" > "$tmp/latin1-glass.toml"
status=0
"$lensopt" analyze "$tmp/latin1-glass.toml" --json --rings 3 --fields 3 > "$tmp/out.json" 2> "$tmp/stderr" || status=$?
[ "$status" -ne 2 ] || fail "internal error on a Latin-1 glass: $(cat "$tmp/stderr")"
bad_path="$tmp/caf$(printf '\xe9').toml"
cp "$tmp/L.toml" "$bad_path"
"$lensopt" analyze "$bad_path" --json --rings 3 --fields 3 > "$tmp/out.json" 2> "$tmp/stderr" ||
  fail "analyze of a non-UTF-8 path: $(cat "$tmp/stderr")"
python3 -c 'import json,sys; json.load(open(sys.argv[1], encoding="utf-8"))' "$tmp/out.json" || fail "invalid JSON for a non-UTF-8 path"

# 4. Degenerate lenses: exit 1 with file:line, never exit 0 with nulls.
degenerate() {
  local what=$1 sedexpr=$2
  sed "$sedexpr" "$tmp/L.toml" > "$tmp/bad.toml"
  local status=0
  "$lensopt" analyze "$tmp/bad.toml" --json > "$tmp/stdout" 2> "$tmp/stderr" || status=$?
  [ "$status" -eq 1 ] || fail "$what: exit $status, expected 1: $(cat "$tmp/stderr")"
  grep -q "bad.toml:[0-9]" "$tmp/stderr" || fail "$what: no file:line: $(cat "$tmp/stderr")"
}
degenerate "half_field_deg = 0" 's/^half_field_deg = .*/half_field_deg = 0.0/'
degenerate "f_number = 1e-320" 's/^f_number = .*/f_number = 1e-320/'
degenerate "sensor_diagonal_mm = 1e-320" 's/^sensor_diagonal_mm = .*/sensor_diagonal_mm = 1e-320/'
degenerate "sensor_diagonal_mm = 1e-9" 's/^sensor_diagonal_mm = .*/sensor_diagonal_mm = 1e-9/'
degenerate "last thickness 1e308" 's/^thickness_mm = 12.037284851074219/thickness_mm = 1e308/'
degenerate "radius 1e-6" '0,/^radius_mm = .*/s//radius_mm = 1e-6/'
degenerate "nd 1e300" 's/^material = "S-LAL12"/material = { nd = 1e300, vd = 50.0 }/'
degenerate "vd 1e-320" 's/^material = "S-LAL12"/material = { nd = 1.6, vd = 1e-320 }/'
sed '/^XFLN/d; /^YFLN/d' "$tmp/a.zmx" > "$tmp/nofield.zmx"
status=0
"$lensopt" analyze "$tmp/nofield.zmx" --json > "$tmp/stdout" 2> "$tmp/stderr" || status=$?
[ "$status" -eq 1 ] && grep -q "field of view" "$tmp/stderr" || fail "a .zmx without fields: exit $status: $(cat "$tmp/stderr")"

# 5. Glass ranges: 250 nm warns once per glass, --strict refuses; catalog says why.
python3 - "$tmp/L.toml" "$tmp/uv.toml" <<'PY'
import sys
t = open(sys.argv[1]).read().replace('dispersion = "abbe"', 'dispersion = "abbe"\nwavelengths_nm = [250.0, 587.6, 656.3]\nchannels = ["B", "G", "R"]')
open(sys.argv[2], "w").write(t)
PY
"$lensopt" analyze "$tmp/uv.toml" --rings 3 --fields 3 > /dev/null 2> "$tmp/stderr" || fail "analyze uv: $(cat "$tmp/stderr")"
[ "$(grep -c "outside its formula's range" "$tmp/stderr")" -eq 2 ] || fail "not one warning per glass: $(cat "$tmp/stderr")"
status=0
"$lensopt" analyze "$tmp/uv.toml" --strict > /dev/null 2> "$tmp/stderr" || status=$?
[ "$status" -eq 1 ] && grep -q "strict" "$tmp/stderr" || fail "--strict did not refuse: $status $(cat "$tmp/stderr")"
"$lensopt" catalog ohara --wavelengths-nm 250,587.5618 --json > "$tmp/cat.json" 2> "$tmp/stderr"
grep -q "outside the formula's range" "$tmp/stderr" || fail "catalog: no warning at 250 nm"
python3 - "$tmp/cat.json" <<'PY' || fail "catalog: a missing value without a reason"
import json, sys
for g in json.load(open(sys.argv[1])):
    for k, v in enumerate(g["n"]):
        if v is None:
            assert g["n_notes"][k], g
PY

# 6. Duplicate YAML keys.
printf 'stop_idx: [2]\nsequence: [GAAGA]\nhfov: [25]\nf_number: [2.]\nc: [ 0.0598, 0.0436, 0.0, 0.0226, -0.0437 ]\nt: [ 1.61, 5.60, 6.90, 2.89, 12.04 ]\nnd: [1.678, 1.892]\nv: [55.34, 37.13]\nf_number: [4.]\n' > "$tmp/dup.yml"
status=0
"$lensopt" analyze "$tmp/dup.yml" > /dev/null 2> "$tmp/stderr" || status=$?
[ "$status" -eq 1 ] && grep -q "dup.yml:9.*duplicate key 'f_number'.*line 4" "$tmp/stderr" ||
  fail "duplicate YAML key: $status $(cat "$tmp/stderr")"

# 7. Tolerance: sensitivity progress without --quiet.
"$lensopt" tolerance "$tmp/L.toml" --trials 4 --rings 3 --fields 3 > /dev/null 2> "$tmp/stderr"
grep -q "sensitivity [0-9]*/[0-9]* evaluations" "$tmp/stderr" || fail "no sensitivity progress: $(cat "$tmp/stderr")"
# 8. A folder where a file belongs is named as one (it used to read as empty text: "no
# [[surfaces]]", "0 SURF blocks", "catalog not found"); a folder with no image to render is a
# failed input, not an empty run with exit 0.
mkdir -p "$tmp/dir.toml" "$tmp/dir.zmx" "$tmp/dir.yml" "$tmp/dir.agf" "$tmp/empty"
for d in dir.toml dir.zmx dir.yml; do
  status=0
  "$lensopt" analyze "$tmp/$d" > /dev/null 2> "$tmp/stderr" || status=$?
  [ "$status" -eq 1 ] && grep -q "$d: .*is a directory" "$tmp/stderr" ||
    fail "analyze of a folder $d: exit $status: $(cat "$tmp/stderr")"
done
status=0
"$lensopt" catalog "$tmp/dir.agf" > /dev/null 2> "$tmp/stderr" || status=$?
[ "$status" -eq 1 ] && grep -q "dir.agf: .*is a directory" "$tmp/stderr" ||
  fail "catalog of a folder: exit $status: $(cat "$tmp/stderr")"
status=0
"$lensopt" render "$tmp/L.toml" "$tmp/empty" -o "$tmp/r-empty" -q > /dev/null 2> "$tmp/stderr" || status=$?
[ "$status" -eq 1 ] && grep -q "empty: no image to render" "$tmp/stderr" ||
  fail "render of an empty folder: exit $status: $(cat "$tmp/stderr")"

# 9. Elements through each other (the second element's front 2.4 mm before the first's rear)
# are named with a warning; analyze used to report only failed rays on a later surface.
sed 's/^thickness_mm = 6.902040481567383/thickness_mm = -8.0/' "$tmp/L.toml" > "$tmp/cross.toml"
"$lensopt" analyze "$tmp/cross.toml" --rings 3 --fields 3 > /dev/null 2> "$tmp/stderr" || true
grep -q "cross.toml: surfaces 2 and 4 cross" "$tmp/stderr" || fail "no crossing warning: $(cat "$tmp/stderr")"
"$lensopt" analyze "$tmp/L.toml" --rings 3 --fields 3 > /dev/null 2> "$tmp/stderr"
! grep -q "cross" "$tmp/stderr" || fail "a crossing warning for the doublet: $(cat "$tmp/stderr")"

echo "ok"
