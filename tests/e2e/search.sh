#!/usr/bin/env bash
# End-to-end tests of `lensopt search`: a tiny search (the doublet with its stop in front, between
# and behind, two glass seeds, coarse sampling) run once; killed with SIGKILL after its first
# result and resumed; run as three shards and merged. The leaderboards (CSV and JSON) of all three
# must be identical except the `seconds` column, the one wall-clock field. Also: a bad candidate
# (the rear stop, which the optimizer's variables reject) is reported and skipped; the best lenses
# read back; a description with an unknown key names file:line.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
pid=""
trap '[ -n "$pid" ] && kill -9 "$pid" 2>/dev/null; rm -rf "$tmp"' EXIT

# Waits (at most 60 s a line) for the first "[1/N] ..." line of a run's stderr, read from the
# FIFO $1: a search prints it once its first candidate's result file is written. The rest of the
# output is then copied to $2 (default /dev/null) in the background, so the run never blocks on a
# full pipe; finish_reading waits for that copy after the run has ended.
wait_for_first_result() {
  exec 3< "$1"
  local line="" out="${2:-/dev/null}"
  : > "$out"
  while true; do
    IFS= read -r -t 60 -u 3 line || fail "the search finished no candidate in 60 s"
    printf '%s\n' "$line" >> "$out"
    [[ "$line" =~ ^\[[0-9]+/[0-9]+\] ]] && break  # "[1/6] <id>: ...": a result is written
  done
  cat <&3 >> "$out" &
  drain=$!
}
finish_reading() {
  wait "$drain" 2>/dev/null || true
  exec 3<&-
}
fail() { echo "FAIL: $*" >&2; exit 1; }
command -v python3 > /dev/null || { echo "skipped: python3 is needed to compare leaderboards"; exit 77; }

search=(lenses/doublet.toml --vary-stop --glass-seeds 2 --rings 3 --fields 3 --max-iterations 3
        --max-rounds 1 --top 2 -q)
# The same search with a line per finished candidate on stderr (no -q), for the runs that are
# stopped once their first result is written.
noisy=()
for arg in "${search[@]}"; do [ "$arg" = -q ] || noisy+=("$arg"); done

# Compares two result folders' leaderboards, every column but seconds.
same_leaderboard() {
  python3 - "$1" "$2" <<'PY' || fail "leaderboards differ: $1 vs $2"
import csv, json, sys
def rows(d):
    with open(d + "/leaderboard.csv", newline="") as f:
        r = [row for row in csv.DictReader(f)]
    for row in r:
        del row["seconds"]
    return r
def board(d):
    j = json.load(open(d + "/leaderboard.json"))
    for row in j["leaderboard"]:
        del row["seconds"]
    return j
a, b = sys.argv[1], sys.argv[2]
assert rows(a) == rows(b), (rows(a), rows(b))
assert board(a) == board(b)
PY
}

# 1. One run, two candidates at a time.
"$lensopt" search "${search[@]}" -o "$tmp/one" --jobs 2 > "$tmp/one.txt" || fail "search run"
python3 - "$tmp/one" <<'PY' || fail "leaderboard content"
import csv, json, sys
d = sys.argv[1]
rows = list(csv.DictReader(open(d + "/leaderboard.csv", newline="")))
assert len(rows) == 6, len(rows)
assert [int(r["rank"]) for r in rows] == list(range(1, 7))
errors = [r for r in rows if r["status"] == "error"]
assert len(errors) == 2 and all(":E-E-S:" in r["id"] for r in errors), errors  # rear stop
assert rows[-1]["status"] == "error" and rows[0]["status"] == "ok"
ok = [r for r in rows if r["status"] == "ok"]
met = [r["constraints_met"] == "yes" for r in ok]
assert met == sorted(met, reverse=True), "feasible designs must rank first"
for r in ok:
    assert float(r["final_spot_um"]) > 0 and r["glasses"], r
j = json.load(open(d + "/leaderboard.json"))
assert j["complete"] and j["candidates"] == 6 and len(j["leaderboard"]) == 6
PY
ls "$tmp/one/best/"rank01_*.toml > /dev/null || fail "no best lens written"
for f in "$tmp/one/best/"*.toml; do
  "$lensopt" analyze "$f" --json --rings 4 --fields 3 > "$tmp/best_toml.json" ||
    fail "best lens $f does not read back"
  # Its Zemax twin (issue 31): the same lens.
  [ -f "${f%.toml}.zmx" ] || fail "best lens $f has no .zmx"
  "$lensopt" analyze "${f%.toml}.zmx" --json --rings 4 --fields 3 > "$tmp/best_zmx.json" ||
    fail "best lens ${f%.toml}.zmx does not read back"
  python3 -c 'import json, sys; a, b = (json.load(open(p)) for p in sys.argv[1:]); assert a["mean_rms_spot_um"] == b["mean_rms_spot_um"], (a["mean_rms_spot_um"], b["mean_rms_spot_um"])' \
    "$tmp/best_toml.json" "$tmp/best_zmx.json" || fail "best lens $f: .zmx and .toml differ"
done
find "$tmp/one" -name '*.tmp*' | grep -q . && fail "a temporary file was left behind"

# 2. Killed after its first finished candidate (SIGKILL: no chance to clean up), then resumed.
# The run's stderr comes through a FIFO: its first "[1/6] ..." line says a result is written.
mkfifo "$tmp/killed.fifo"
"$lensopt" search "${noisy[@]}" -o "$tmp/killed" --jobs 1 > /dev/null 2> "$tmp/killed.fifo" &
pid=$!
wait_for_first_result "$tmp/killed.fifo"
kill -9 "$pid" 2>/dev/null || true
wait "$pid" 2>/dev/null || true
pid=""
finish_reading
before=$(find "$tmp/killed/results" -name '*.json' | wc -l)
[ "$before" -ge 1 ] || fail "no result file before the kill"
[ "$before" -lt 6 ] || echo "note: the search finished before it could be killed"
"$lensopt" search "${search[@]}" -o "$tmp/killed" --jobs 1 > "$tmp/resumed.txt" || fail "resume"
grep -q "$before finished before this run, $((6 - before)) now" "$tmp/resumed.txt" \
  || fail "resume should redo only the unfinished: $(cat "$tmp/resumed.txt")"
same_leaderboard "$tmp/one" "$tmp/killed"

# 3. Three shards and a merge.
for i in 1 2 3; do
  "$lensopt" search "${search[@]}" -o "$tmp/shard$i" --shard "$i/3" --jobs 1 > /dev/null || fail "shard $i"
done
"$lensopt" search merge "$tmp/shard1" "$tmp/shard2" "$tmp/shard3" -o "$tmp/merged" > /dev/null || fail "merge"
same_leaderboard "$tmp/one" "$tmp/merged"
cmp -s "$tmp/one/search.json" "$tmp/merged/search.json" || fail "search.json differs after merge"

# 4. SIGINT stops the search: exit 130, the finished candidates kept, a partial leaderboard.
mkfifo "$tmp/int.fifo"
"$lensopt" search "${noisy[@]}" -o "$tmp/int" --jobs 1 > /dev/null 2> "$tmp/int.fifo" &
pid=$!
wait_for_first_result "$tmp/int.fifo" "$tmp/int.txt"
kill -INT "$pid" 2>/dev/null || true
rc=0
wait "$pid" || rc=$?
pid=""
finish_reading
if [ "$rc" -eq 130 ]; then
  grep -q "run the same command again to resume" "$tmp/int.txt" || fail "SIGINT message: $(cat "$tmp/int.txt")"
  [ -f "$tmp/int/leaderboard.csv" ] || fail "no partial leaderboard after SIGINT"
else
  [ "$rc" -eq 0 ] || fail "SIGINT: exit code $rc"
  echo "note: the search finished before SIGINT arrived"
fi

# 5. A folder of another search is refused; so is an unknown key in a description.
if "$lensopt" search "${search[@]}" --constraints paper -o "$tmp/one" > /dev/null 2> "$tmp/err.txt"; then
  fail "resumed into another search's folder"
fi
grep -q "another search" "$tmp/err.txt" || fail "message: $(cat "$tmp/err.txt")"
printf '[search]\nlenses = ["%s/lenses/doublet.toml"]\nglas_seeds = 2\n' "$PWD" > "$tmp/desc.toml"
if "$lensopt" search "$tmp/desc.toml" -o "$tmp/desc" > /dev/null 2> "$tmp/err.txt"; then
  fail "unknown key accepted"
fi
grep -q "desc.toml:3:.*glas_seeds" "$tmp/err.txt" || fail "unknown key message: $(cat "$tmp/err.txt")"
# 6. A lens that is not the paper's (a 100 mm double Gauss with 14 mm glasses) is searched with
# the bounds `optimize` gives it (its own), not the paper's glass 1..3 mm, which drove a glass to
# a negative thickness: the candidate failed. A search in which every candidate fails exits 1
# naming the input.
"$lensopt" search lenses/zmx/double_gauss_100.zmx --rings 3 --fields 3 --max-iterations 3 \
  --max-rounds 1 -q -o "$tmp/dg" > "$tmp/dg.txt" 2> "$tmp/err.txt" || fail "double Gauss search: $(cat "$tmp/err.txt")"
grep -q "0 failed" "$tmp/dg.txt" || fail "double Gauss candidate failed: $(cat "$tmp/dg.txt")"
python3 - "$tmp/dg/leaderboard.json" <<'PY' || fail "double Gauss leaderboard"
import json, sys
(row,) = json.load(open(sys.argv[1]))["leaderboard"]
assert row["status"] == "ok" and row["final_mean_rms_spot_um"] > 0, row
PY
rc=0
"$lensopt" search tests/data/zmx-real/thorlabs_AC254-100-A.zmx -q -o "$tmp/onaxis" > /dev/null 2> "$tmp/err.txt" || rc=$?
[ "$rc" -eq 1 ] || fail "a search whose every candidate failed: exit $rc"
grep -q "thorlabs_AC254-100-A.zmx: every candidate failed (1 of 1)" "$tmp/err.txt" ||
  fail "every-candidate-failed message: $(cat "$tmp/err.txt")"
echo "search e2e: ok"
