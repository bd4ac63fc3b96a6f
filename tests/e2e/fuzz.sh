#!/usr/bin/env bash
# Bounded, seeded fuzz test (issue 15): mutated TOML, paper-YAML, .zmx and AGF inputs go through
# `lensopt analyze --json` (and `catalog --json` for AGF files). No input may give an internal
# error (exit 2), a crash (a signal), a NaN / null / inf in the JSON, or exit 0 after a failed
# analysis (exit 0 must come with a complete report). LENSOPT_FUZZ_CASES (default 60) and
# LENSOPT_FUZZ_SEED (default 15) set the size and the seed; tools/fuzz-sanitize.sh runs it under
# AddressSanitizer and UBSan.
set -euo pipefail
lensopt="$1"
command -v python3 > /dev/null || { echo "skipped: python3 is needed for the fuzz test"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$lensopt" convert lenses/doublet.toml "$tmp/doublet.zmx" > /dev/null
python3 - "$lensopt" "$tmp" "${LENSOPT_FUZZ_CASES:-60}" "${LENSOPT_FUZZ_SEED:-15}" <<'PY'
import json, math, os, random, subprocess, sys
lensopt, tmp, cases, seed = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
rng = random.Random(seed)
seeds = {
    "toml": open("lenses/doublet.toml", "rb").read(),
    "zmx": open(os.path.join(tmp, "doublet.zmx"), "rb").read(),
    "yml": b"stop_idx: [2]\nsequence: [GAAGA]\nhfov: [25]\nf_number: [2.]\n"
           b"c: [ 0.0598353706, 0.0436377897, 0.0, 0.0225578248, -0.0437268428 ]\n"
           b"t: [ 1.61055207, 5.60145998, 6.90204048, 2.89036393, 12.0372848 ]\n"
           b"nd: [1.6778998, 1.8918993]\nv: [55.3400764, 37.1333389]\n",
}
agf_lines = open("catalogs/ohara65.agf", "rb").read().split(b"\n")
# A small AGF: the header and the two glasses doublet.toml uses.
blocks, header, current = {}, [], None
for line in agf_lines:
    if line.startswith(b"NM "):
        current = line.split()[1]
        blocks[current] = []
    (blocks[current] if current else header).append(line)
agf_seed = b"\n".join(header + blocks[b"S-LAL12"] + blocks[b"S-LAH92"]) + b"\n"
numbers = [b"0", b"-0", b"1e308", b"-1e308", b"1e-320", b"1e-6", b"1e300", b"nan", b"inf", b"-inf",
           b"-1", b"2", b"89.5", b"1e9", b"0.5", b"1e-9", b"3", b"-5", b"65535", b"2147483648"]
junk = [b"\xe9", b"\xff\xfe", b"\x00", b"\"", b"[", b"]", b"=", b"\n", b"{", b"}", b",", b":",
        b"SURF 1\n", b"[[surfaces]]\n", b"NAME caf\xe9\n", b"- ", b"  ", b"# ", b"'", b"\\"]

def mutate(data):
    data = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        kind = rng.randrange(6)
        if not data:
            data += rng.choice(junk)
            continue
        pos = rng.randrange(len(data))
        if kind == 0:  # replace a number
            starts = [i for i in range(len(data)) if chr(data[i]).isdigit() and (i == 0 or not chr(data[i-1]).isalnum())]
            if starts:
                i = rng.choice(starts)
                j = i
                while j < len(data) and (chr(data[j]).isdigit() or data[j] in b".eE-+"):
                    j += 1
                data[i:j] = rng.choice(numbers)
        elif kind == 1:  # delete a span
            data[pos:pos + rng.randint(1, 40)] = b""
        elif kind == 2:  # insert junk
            data[pos:pos] = rng.choice(junk)
        elif kind == 3:  # duplicate a line
            lines = bytes(data).split(b"\n")
            k = rng.randrange(len(lines))
            lines.insert(k, lines[k])
            data = bytearray(b"\n".join(lines))
        elif kind == 4:  # flip a byte
            data[pos] = rng.randrange(256)
        else:  # drop a line
            lines = bytes(data).split(b"\n")
            del lines[rng.randrange(len(lines))]
            data = bytearray(b"\n".join(lines))
    return bytes(data)

def reject_constant(c):
    raise ValueError("non-finite constant " + c)

def bad_values(j, path="$"):
    if j is None:
        return [path]
    if isinstance(j, float) and not math.isfinite(j):
        return [path]
    out = []
    if isinstance(j, dict):
        for k, v in j.items():
            out += bad_values(v, path + "." + k)
    elif isinstance(j, list):
        for i, v in enumerate(j):
            out += bad_values(v, f"{path}[{i}]")
    return out

failures = []
counts = {}
def run(args, name, data, check_json):
    r = subprocess.run([lensopt] + args, capture_output=True, timeout=60)
    counts[r.returncode] = counts.get(r.returncode, 0) + 1
    err = r.stderr.decode("utf-8", "replace")
    why = None
    if r.returncode < 0:
        why = f"killed by signal {-r.returncode}"
    elif r.returncode == 2 or "internal error" in err:
        why = "internal error: " + err.strip()[-300:]
    elif r.returncode not in (0, 1, 3):
        why = f"exit {r.returncode}"
    elif r.returncode == 1 and "error" not in err:
        why = "exit 1 without an error message"
    elif r.returncode in (0, 3):
        try:
            j = json.loads(r.stdout.decode("utf-8"), parse_constant=reject_constant)
            bad = check_json(j)
            if bad:
                why = f"exit {r.returncode} with null / non-finite values at {bad[:5]}"
        except Exception as e:
            why = f"exit {r.returncode} with output that is not valid JSON: {e}"
    if why:
        keep = os.path.join(tmp, "failed-" + os.path.basename(name))
        failures.append((name, why))
        open(keep, "wb").write(data)

def lens_json_ok(j):
    # An unknown relative illumination is null with its reason in relative_illumination_notes.
    notes = j.get("relative_illumination_notes", []) if isinstance(j, dict) else []
    bad = [p for p in bad_values(j)
           if not (p.startswith("$.relative_illumination[") and
                   (k := int(p[len("$.relative_illumination["):-1])) < len(notes) and notes[k])]
    return bad

def catalog_json_ok(j):
    # Missing indices are null with a reason in n_notes.
    bad = []
    for g in j:
        for k, v in enumerate(g.get("n", [])):
            if v is None and not (g.get("n_notes") and g["n_notes"][k]):
                bad.append(g.get("name", "?"))
    return bad

kinds = ["toml", "yml", "zmx", "agf"]
for case in range(cases):
    kind = kinds[case % 4]
    if kind == "agf":
        data = mutate(agf_seed)
        agf = os.path.join(tmp, f"c{case}.agf")
        open(agf, "wb").write(data)
        run(["catalog", agf, "--json", "--wavelengths-nm", "400,587.5618,700"], agf, data, catalog_json_ok)
        lens = seeds["toml"].replace(b'catalog = "ohara"', b'catalog = "' + agf.encode() + b'"')
        path = os.path.join(tmp, f"c{case}.toml")
        open(path, "wb").write(lens)
        run(["analyze", path, "--json", "--rings", "3", "--fields", "3"], path, data, lens_json_ok)
    else:
        data = mutate(seeds[kind])
        path = os.path.join(tmp, f"c{case}.{kind}")
        open(path, "wb").write(data)
        run(["analyze", path, "--json", "--rings", "3", "--fields", "3"], path, data, lens_json_ok)

print(f"fuzz: {cases} cases (seed {seed}), exit codes {dict(sorted(counts.items()))}")
if failures:
    for name, why in failures[:20]:
        print(f"FAIL: {name}: {why}", file=sys.stderr)
    sys.exit(1)
PY
