#!/usr/bin/env python3
"""Writes N different small 8-bit RGB PNGs for the render e2e tests (no dependency but Python):
a grey background with six random rectangles (sharp edges the blur changes), image i seeded by
1000 + i; every third goes to the subfolder sub/. Usage: make_images.py DIR N WIDTH HEIGHT"""
import os
import random
import struct
import sys
import zlib


def write_png(path, width, height, pixels):
    raw = b"".join(b"\0" + bytes(c for px in row for c in px) for row in pixels)

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw))
                + chunk(b"IEND", b""))


def main():
    out, count, width, height = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    os.makedirs(os.path.join(out, "sub"), exist_ok=True)
    for i in range(count):
        rng = random.Random(1000 + i)
        grey = rng.randrange(40, 200)
        pixels = [[(grey, grey, grey)] * width for _ in range(height)]
        for _ in range(6):
            x0, y0 = rng.randrange(width - 8), rng.randrange(height - 8)
            x1, y1 = x0 + rng.randrange(4, width - x0), y0 + rng.randrange(4, height - y0)
            colour = tuple(rng.randrange(256) for _ in range(3))
            for y in range(y0, y1):
                pixels[y][x0:x1] = [colour] * (x1 - x0)
        write_png(os.path.join(out, "sub" if i % 3 == 0 else "", f"img_{i:02d}.png"), width, height,
                  pixels)


if __name__ == "__main__":
    main()
