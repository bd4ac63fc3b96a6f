#!/usr/bin/env bash
# The documentation's commands run (issue 29: the README's `convert ... -o dg.toml` exited 109
# and nothing noticed). Every ```sh block of README.md and docs/*.md is extracted and run, block
# by block, in one bash per block (so `export` carries to the next line), in a temporary folder
# that holds the repository's files (symlinks), `build` (the folder of the lensopt under test),
# `lensopt` on PATH and an empty `out/`. A line that exits non-zero fails the test, naming
# FILE:LINE. Lines continued with a trailing backslash are one command.
#
# docs/search.md is not run: each of its searches optimizes tens of candidates (minutes; the
# optimizer and search have their own e2e tests). Not run either, and listed at the end:
#   - lines whose comment says `# slow` (a full joint optimization, ...): keep them few;
#   - lines that need ../shared when it is absent;
#   - the set-up commands tools/run-main.sh and tools/test.sh (they install packages and build:
#     the test runs inside them) and `cmake --install` (writes outside the checkout).
# Reduced so the whole test stays under a minute, and listed: `--trials N` above 200 runs with
# `--trials 200`; `--glass-seeds N` above 2 with `--glass-seeds 2`; `optimize --joint` with a
# few steps on small crops and scenes at coarse sampling (the `tiny` options below, replacing
# the line's own values); `chart --count N` above 8 with `--count 8`.
set -euo pipefail
lensopt="$(realpath "$1")"
root="$(pwd)"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
[ -f "$root/README.md" ] || fail "run from the repository root (README.md not found)"

work="$tmp/work"
mkdir -p "$work/out" "$tmp/bin"
for entry in "$root"/*; do
  name=$(basename "$entry")
  case "$name" in build | build-* | out) continue ;; esac
  ln -s "$entry" "$work/$name"
done
ln -s "$(dirname "$lensopt")" "$work/build"
ln -s "$lensopt" "$tmp/bin/lensopt"
if [ -d "$root/../shared" ]; then ln -s "$(realpath "$root/../shared")" "$tmp/shared"; fi

python3 - "$root" "$tmp" <<'PY'
import glob, os, re, sys
root, tmp = sys.argv[1], sys.argv[2]
have_shared = os.path.isdir(os.path.join(tmp, "shared"))
setup = [(re.compile(r"^tools/(run-main|test)\.sh\b"), "set-up: installs packages and builds"),
         (re.compile(r"^cmake --install\b"), "installs outside the checkout")]
reductions = [(re.compile(r"--trials (\d+)"), 200, "--trials {}"),
              (re.compile(r"--glass-seeds (\d+)"), 2, "--glass-seeds {}"),
              (re.compile(r"--count (\d+)"), 8, "--count {}")]
tiny = {"--steps": "2", "--perfect-steps": "2", "--decay-steps": "1", "--crop": "64",
        "--batch": "1", "--eval-crops": "1", "--psf-rings": "3", "--psf-fields": "3",
        "--design-rings": "3", "--design-fields": "3", "--scenes": "2",
        "--scene-width": "160", "--scene-height": "96", "--checkpoint-every": "1"}


def tiny_joint(command):
    """`optimize --joint` with the tiny options (the line's own values replaced)."""
    head, sep, comment = command.partition(" #")
    for option, value in tiny.items():
        if option == "--scenes" and "--data" in head:
            continue
        if option == "--perfect-steps" and "--data" not in head:
            continue
        pattern = re.compile(re.escape(option) + r"(?:=|\s+)\S+")
        if pattern.search(head):
            head = pattern.sub(f"{option} {value}", head)
        elif option != "--checkpoint-every":
            head += f" {option} {value}"
    return head + sep + comment
not_cheap = {"docs/search.md": "searches of tens of candidates (minutes)"}
files = ["README.md"] + sorted(os.path.relpath(p, root)
                               for p in glob.glob(os.path.join(root, "docs", "*.md"))
                               if os.path.relpath(p, root) not in not_cheap)
blocks, skipped, reduced = [], [], []
for name in files:
    lines = open(os.path.join(root, name), encoding="utf-8").read().split("\n")
    fence, block = None, []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            if fence is None:
                fence, block = line[3:].strip(), []
            else:
                if fence == "sh" and block:
                    blocks.append(block)
                fence = None
            i += 1
            continue
        if fence == "sh":
            start = i + 1
            command = line
            while command.endswith("\\") and i + 1 < len(lines):
                i += 1
                command = command[:-1] + " " + lines[i].strip()
            command = command.strip()
            where = f"{name}:{start}"
            comment = command.split(" #", 1)[1] if " #" in command else ""
            if command and not command.startswith("#"):
                reason = None
                if re.search(r"\bslow\b", comment):
                    reason = "marked # slow"
                elif "../shared" in command and not have_shared:
                    reason = "needs ../shared (absent)"
                for pattern, why in setup:
                    if pattern.search(command):
                        reason = why
                if reason:
                    skipped.append(f"{where}: {command}  [{reason}]")
                else:
                    if re.search(r"\boptimize\b.*--joint\b", command):
                        command = tiny_joint(command)
                        reduced.append(f"{where}: optimize --joint with the tiny options")
                    for pattern, limit, form in reductions:
                        m = pattern.search(command)
                        if m and int(m.group(1)) > limit:
                            command = pattern.sub(form.format(limit), command)
                            reduced.append(f"{where}: {form.format(m.group(1))} -> {form.format(limit)}")
                    block.append((where, command))
        i += 1
n = 0
for k, block in enumerate(blocks):
    with open(os.path.join(tmp, f"block{k:02d}.sh"), "w") as f:
        f.write("set -uo pipefail\n")
        for where, command in block:
            n += 1
            quoted = command.replace("'", "'\\''")
            f.write(f"echo '+ {where}: {quoted}'\n")
            f.write(f"{{\n{command}\n}} > \"$DOC_LOG\" 2>&1 || {{ s=$?; cat \"$DOC_LOG\"; "
                    f"echo 'FAIL {where}: exit '$s': {quoted}'; exit 1; }}\n")
with open(os.path.join(tmp, "summary.txt"), "w") as f:
    f.write(f"{n} commands in {len(blocks)} blocks of {len(files)} files\n")
    for name, why in not_cheap.items():
        f.write(f"not run: {name} ({why})\n")
    for s in skipped:
        f.write(f"not run: {s}\n")
    for r in reduced:
        f.write(f"reduced: {r}\n")
PY

status=0
for script in "$tmp"/block*.sh; do
  (cd "$work" && PATH="$tmp/bin:$PATH" DOC_LOG="$tmp/log" bash "$script") || status=1
  [ "$status" -eq 0 ] || break
done
cat "$tmp/summary.txt"
[ "$status" -eq 0 ] || fail "a documented command failed (above)"
echo "e2e doc_commands: ok"
