#!/usr/bin/env python3
"""Writes optiland_run_rays.json: paraxial data and real-ray image intercepts of real .zmx files,
computed by running optiland (HarrisonKramer/optiland, MIT) on this machine.

Provenance only: CI does not run this script (optiland is not a dependency of lensopt). It
contains no optiland code; it imports optiland from the folder given by --optiland (a package
whose `optiland` module provides optic.Optic, materials.BaseMaterial and the paraxial and real
ray tracing of optiland 0.2.x).

What it does, per lens:
- reads the .zmx itself (its own small reader below: SURF, CURV, DISZ, CONI, PARM, GLAS, STOP,
  DIAM of the stop, ENPD / FNUM / FLOA, FTYP, YFLN, WAVM, PWAV, GCAT; solves and pickups are
  not evaluated: a .zmx stores their resolved values on the CURV / DISZ / GLAS lines);
- computes every glass index from the same glass data lensopt ships: the catalog's AGF
  coefficients (catalogs/*.agf, searched in GCAT order; Sellmeier 1, n^2 - 1 = sum K l^2 /
  (l^2 - L), l in um) or, for a model glass (GLAS ___BLANK 1 0 nd vd), lensopt's model
  n = nd + B (l^-2 - ld^-2), B = (nd - 1) / (vd (lF^-2 - lC^-2)), lC/d/F = 656.3 / 587.6 /
  486.1 nm; air is 1;
- hands optiland the index table through a material class of its own (TableMaterial below,
  optiland's BaseMaterial interface) and builds the lens with optiland's Optic.add_surface
  (standard surfaces with conic, even aspheres with coefficients from r^2), object at infinity,
  fields by angle;
- records, at each wavelength, optiland's paraxial EFL (f2), back focal point from the image
  surface (F2), EPL, EPD, XPL, computed with that wavelength as optiland's primary; and the
  image-plane (x, y) of the chief ray, the marginal rays (Px, Py) = (0, 1), (0, -1), (1, 0)
  and the zonal rays (0, 0.5), (0, -0.5), (0.5, 0) at every written field, with their
  direction cosines (L, M, N) in image space and, for the chief and marginal rays at the
  primary wavelength, their (x, y) on every lens surface (a ray that misses a surface in
  optiland, a NaN, is recorded as not traced), traced with optiland's trace_generic at that wavelength while
  the optic's primary is the file's primary (so every ray goes through the paraxial entrance
  pupil of the primary wavelength: optiland does not aim rays).
  Vignetting factors of the file are not applied (pupil coordinates are those of the paraxial
  entrance pupil), nor its clear apertures (DIAM); a FLOA aperture's EPD is found with
  optiland's paraxial marginal ray (EPD = stop semi-diameter / marginal height at the stop for
  EPD = 1); even-asphere intersections use optiland's iteration with tol 1e-14 mm and up to
  1000 steps (its surface factory's default tol is 1e-6 mm). A file without GCAT uses SCHOTT
  (OpticStudio's default catalog).

Usage:
  generate_optiland_rays.py --optiland /tmp/optiland-src --repo . \
      --out tests/data/independent/optiland_run_rays.json --optiland-commit <sha> \
      --optiland-note "<how that optiland copy was obtained>"
"""

import argparse
import datetime
import json
import math
import os
import sys

# (name, path from the repository root, extra wavelengths in um beyond the file's own)
LENSES = [
    ("optiland_lens1", "tests/data/zmx-real/optiland_lens1.zmx", []),
    ("optiland_lens_floa", "tests/data/zmx-real/optiland_lens_floa.zmx", [0.4861327]),
    ("optiland_thorlabs_AL1815-C", "tests/data/zmx-real/optiland_thorlabs_AL1815-C_iso_8859_1.zmx",
     [0.55]),
    ("thorlabs_AC254-100-A", "tests/data/zmx-real/thorlabs_AC254-100-A.zmx", []),
    ("thorlabs_AC254-125-A", "tests/data/zmx-real/thorlabs_AC254-125-A.zmx", []),
    ("rayoptics_US00583336-2-scaled", "tests/data/zmx-real/rayoptics_US00583336-2-scaled.zmx", []),
    ("achromat_ac254_100", "lenses/zmx/achromat_ac254_100.zmx", []),
    ("cooke_triplet_50", "lenses/zmx/cooke_triplet_50.zmx", []),
    ("double_gauss_100", "lenses/zmx/double_gauss_100.zmx", []),
]

# (Px, Py): the chief ray, the marginal rays, and zonal rays at half the pupil radius (the
# marginal rays of a very fast lens may miss a surface: recorded as not traced).
PUPIL_POINTS = [[0.0, 0.0], [0.0, 1.0], [0.0, -1.0], [1.0, 0.0], [0.0, 0.5], [0.0, -0.5],
                [0.5, 0.0]]

ASPHERE_TOL_MM = 1e-14
ASPHERE_MAX_ITER = 1000


# ---------------------------------------------------------------- .zmx reader (our own, minimal)
def read_zmx(path):
    with open(path, "rb") as f:
        raw = f.read()
    if raw.startswith(b"\xff\xfe") or raw.startswith(b"\xfe\xff"):
        text = raw.decode("utf-16")
    else:
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            text = raw.decode("latin-1")
    lens = {"surfaces": [], "catalogs": [], "aperture": None, "primary": 1}
    surf = None
    for line in text.splitlines():
        words = line.split()
        if not words:
            continue
        key = words[0]
        if key == "SURF":
            surf = {"curv": 0.0, "disz": 0.0, "conic": 0.0, "parm": {}, "glass": None,
                    "stop": False, "diam": None, "type": "STANDARD"}
            lens["surfaces"].append(surf)
        elif surf is not None and line.startswith("  "):
            if key == "TYPE":
                surf["type"] = words[1]
            elif key == "CURV":
                surf["curv"] = float(words[1])
            elif key == "DISZ":
                surf["disz"] = math.inf if words[1] == "INFINITY" else float(words[1])
            elif key == "CONI":
                surf["conic"] = float(words[1])
            elif key == "PARM":
                surf["parm"][int(words[1])] = float(words[2])
            elif key == "GLAS":
                if words[1] == "___BLANK":
                    surf["glass"] = ("model", float(words[4]), float(words[5]))
                else:
                    surf["glass"] = ("catalog", words[1])
            elif key == "STOP":
                surf["stop"] = True
            elif key == "DIAM":
                surf["diam"] = float(words[1])
        else:
            surf = None if key not in ("SURF",) else surf
            if key == "ENPD":
                lens["aperture"] = ("EPD", float(words[1]))
            elif key == "FNUM":
                lens["aperture"] = ("FNUM", float(words[1]))
            elif key == "FLOA":
                lens["aperture"] = ("FLOA", None)
            elif key == "GCAT":
                lens["catalogs"] = words[1:]
            elif key == "FTYP":
                lens["field_type"] = int(words[1])
                lens["num_fields"] = int(words[3])
                lens["num_wavelengths"] = int(words[4])
            elif key == "YFLN":
                lens["yfln"] = [float(w) for w in words[1:]]
            elif key == "XFLN":
                lens["xfln"] = [float(w) for w in words[1:]]
            elif key == "WAVM":
                lens.setdefault("wavm", {})[int(words[1])] = float(words[2])
            elif key == "PWAV":
                lens["primary"] = int(words[1])
    lens["wavelengths_um"] = [lens["wavm"][i + 1] for i in range(lens["num_wavelengths"])]
    lens["fields_deg"] = lens["yfln"][: lens["num_fields"]]
    assert lens["field_type"] == 0, "fields by angle only"
    assert all(x == 0.0 for x in lens.get("xfln", [0.0])[: lens["num_fields"]])
    assert math.isinf(lens["surfaces"][0]["disz"]), "object at infinity only"
    return lens


# ---------------------------------------------------------------- glass data (lensopt's files)
def read_agf(path):
    glasses = {}
    name = None
    with open(path, encoding="latin-1") as f:
        for line in f:
            words = line.split()
            if not words:
                continue
            if words[0] == "NM":
                name = words[1]
                glasses[name] = {"formula": int(float(words[2]))}
            elif words[0] == "CD" and name is not None:
                glasses[name]["cd"] = [float(w) for w in words[1:]]
    return glasses


def catalog_index(glass, wavelength_um):
    if glass["formula"] != 2:
        raise ValueError(f"formula {glass['formula']} not evaluated here")
    k1, l1, k2, l2, k3, l3 = glass["cd"][:6]
    w2 = wavelength_um * wavelength_um
    return math.sqrt(1.0 + k1 * w2 / (w2 - l1) + k2 * w2 / (w2 - l2) + k3 * w2 / (w2 - l3))


def model_index(nd, vd, wavelength_um):
    lc, ld, lf = 656.3, 587.6, 486.1
    lam = wavelength_um * 1000.0
    b = (nd - 1.0) / (vd * (1.0 / (lf * lf) - 1.0 / (lc * lc)))
    return nd + b * (1.0 / (lam * lam) - 1.0 / (ld * ld))


def glass_index(glass, catalogs, wavelength_um):
    if glass[0] == "model":
        return model_index(glass[1], glass[2], wavelength_um)
    for catalog_name, catalog in catalogs:
        if glass[1] in catalog:
            return catalog_index(catalog[glass[1]], wavelength_um)
    raise KeyError(f"glass {glass[1]} not in {[c for c, _ in catalogs]}")


# ---------------------------------------------------------------- optiland run
def build_optic(optiland, lens, catalogs, wavelengths_um, primary_um, epd_override=None):
    import numpy as np

    Optic = optiland["Optic"]
    table_material = optiland["TableMaterial"]
    optic = Optic()
    surfaces = lens["surfaces"]
    optic.add_surface(index=0, radius=np.inf, thickness=np.inf)
    for k in range(1, len(surfaces)):
        s = surfaces[k]
        radius = np.inf if s["curv"] == 0.0 else 1.0 / s["curv"]
        kwargs = {"index": k, "radius": radius, "is_stop": s["stop"]}
        if k < len(surfaces) - 1:
            kwargs["thickness"] = s["disz"]
        if s["glass"] is not None:
            kwargs["material"] = table_material(
                {w: glass_index(s["glass"], catalogs, w) for w in wavelengths_um})
        if s["type"] == "EVENASPH":
            kwargs["surface_type"] = "even_asphere"
            kwargs["conic"] = s["conic"]
            kwargs["coefficients"] = [s["parm"].get(i, 0.0) for i in range(1, 9)]
        elif s["type"] == "STANDARD":
            kwargs["conic"] = s["conic"]
        else:
            raise ValueError(f"surface type {s['type']} not handled")
        optic.add_surface(**kwargs)
        if s["type"] == "EVENASPH":
            geometry = optic.surface_group.surfaces[k].geometry
            geometry.tol = ASPHERE_TOL_MM
            geometry.max_iter = ASPHERE_MAX_ITER
    optic.set_field_type("angle")
    for field in lens["fields_deg"]:
        optic.add_field(y=field)
    for w in wavelengths_um:
        optic.add_wavelength(value=w, is_primary=(w == primary_um))
    ap_type, ap_value = lens["aperture"]
    if epd_override is not None:
        optic.set_aperture("EPD", epd_override)
    elif ap_type == "EPD":
        optic.set_aperture("EPD", ap_value)
    elif ap_type == "FNUM":
        optic.set_aperture("imageFNO", ap_value)
    else:
        raise ValueError("FLOA needs epd_override")
    return optic


def floa_epd(optiland, lens, catalogs, wavelengths_um, primary_um):
    """EPD of a float-by-stop aperture: the stop's semi-diameter over the paraxial marginal ray
    height at the stop for an entrance pupil of diameter 1 (optiland's marginal_ray)."""
    stop = next(k for k, s in enumerate(lens["surfaces"]) if s["stop"])
    semi = lens["surfaces"][stop]["diam"]
    optic = build_optic(optiland, lens, catalogs, wavelengths_um, primary_um, epd_override=1.0)
    ya, _ = optic.paraxial.marginal_ray()
    return semi / abs(float(ya[stop][0]))


def run_lens(optiland, repo, name, rel_path, extra_um):
    lens = read_zmx(os.path.join(repo, rel_path))
    catalogs = []
    # No GCAT line: SCHOTT, OpticStudio's default catalog.
    for c in lens["catalogs"] or ["SCHOTT"]:
        agf = os.path.join(repo, "catalogs", c + ".agf")
        if os.path.exists(agf):
            catalogs.append((c, read_agf(agf)))
    file_wavelengths = lens["wavelengths_um"]
    primary_um = file_wavelengths[lens["primary"] - 1]
    wavelengths_um = list(dict.fromkeys(file_wavelengths + extra_um))

    epd_floa = None
    if lens["aperture"][0] == "FLOA":
        epd_floa = floa_epd(optiland, lens, catalogs, wavelengths_um, primary_um)

    out = {
        "name": name,
        "file": rel_path,
        "primary_wavelength_um": primary_um,
        "wavelengths_um": wavelengths_um,
        "extra_wavelengths_um": extra_um,
        "fields_deg": lens["fields_deg"],
        "aperture": [lens["aperture"][0], lens["aperture"][1]],
        "indices": {},
        "paraxial": [],
        "rays": [],
    }
    for k, s in enumerate(lens["surfaces"]):
        if s["glass"] is not None:
            label = s["glass"][1] if s["glass"][0] == "catalog" else (
                f"model nd={s['glass'][1]!r} vd={s['glass'][2]!r}")
            out["indices"][f"{k}:{label}"] = [glass_index(s["glass"], catalogs, w)
                                               for w in wavelengths_um]

    # Paraxial data at each wavelength (optiland's paraxial uses its primary wavelength).
    for w in wavelengths_um:
        optic = build_optic(optiland, lens, catalogs, wavelengths_um, w, epd_floa)
        par = optic.paraxial
        positions = optic.surface_group.positions.ravel()
        t_last = float(positions[-1] - positions[-2])
        f2_point = float(par.F2())
        out["paraxial"].append({
            "wavelength_um": w,
            "EFL": float(par.f2()),
            "F2_from_image": f2_point,
            "BFL": f2_point + t_last,
            "EPL": float(par.EPL()),
            "EPD": float(par.EPD()),
            "XPL_from_image": float(par.XPL()),
        })

    # Real rays: the optic's primary is the file's (entrance pupil of the primary wavelength).
    import numpy as np

    optic = build_optic(optiland, lens, catalogs, wavelengths_um, primary_um, epd_floa)
    max_field = max(lens["fields_deg"]) if max(lens["fields_deg"]) > 0 else 1.0
    for w in wavelengths_um:
        for field in lens["fields_deg"]:
            hy = field / max_field
            for px, py in PUPIL_POINTS:
                rays = optic.trace_generic(Hx=0.0, Hy=hy, Px=np.array([px]), Py=np.array([py]),
                                           wavelength=w)
                x, y, z = float(rays.x[0]), float(rays.y[0]), float(rays.z[0])
                traced = all(math.isfinite(v) for v in (x, y, z))
                # At the primary wavelength, the chief and marginal rays' (x, y) on every lens
                # surface (SURF 1 .. N-1 of the file) as well.
                on_surfaces = None
                if traced and w == primary_um and abs(px) in (0.0, 1.0) and abs(py) in (0.0, 1.0):
                    group = optic.surface_group
                    on_surfaces = [[float(group.x[k][0]), float(group.y[k][0])]
                                   for k in range(1, group.num_surfaces - 1)]
                out["rays"].append({
                    "wavelength_um": w,
                    "field_deg": field,
                    "px": px,
                    "py": py,
                    "traced": traced,
                    "x": x if traced else None,
                    "y": y if traced else None,
                    "z": z if traced else None,
                    "L": float(rays.L[0]) if traced else None,
                    "M": float(rays.M[0]) if traced else None,
                    "N": float(rays.N[0]) if traced else None,
                })
                if on_surfaces is not None:
                    out["rays"][-1]["surfaces_xy"] = on_surfaces
    return out


def load_optiland(path):
    sys.path.insert(0, path)
    import numpy as np
    from optiland.materials import BaseMaterial
    from optiland.optic import Optic

    class TableMaterial(BaseMaterial):
        """Indices given per wavelength (um), as lensopt's glass data give them."""

        def __init__(self, table):
            self.table = dict(table)

        def _lookup(self, wavelength):
            w = np.atleast_1d(np.asarray(wavelength, dtype=float))
            values = np.array([self.table[min(self.table, key=lambda t: abs(t - v))]
                               for v in w.ravel()])
            for v in w.ravel():
                nearest = min(self.table, key=lambda t: abs(t - v))
                assert abs(nearest - v) < 1e-12, (v, nearest)
            return values.reshape(w.shape) if np.ndim(wavelength) else float(values[0])

        def n(self, wavelength):
            return self._lookup(wavelength)

        def k(self, wavelength):
            return 0.0 * np.asarray(wavelength, dtype=float)

    return {"Optic": Optic, "TableMaterial": TableMaterial}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--optiland", required=True, help="folder holding the optiland package")
    parser.add_argument("--optiland-commit", required=True)
    parser.add_argument("--optiland-note", default="",
                        help="how the optiland package at --optiland was obtained")
    parser.add_argument("--repo", default=".")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    optiland = load_optiland(args.optiland)
    lenses = [run_lens(optiland, args.repo, n, p, e) for n, p, e in LENSES]
    doc = {
        "source": "optiland (HarrisonKramer/optiland, MIT) run on this machine by "
                  "tests/data/independent/generate_optiland_rays.py",
        "optiland_commit": args.optiland_commit,
        "optiland_note": args.optiland_note,
        "date": datetime.date.today().isoformat(),
        "conventions": {
            "units": "mm; wavelengths in um",
            "glass": "indices from lensopt's catalogs/*.agf coefficients (Sellmeier 1) or "
                     "lensopt's model-glass formula for GLAS ___BLANK; air 1",
            "paraxial": "optiland's f2 (EFL), F2 (back focal point from the image surface), "
                        "EPL (from the first vertex), EPD, XPL (from the image surface), each "
                        "with that wavelength as optiland's primary; BFL = F2 + last thickness",
            "rays": "optiland's trace_generic, no ray aiming: collimated at the field angle, "
                    "through (Px EPD/2, Py EPD/2) on the paraxial entrance pupil plane z = EPL "
                    "of the primary wavelength; the file's vignetting factors and clear "
                    "apertures (DIAM) are not applied; (x, y) on the image surface, (L, M, N) "
                    "the direction cosines after it; surfaces_xy: (x, y) on the file's "
                    "SURF 1 .. N-1 (primary wavelength, chief and marginal rays)",
            "even_asphere": f"optiland's intersection iteration with tol {ASPHERE_TOL_MM} mm, "
                            f"max_iter {ASPHERE_MAX_ITER}",
            "floa": "EPD = stop semi-diameter / optiland's paraxial marginal-ray height at the "
                    "stop for EPD 1",
        },
        "relative_bound": 1e-9,
        "lenses": lenses,
    }
    with open(args.out, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
