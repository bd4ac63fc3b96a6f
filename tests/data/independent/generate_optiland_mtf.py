#!/usr/bin/env python3
"""Writes optiland_run_mtf.json: the diffraction (FFT) and geometric MTF of the three lenses/zmx
lenses and the Tessar, computed by running optiland (HarrisonKramer/optiland, MIT) on this
machine, for tests/unit/test_reference_independent_mtf.cpp (issue 17).

Provenance only: CI does not run this script (optiland is not a dependency of lensopt). It
contains no optiland code; it imports optiland from the folder given by --optiland (a package
whose `optiland` module provides optic.Optic, materials.IdealMaterial and mtf.FFTMTF /
mtf.GeometricMTF of optiland 0.2.x).

Input (--inputs): the optics as lensopt traces them, written by the test itself:
  LENSOPT_WRITE_OPTILAND_MTF_INPUTS=/tmp/mtf_inputs.json build/lensopt_tests \
      -tc='independent: optiland*MTF*'
i.e. per lens its primary wavelength, the surfaces (curvature, thickness after, index of the
medium after at that wavelength: lensopt's own glass data, model glass or catalog), the stop,
the EPD and the two compared field angles (0 and the full field). The Tessar is lensopt's
paper-mode system (scaled to f = 16 / (2 tan 25 deg)). optiland gets each medium as its
IdealMaterial(n) (a constant index: every run here is monochromatic), so glass data cannot
differ.

What it computes, per lens and field (0 and full), monochromatic at the primary wavelength:
- optiland's FFTMTF(optic, fields=[(0, 0), (0, 1)], wavelength, num_rays=N, grid_size=2N) for
  N = 64, 128, 256, 512: its pupil grid is linspace(-1, 1, N) in both directions (points with
  r <= 1), OPD to the chief ray's reference sphere, the PSF by FFT on a 2N grid (no wrap of the
  autocorrelation), the MTF = |FFT(PSF)| normalized to its zero frequency, tangential along the
  pupil's y, sagittal along x. Sample k of that MTF is a pupil shift of k grid steps
  (2 / (N - 1) in normalized pupil units), i.e. the frequency nu = k / ((N - 1) lambda F) with F
  optiland's paraxial F-number (FFTMTF.FNO; the relation later optiland versions use for their
  frequency axis; this version's _get_mtf_units, Q / (lambda_um F), is it only for grid_size ~
  1000). The values at 10, 30, 50 cycles/mm are read off the samples by a cubic spline in k
  (scipy CubicSpline; samples ~1.3-4 cycles/mm apart at N = 256).
- optiland's GeometricMTF(optic, fields, wavelength, num_rays=N, distribution='uniform',
  num_points=P, scale=False) (not multiplied by the diffraction limit, as lensopt's): the spot
  of the N x N uniform grid binned into P + 1 bins, its Fourier transform at P frequencies from 0
  to 1 / (lambda F); the values at 10, 30, 50 by the same cubic spline in frequency.
- the same FFTMTF with a clear aperture on the stop (StopClip below, radius: lensopt's real stop
  radius, the on-axis marginal ray's height there, x (1 + 1e-9)): rays outside the real stop
  are vignetted (intensity 0), as in a real lens traced without ray aiming. Without it, at the
  Tessar's full field part of the paraxial pupil passes outside the stop through overlapping
  lens edges, travelling backwards between surfaces (counted here as backward_rays), where the
  two tools' optical paths differ by definition (optiland |t| n, lensopt t n).
The reported reference is the finest sampling (FFT N = 512, geometric N = 512 with P = 4096);
the coarser runs are kept in the file to show the convergence.

Usage:
  generate_optiland_mtf.py --optiland /tmp/optiland-src --inputs /tmp/mtf_inputs.json \
      --out tests/data/independent/optiland_run_mtf.json --optiland-commit <sha> \
      --optiland-note "<how that optiland copy was obtained>"
"""

import argparse
import datetime
import json
import math
import sys
import time

FREQUENCIES = [10.0, 30.0, 50.0]
FFT_SAMPLINGS = [64, 128, 256, 512]
GEO_SAMPLINGS = [(128, 1024), (256, 2048), (512, 4096)]  # (num_rays, num_points)


class StopClip:
    """A circular clear aperture of radius r_mm on the stop (written here: this optiland's
    physical apertures are not used); it gives optiland's rays outside it intensity 0."""

    def __init__(self, r_mm):
        self.r_mm = r_mm

    def clip(self, rays):
        rays.clip(rays.x ** 2 + rays.y ** 2 > self.r_mm ** 2)


def build_optic(optic_in, Optic, IdealMaterial, stop_clip=False):
    lens = Optic()
    lens.add_surface(index=0, radius=math.inf, thickness=math.inf)
    surfaces = optic_in["surfaces"]
    for k, s in enumerate(surfaces):
        c = s["curvature_per_mm"]
        kwargs = dict(index=k + 1, radius=(1.0 / c if c != 0.0 else math.inf),
                      thickness=s["thickness_mm"], is_stop=(k == optic_in["stop_surface"]))
        n = s["index_after"]
        if stop_clip and k == optic_in["stop_surface"]:
            kwargs["aperture"] = StopClip(optic_in["stop_clip_radius_mm"])
        kwargs["material"] = IdealMaterial(n) if n != 1.0 else "air"
        lens.add_surface(**kwargs)
    lens.add_surface(index=len(surfaces) + 1)  # image plane
    lens.set_aperture("EPD", optic_in["epd_mm"])
    lens.set_field_type("angle")
    for f in optic_in["fields_deg"]:
        lens.add_field(y=f)
    lens.add_wavelength(optic_in["wavelength_nm"] * 1e-3, is_primary=True)
    return lens


def spline_at(samples_x, samples_y, x):
    from scipy.interpolate import CubicSpline
    return float(CubicSpline(samples_x, samples_y)(x))


def backward_rays(lens, optic_in, n):
    """Per field: how many rays of the n x n uniform grid that arrive (intensity > 0) travel
    backwards (z decreasing) between two consecutive surfaces: there optiland adds |t| n to the
    optical path and lensopt the signed t n, so their OPD differs."""
    import numpy as np

    class Grid:
        pass

    x = np.linspace(-1, 1, n)
    x, y = np.meshgrid(x, x)
    inside = x ** 2 + y ** 2 <= 1
    g = Grid()
    g.x, g.y = x[inside], y[inside]
    out = []
    for field in [(0.0, 0.0), (0.0, 1.0)]:
        lens.trace(*field, optic_in["wavelength_nm"] * 1e-3, None, g)
        z = lens.surface_group.z[1:, :]
        arrived = lens.surface_group.intensity[-1, :] > 0
        backward = np.any(np.diff(z, axis=0) < 0, axis=0) & arrived
        out.append({"rays": int(g.x.size), "arrived": int(arrived.sum()),
                    "backward": int(backward.sum())})
    return out


def fft_mtf(lens, optic_in, n, FFTMTF):
    fields = [(0.0, 0.0), (0.0, 1.0)]
    lam_um = optic_in["wavelength_nm"] * 1e-3
    m = FFTMTF(lens, fields=fields, wavelength=lam_um, num_rays=n, grid_size=2 * n)
    fno = float(m.FNO)
    out = []
    for f, (t, s) in enumerate(m.mtf):
        k = list(range(len(t)))
        row = {}
        for nu in FREQUENCIES:
            kk = nu * (n - 1) * lam_um * 1e-3 * fno
            row[nu] = (spline_at(k, t, kk), spline_at(k, s, kk))
        out.append(row)
    return fno, out


def geometric_mtf(lens, optic_in, n, points, GeometricMTF):
    fields = [(0.0, 0.0), (0.0, 1.0)]
    lam_um = optic_in["wavelength_nm"] * 1e-3
    g = GeometricMTF(lens, fields=fields, wavelength=lam_um, num_rays=n, distribution="uniform",
                     num_points=points, scale=False)
    out = []
    for t, s in g.mtf:
        out.append({nu: (spline_at(g.freq, t, nu), spline_at(g.freq, s, nu))
                    for nu in FREQUENCIES})
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--optiland", required=True)
    ap.add_argument("--inputs", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--optiland-commit", required=True)
    ap.add_argument("--optiland-note", default="")
    args = ap.parse_args()
    sys.path.insert(0, args.optiland)
    import numpy
    from optiland.optic import Optic
    from optiland.materials import IdealMaterial
    from optiland.mtf import FFTMTF, GeometricMTF

    with open(args.inputs) as f:
        inputs = json.load(f)
    lenses = []
    for optic_in in inputs["lenses"]:
        name = optic_in["name"]
        lens = build_optic(optic_in, Optic, IdealMaterial)
        clipped = build_optic(optic_in, Optic, IdealMaterial, stop_clip=True)
        paraxial = {"efl_mm": float(lens.paraxial.f2()), "epd_mm": float(lens.paraxial.EPD()),
                    "fno": float(lens.paraxial.FNO()), "epl_mm": float(lens.paraxial.EPL()),
                    "xpl_mm": float(lens.paraxial.XPL())}
        fft_runs = {}
        clip_runs = {}
        for n in FFT_SAMPLINGS:
            t0 = time.time()
            fno, fft_runs[n] = fft_mtf(lens, optic_in, n, FFTMTF)
            _, clip_runs[n] = fft_mtf(clipped, optic_in, n, FFTMTF)
            print(f"{name}: FFT N = {n} in {time.time() - t0:.1f} s", file=sys.stderr)
        geo_runs = {}
        for n, points in GEO_SAMPLINGS:
            t0 = time.time()
            geo_runs[(n, points)] = geometric_mtf(lens, optic_in, n, points, GeometricMTF)
            print(f"{name}: geometric N = {n}, P = {points} in {time.time() - t0:.1f} s",
                  file=sys.stderr)
        finest = FFT_SAMPLINGS[-1]
        backward = backward_rays(lens, optic_in, finest)
        backward_clipped = backward_rays(clipped, optic_in, finest)
        finest_geo = GEO_SAMPLINGS[-1]
        points = []
        for f, field_name in enumerate(["axis", "full"]):
            for nu in FREQUENCIES:
                t, s = fft_runs[finest][f][nu]
                ct, cs = clip_runs[finest][f][nu]
                gt, gs = geo_runs[finest_geo][f][nu]
                points.append({
                    "field": field_name, "field_deg": optic_in["fields_deg"][f],
                    "frequency_cyc_mm": nu,
                    "pupil_shift": 2.0 * nu * optic_in["wavelength_nm"] * 1e-6 * fno,
                    "fft_t": round(t, 6), "fft_s": round(s, 6),
                    "fft_stop_clipped_t": round(ct, 6), "fft_stop_clipped_s": round(cs, 6),
                    "geometric_t": round(gt, 6), "geometric_s": round(gs, 6),
                    "backward_rays": backward[f]["backward"],
                    "backward_rays_stop_clipped": backward_clipped[f]["backward"],
                    "arrived_stop_clipped": backward_clipped[f]["arrived"],
                    "grid_rays": backward[f]["rays"],
                    "fft_convergence": {str(n): [round(v, 6) for v in fft_runs[n][f][nu]]
                                        for n in FFT_SAMPLINGS},
                    "fft_stop_clipped_convergence": {
                        str(n): [round(v, 6) for v in clip_runs[n][f][nu]]
                        for n in FFT_SAMPLINGS},
                    "geometric_convergence": {f"{n}/{p}": [round(v, 6) for v in
                                                           geo_runs[(n, p)][f][nu]]
                                              for n, p in GEO_SAMPLINGS},
                })
        lenses.append({"optic": optic_in, "optiland_paraxial": paraxial, "points": points})
    doc = {
        "description": "Diffraction (FFT) and geometric MTF of lensopt's lenses computed by "
                       "optiland's FFTMTF and GeometricMTF, monochromatic at the primary "
                       "wavelength, on axis and at full field. See README.md in this folder.",
        "tool": "optiland (HarrisonKramer/optiland, MIT), Python " + sys.version.split()[0] +
                ", numpy " + numpy.__version__,
        "optiland_commit": args.optiland_commit,
        "optiland_note": args.optiland_note,
        "generated_utc": datetime.datetime.now(datetime.timezone.utc).strftime(
            "%Y-%m-%dT%H:%M:%SZ"),
        "generator": "tests/data/independent/generate_optiland_mtf.py",
        "fft_sampling": {"num_rays": FFT_SAMPLINGS[-1], "grid_size": 2 * FFT_SAMPLINGS[-1],
                         "convergence_num_rays": FFT_SAMPLINGS},
        "geometric_sampling": {"num_rays": GEO_SAMPLINGS[-1][0],
                               "num_points": GEO_SAMPLINGS[-1][1],
                               "convergence": [f"{n}/{p}" for n, p in GEO_SAMPLINGS]},
        "conventions": [
            "optic: lensopt's traced system at its primary wavelength (inputs written by the "
            "test), media as optiland IdealMaterial(n); object at infinity; fields by angle",
            "no ray aiming: rays through the paraxial entrance pupil (optiland's only mode at "
            "this version; lensopt traced with ray_aiming = false)",
            "OPD: optiland's reference sphere centred on the chief ray's image point, radius to "
            "the paraxial exit pupil centre; tilt not removed (it does not change |OTF|)",
            "FFT MTF frequency: sample k = pupil shift 2k/(N-1) = frequency k/((N-1) lambda F), "
            "F = paraxial EFL/EPD, the same for every field; values read by cubic spline",
            "geometric MTF: unscaled (scale=False), spot binned into num_points + 1 bins; "
            "values read by cubic spline in frequency",
            "monochromatic only: this optiland's FFTMTF and GeometricMTF take one wavelength",
            "fft_stop_clipped_*: the same FFT MTF with a clear aperture on the stop of radius "
            "stop_clip_radius_mm (lensopt's real stop radius x (1 + 1e-9)): rays outside the real "
            "stop get intensity 0 (lensopt: vignetted)",
            "backward_rays: rays of the finest FFT grid that arrive and travel backwards (z "
            "decreasing) between two consecutive surfaces (they cross overlapping surfaces "
            "outside the real stop); optiland adds |t| n to their optical path, lensopt t n",
        ],
        "lenses": lenses,
    }
    with open(args.out, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
