#!/usr/bin/env python3
"""Writes optiland_run_geometry3d.json: real rays through geometry3d_cb.zmx (two singlets behind
OpticStudio coordinate breaks, decentred and tilted about x and about y) traced by optiland
(HarrisonKramer/optiland, MIT) on this machine, as an independent check of lensopt's COORDBRK
convention and tilt handedness (issue 32).

Provenance only: CI does not run this script (optiland is not a dependency of lensopt). It contains
no optiland code; it imports optiland from the folder given by --optiland.

What it does:
- loads the .zmx with optiland's own Zemax reader (optiland.fileio.load_zemax_file), which turns
  each COORDBRK into a coordinate system (decenter, then rotations about x, y, z) chained to the
  surfaces after it: an independent reading of the file;
- replaces the two glasses (model glasses ___BLANK nd vd, which optiland reads as its AbbeMaterial,
  whose index at 587.5618 nm is not nd exactly) by optiland's IdealMaterial(nd), the index lensopt's
  model glass has there (OpticStudio's model glass: nd exact at 587.5618 nm), so both tools trace
  the same indices;
- starts each ray 1 mm before the stop (z = -1, the stop plane at z = 0) with a direction of a
  field (on axis, 3 deg on y, 2 deg on x: (sin a, 0, cos a) for x, (0, sin a, cos a) for y) through
  a point (x_s, y_s) of the stop, traces it with optiland's SurfaceGroup.trace (the object surface
  skipped), and records it in the image surface's own frame (optiland's image surface
  geometry.localize): x, y (mm) and the direction cosines L, M, N.

Usage:
  generate_optiland_geometry3d.py --optiland /tmp/optiland-src --zmx geometry3d_cb.zmx \
      --out optiland_run_geometry3d.json --optiland-commit <sha>
"""

import argparse
import datetime
import json
import math
import sys

FIELDS = [("on axis", 0.0, 0.0), ("y 3 deg", 0.0, 3.0), ("x 2 deg", 2.0, 0.0)]
STOP_POINTS = [[0.0, 0.0], [0.0, 4.0], [0.0, -4.0], [4.0, 0.0], [-4.0, 0.0], [2.5, 2.5]]
GLASSES = {2: 1.5168, 4: 1.6}  # optiland surface number (object 0, stop 1) -> nd


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--optiland", required=True)
    parser.add_argument("--zmx", required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--optiland-commit", required=True)
    args = parser.parse_args()
    sys.path.insert(0, args.optiland)
    import numpy as np
    from optiland.fileio import load_zemax_file
    from optiland.materials import IdealMaterial
    from optiland.rays import RealRays

    optic = load_zemax_file(args.zmx)
    surfaces = optic.surfaces
    for k, n in GLASSES.items():
        surfaces[k].material_post = IdealMaterial(n=n)
    wavelength_um = 0.5875618
    rays_out = []
    for label, ax_deg, ay_deg in FIELDS:
        ax, ay = math.radians(ax_deg), math.radians(ay_deg)
        if ax_deg != 0.0:
            L, M, N = math.sin(ax), 0.0, math.cos(ax)
        else:
            L, M, N = 0.0, math.sin(ay), math.cos(ay)
        xs = np.array([p[0] for p in STOP_POINTS], dtype=float)
        ys = np.array([p[1] for p in STOP_POINTS], dtype=float)
        count = len(STOP_POINTS)
        rays = RealRays(xs - L / N, ys - M / N, np.full(count, -1.0), np.full(count, L),
                        np.full(count, M), np.full(count, N), np.ones(count),
                        np.full(count, wavelength_um))
        surfaces.trace(rays, skip=1)
        surfaces[-1].geometry.localize(rays)
        for i, p in enumerate(STOP_POINTS):
            rays_out.append({
                "field": label,
                "start": [float(xs[i] - L / N), float(ys[i] - M / N), -1.0],
                "direction": [L, M, N],
                "stop_point": p,
                "image_xy": [float(rays.x[i]), float(rays.y[i])],
                "image_LMN": [float(rays.L[i]), float(rays.M[i]), float(rays.N[i])],
            })
    out = {
        "comment": "Real rays through geometry3d_cb.zmx traced by optiland (see "
                   "generate_optiland_geometry3d.py): each ray starts at `start` (mm; the stop "
                   "plane is z = 0) along `direction`; image_xy and image_LMN are in the image "
                   "surface's own frame (after both coordinate breaks).",
        "optiland": "HarrisonKramer/optiland @ " + args.optiland_commit + " (MIT), run here with "
                    "Debian 12's python3 " + sys.version.split()[0] + ", numpy " + np.__version__,
        "optiland_note": "the repository snapshot's optiland/ package imported from a plain "
                         "export of that commit, unmodified; its Zemax reader reads the .zmx",
        "generated": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "wavelength_um": wavelength_um,
        "indices": {"surface 3 (lensopt) / 2 (optiland)": 1.5168,
                    "surface 6 (lensopt) / 4 (optiland)": 1.6},
        "rays": rays_out,
    }
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
