#!/usr/bin/env bash
# End-to-end test of `lensopt render --shard I/N` and `lensopt render merge` (issue 18): a dataset
# of 24 small images (each different) rendered by one run is the reference. (1) Three shards in
# one shared output folder, run at the same time, one of them SIGKILLed once it has written two of
# its images and then run again; `render merge OUT` joins them. (2) Three shards in three folders,
# joined by `render merge D1 D2 D3 -o M` (images copied). Both must give the reference's images
# byte for byte and its metrics (CSV and JSON) but the seconds; a plain run over the shards'
# folder then renders nothing. A merge with a shard missing, given twice, or killed and not
# resumed is refused naming it; a bad --shard is refused.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
command -v python3 > /dev/null || { echo "skipped: python3 is needed to compare metrics"; exit 77; }
python3 "$(dirname "$0")/make_images.py" "$tmp/in" 24 128 96
render=("$lensopt" render lenses/doublet.toml "$tmp/in" --jobs 1 -q)

# Same images and metrics as the reference (every column but seconds).
same_as_reference() {
  (cd "$tmp/in" && find . -name '*.png') | while read -r f; do
    cmp -s "$tmp/ref/$f" "$1/$f" || fail "$1/$f differs from the one-run image"
  done
  python3 - "$tmp/ref" "$1" <<'PY' || fail "metrics of $1 differ from the one run's"
import csv, json, sys
def rows(d):
    with open(d + "/render_metrics.csv", newline="") as f:
        r = list(csv.DictReader(f))
    for row in r:
        del row["seconds"]
    return r
def doc(d):
    j = json.load(open(d + "/render_metrics.json"), parse_constant=lambda x: 1 / 0)
    for img in j["images"]:
        assert img["seconds"] > 0, img
        del img["seconds"]
    return j
a, b = sys.argv[1], sys.argv[2]
assert rows(a) == rows(b), (rows(a), rows(b))
assert doc(a) == doc(b), (doc(a), doc(b))
assert len(rows(a)) == 25 and all(r["status"] == "rendered" for r in rows(a)[:-1])
PY
}

"${render[@]}" -o "$tmp/ref" > /dev/null || fail "reference run"

# A bad shard is refused before any work.
for bad in 4/3 0/3 3 a/b 1/0; do
  if "${render[@]}" -o "$tmp/bad" --shard "$bad" 2> "$tmp/err"; then fail "--shard $bad accepted"; fi
  grep -q -- "--shard" "$tmp/err" || fail "--shard $bad: $(cat "$tmp/err")"
done
[ ! -e "$tmp/bad" ] || fail "a refused shard created its folder"

# (1) Three shards at once in one folder; shard 2 is SIGKILLed once two of its images are there
# (polled, not timed).
python3 - "$tmp" "${render[@]}" <<'PY' || fail "shards at once"
import os, signal, subprocess, sys, time
tmp, render = sys.argv[1], sys.argv[2:]
src, out = tmp + "/in", tmp + "/shared"
names = sorted(os.path.relpath(os.path.join(d, f), src) for d, _, fs in os.walk(src) for f in fs)
mine = [n for k, n in enumerate(names) if k % 3 == 1]  # shard 2/3
procs = {i: subprocess.Popen(render + ["-o", out, "--shard", f"{i}/3"], stdout=subprocess.DEVNULL)
         for i in (2, 1, 3)}
while sum(os.path.exists(os.path.join(out, n)) for n in mine) < 2:
    assert procs[2].poll() is None, "shard 2/3 ended before it could be killed"
    time.sleep(0.001)
procs[2].send_signal(signal.SIGKILL)
assert procs[2].wait() == -signal.SIGKILL
assert procs[1].wait() == 0 and procs[3].wait() == 0, "shards 1/3 and 3/3"
done = sum(os.path.exists(os.path.join(out, n)) for n in mine)
assert 2 <= done < len(mine), f"shard 2/3 had {done} of {len(mine)} images when killed"
PY
# The killed shard is not merged.
if "$lensopt" render merge "$tmp/shared" > /dev/null 2> "$tmp/err"; then fail "merged a killed shard"; fi
grep -qE "shard 2/3|run it again" "$tmp/err" || fail "merge of a killed shard: $(cat "$tmp/err")"
"${render[@]}" -o "$tmp/shared" --shard 2/3 > "$tmp/resume.txt" || fail "resumed shard 2/3"
grep -q "shard 2/3: 8 of the dataset's 24 images" "$tmp/resume.txt" || fail "shard summary: $(cat "$tmp/resume.txt")"
# It renders again only what it has no completion record of (at least the one it was killed on).
sed -n 's/^rendered \([0-9]*\), skipped \([0-9]*\) .*/\1 \2/p' "$tmp/resume.txt" |
  awk '{exit !($1 >= 1 && $2 >= 1 && $1 + $2 == 8)}' || fail "resume: $(cat "$tmp/resume.txt")"
"$lensopt" render merge "$tmp/shared" > "$tmp/merge.txt" || fail "merge: $(cat "$tmp/merge.txt")"
grep -q "merged 24 images: rendered 24, failed 0" "$tmp/merge.txt" || fail "merge: $(cat "$tmp/merge.txt")"
same_as_reference "$tmp/shared"
[ -z "$(find "$tmp/shared" -name '.*')" ] || fail "temporary files left: $(find "$tmp/shared" -name '.*')"
for i in 1 2 3; do
  [ -f "$tmp/shared/render_metrics-shard${i}of3.json" ] || fail "shard $i metrics"
done
# A plain run over the folder the shards filled trusts their records: nothing to render.
"${render[@]}" -o "$tmp/shared" > "$tmp/plain.txt" || fail "plain run after the shards"
grep -q "rendered 0, skipped 24 " "$tmp/plain.txt" || fail "plain run: $(cat "$tmp/plain.txt")"

# (2) Three shards in three folders, merged into a fourth.
for i in 1 2 3; do "${render[@]}" -o "$tmp/s$i" --shard "$i/3" > /dev/null || fail "shard $i/3"; done
if "$lensopt" render merge "$tmp/s1" "$tmp/s3" -o "$tmp/m" 2> "$tmp/err"; then fail "merged without shard 2"; fi
grep -q "shard(s) 2 of 3 not found" "$tmp/err" || fail "missing shard: $(cat "$tmp/err")"
if "$lensopt" render merge "$tmp/s1" "$tmp/s1" "$tmp/s2" "$tmp/s3" -o "$tmp/m" 2> "$tmp/err"; then
  fail "merged a shard given twice"
fi
grep -q "given twice" "$tmp/err" || fail "shard twice: $(cat "$tmp/err")"
[ -z "$(find "$tmp/m" -name '*.png' 2> /dev/null)" ] || fail "a refused merge copied images"
"$lensopt" render merge "$tmp/s1" "$tmp/s2" "$tmp/s3" -o "$tmp/m" > /dev/null || fail "merge of three folders"
same_as_reference "$tmp/m"
echo "render shard: ok"
