#!/usr/bin/env bash
# The catalogs made from the refractiveindex.info data (catalogs/HIKARI.agf, ...) are exactly what
# tools/make-rii-catalogs.py writes from ../shared/data/rii (skipped without the data or PyYAML).
set -euo pipefail
lensopt="$1"
root="$(cd "$(dirname "$0")/../.." && pwd)"
rii="$root/../shared/data/rii"
[ -d "$rii/specs" ] || { echo "skipped: $rii is absent"; exit 77; }
python3 -c "import yaml" 2>/dev/null || { echo "skipped: python3 has no yaml module"; exit 77; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
python3 "$root/tools/make-rii-catalogs.py" "$rii" "$tmp" > "$tmp/log"
for name in HIKARI SUMITA LZOS LIGHTPATH CORNING INFRARED MISC; do
  cmp "$tmp/$name.agf" "$root/catalogs/$name.agf" || {
    echo "catalogs/$name.agf differs from the generator's output (run tools/make-rii-catalogs.py)"
    exit 1
  }
done
# The command lists them by their Zemax names.
"$lensopt" catalog NIKON-HIKARI >"$tmp/hikari.txt"
grep -q "^J-LASF08A " "$tmp/hikari.txt" || { echo "J-LASF08A not listed"; exit 1; }
echo "ok"
