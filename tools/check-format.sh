#!/usr/bin/env bash
# Checks that the C++ sources follow .clang-format: src/, include/, tests/ and python/src/.
# Usage: tools/check-format.sh [source-tree]. Prints the files clang-format would change (with
# its diagnostics) and exits 1 when there is one; exit 77 (skipped) when clang-format 14, the
# version the tree is formatted with, is not installed (other versions lay out differently).
# Fix with: clang-format-14 -i <file> (or the whole tree: tools/check-format.sh --fix).
set -euo pipefail
fix=0
if [[ "${1:-}" == "--fix" ]]; then
  fix=1
  shift
fi
root="${1:-$(dirname "$0")/..}"
cd "$root"

format=""
for candidate in clang-format-14 clang-format; do
  if command -v "$candidate" >/dev/null &&
    "$candidate" --version | grep -qE 'version 14\.'; then
    format="$candidate"
    break
  fi
done
if [[ -z "$format" ]]; then
  echo "check-format: clang-format 14 not found; skipped" >&2
  exit 77
fi

mapfile -t files < <(find src include tests python/src -type f \
  \( -name '*.h' -o -name '*.cpp' -o -name '*.c' \) | sort)
if ((fix)); then
  "$format" -i "${files[@]}"
  exit 0
fi
bad=()
for file in "${files[@]}"; do
  if ! "$format" --dry-run --Werror "$file" >/dev/null 2>&1; then bad+=("$file"); fi
done
if ((${#bad[@]})); then
  for file in "${bad[@]}"; do
    echo "check-format: $file is not clang-formatted; first difference:" >&2
    "$format" --dry-run "$file" 2>&1 | head -n 3 >&2
  done
  echo "check-format: ${#bad[@]} of ${#files[@]} files need '$format -i' (or tools/check-format.sh --fix)" >&2
  exit 1
fi
echo "check-format: ${#files[@]} files formatted"
