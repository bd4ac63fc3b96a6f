#!/usr/bin/env python3
"""Analyse a lens from Python and plot its spot size, distortion and relative illumination.

    PYTHONPATH=build/python python3 examples/analyze_lens.py lenses/cooke.toml -o cooke.svg

Prints the analysis (the same report as `lensopt analyze`) and writes an SVG with three charts
against the field angle (plain SVG, so no plotting package is needed), plus the lens's PSFs at
the axis and the edge of the field as numbers.
"""

import argparse
import sys
from pathlib import Path

import lensopt


def svg_chart(x0, y0, width, height, xs, ys, title, unit):
    """One line chart as SVG elements, in a box at (x0, y0)."""
    lo, hi = min(ys), max(ys)
    if hi - lo < 1e-12:
        lo, hi = lo - 1, hi + 1
    px = [x0 + 40 + (width - 50) * (x - xs[0]) / (xs[-1] - xs[0]) for x in xs]
    py = [y0 + height - 25 - (height - 45) * (y - lo) / (hi - lo) for y in ys]
    points = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(px, py))
    return "\n".join([
        f'<rect x="{x0}" y="{y0}" width="{width}" height="{height}" fill="none" stroke="#ccc"/>',
        f'<text x="{x0 + 40}" y="{y0 + 14}" font-size="12">{title} ({unit})</text>',
        f'<text x="{x0 + 2}" y="{y0 + 30}" font-size="10">{hi:.3g}</text>',
        f'<text x="{x0 + 2}" y="{y0 + height - 25}" font-size="10">{lo:.3g}</text>',
        f'<text x="{x0 + width - 60}" y="{y0 + height - 8}" font-size="10">field {xs[-1]:.1f} deg</text>',
        f'<polyline points="{points}" fill="none" stroke="#1f77b4" stroke-width="2"/>',
    ])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("lens", help="lens file (.toml, .yml, .zmx)")
    parser.add_argument("-o", "--output", default="lens.svg", help="SVG to write")
    parser.add_argument("--rings", type=int, default=32)
    parser.add_argument("--fields", type=int, default=21)
    args = parser.parse_args(argv)

    lens = lensopt.load_lens(args.lens)
    report = lensopt.analyze(lens, rings=args.rings, fields=args.fields)
    print(report.to_text())

    fields = [f.field_deg for f in report.fields]
    charts = [
        ([f.rms_spot_um or 0.0 for f in report.fields], "RMS spot", "um"),
        ([f.distortion_percent for f in report.fields], "distortion", "%"),
        ([f.relative_illumination for f in report.fields], "relative illumination", "1"),
    ]
    body = [svg_chart(10, 10 + 190 * i, 420, 180, fields, ys, t, u)
            for i, (ys, t, u) in enumerate(charts)]
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="440" height="590" '
           'font-family="DejaVu Sans, sans-serif">\n' + "\n".join(body) + "\n</svg>\n")
    Path(args.output).write_text(svg)
    print(f"wrote {args.output}")

    psf = lensopt.psfs(lens, rings=min(args.rings, 16), fields=2, grid_size=33)
    for h, field in enumerate(psf["fields_deg"]):
        peak = psf["psf"][h].max(axis=(1, 2))
        print(f"PSF at {field:.1f} deg: peak bin share R {peak[0]:.3f} G {peak[1]:.3f} "
              f"B {peak[2]:.3f} ({psf['bin_um']} um bins)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
