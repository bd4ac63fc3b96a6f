#!/usr/bin/env bash
# End-to-end test of `lensopt render --annotations FILE` (issue 19): a generated detection
# dataset rendered through the Doublet at 2x comes with its annotations as the rendered images
# show them, in COCO: the same images and categories, every box inside its image, boxes moved by
# the distortion (not the input's), and without distortion the input's boxes exactly. A bright
# square's rendered centroid lies inside its transformed box.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
"$lensopt" chart --detection -o "$tmp/data" --count 3 --size 256x144 --seed 2 > /dev/null
# One more image: a bright 6 x 6 square on black near the far corner (2x: the axis is at the
# bottom-right corner), annotated by hand.
python3 - "$tmp/data" <<'PY'
import json, sys, zlib, struct
d = sys.argv[1]
w, h = 256, 144
rows = []
for y in range(h):
    row = bytearray([0])
    for x in range(w):
        v = 255 if 20 <= x < 26 and 14 <= y < 20 else 0
        row += bytes([v, v, v])
    rows.append(bytes(row))
def chunk(t, data):
    c = struct.pack(">I", len(data)) + t + data
    return c + struct.pack(">I", zlib.crc32(t + data) & 0xFFFFFFFF)
png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
png += chunk(b"IDAT", zlib.compress(b"".join(rows))) + chunk(b"IEND", b"")
open(d + "/images/square.png", "wb").write(png)
j = json.load(open(d + "/annotations.json"))
j["images"].append({"id": 999, "file_name": "square.png", "width": w, "height": h})
j["annotations"].append({"id": 99999, "image_id": 999, "category_id": 1, "bbox": [20, 14, 6, 6],
                         "area": 36, "iscrowd": 0})
json.dump(j, open(d + "/annotations.json", "w"))
PY
"$lensopt" render lenses/doublet.toml "$tmp/data/images" -o "$tmp/out" --res-factor 2 \
  --annotations "$tmp/data/annotations.json" -q > "$tmp/log" || fail "render: $(cat "$tmp/log")"
grep -q "^annotations: $tmp/out/annotations.json" "$tmp/log" || fail "no annotations line: $(cat "$tmp/log")"
"$lensopt" render lenses/doublet.toml "$tmp/data/images" -o "$tmp/plain" --res-factor 2 \
  --no-distortion --annotations "$tmp/data/annotations.json" -q > /dev/null
python3 - "$tmp" <<'PY'
import json, sys, zlib, struct
t = sys.argv[1]
src = json.load(open(t + "/data/annotations.json"))
out = json.load(open(t + "/out/annotations.json"))
plain = json.load(open(t + "/plain/annotations.json"))
assert [i["file_name"] for i in out["images"]] == [i["file_name"] for i in src["images"]]
assert out["categories"] == src["categories"]
size = {i["id"]: (i["width"], i["height"]) for i in out["images"]}
for a in out["annotations"]:
    x, y, w, h = a["bbox"]
    W, H = size[a["image_id"]]
    assert w > 0 and h > 0 and x >= 0 and y >= 0 and x + w <= W + 1e-9 and y + h <= H + 1e-9, a
key = lambda a: (a["image_id"], a["category_id"])
assert len(plain["annotations"]) == len(src["annotations"])
for p, s in zip(plain["annotations"], src["annotations"]):
    assert all(abs(u - v) < 1e-9 for u, v in zip(p["bbox"], s["bbox"])), (p, s)
moved = max(max(abs(u - v) for u, v in zip(o["bbox"][:2], s["bbox"][:2]))
            for o, s in zip(out["annotations"], src["annotations"]) if key(o) == key(s))
assert moved > 2, moved
# The square's rendered centroid (green channel) is inside its box (1 px).
def read_png(path):
    data = open(path, "rb").read()
    pos, idat, w = 8, b"", 0
    while pos < len(data):
        n, = struct.unpack(">I", data[pos:pos + 4]); kind = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + n]; pos += 12 + n
        if kind == b"IHDR":
            w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and ctype == 2, (depth, ctype)
        elif kind == b"IDAT":
            idat += body
    raw = zlib.decompress(idat); stride = 3 * w; img = []; prev = bytearray(stride); p = 0
    for y in range(h):
        f = raw[p]; line = bytearray(raw[p + 1:p + 1 + stride]); p += 1 + stride
        for i in range(stride):
            a = line[i - 3] if i >= 3 else 0; b = prev[i]; c = prev[i - 3] if i >= 3 else 0
            if f == 1: line[i] = (line[i] + a) & 255
            elif f == 2: line[i] = (line[i] + b) & 255
            elif f == 3: line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        img.append(line); prev = line
    return w, h, img
w, h, img = read_png(t + "/out/square.png")
s = sx = sy = 0.0
for y in range(h):
    for x in range(w):
        v = img[y][3 * x + 1]
        s += v; sx += v * (x + 0.5); sy += v * (y + 0.5)
cx, cy = sx / s, sy / s
box = [a for a in out["annotations"] if a["image_id"] == 999][0]["bbox"]
assert box[0] - 1 <= cx <= box[0] + box[2] + 1 and box[1] - 1 <= cy <= box[1] + box[3] + 1, (cx, cy, box)
assert abs(box[0] - 20) > 1 or abs(box[1] - 14) > 1, box  # the distortion moved it
print(f"render --annotations: {len(out['annotations'])} boxes, moved up to {moved:.2f} px; "
      f"square centroid ({cx:.2f}, {cy:.2f}) in box {box}")
PY
echo "e2e render_annotations: ok"
