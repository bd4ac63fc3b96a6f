#!/usr/bin/env python3
"""Writes lensopt's catalogs made from the refractiveindex.info database (CC0) into catalogs/.

Usage: tools/make-rii-catalogs.py [RII_DIR] [OUT_DIR]
  RII_DIR  the database's data folder (default ../shared/data/rii): specs/, main/, glass/
  OUT_DIR  where the catalogs go (default catalogs/ next to this script's folder)

Catalogs (file, what, from):
  HIKARI.agf     Hikari (Nikon) J-, E-, Q- glasses, Nikon fused silica (NIFS) and CaF2 (NICF):
                 specs/hikari/{optical,SiO2,CaF}
  SUMITA.agf     Sumita K- glasses: specs/sumita/optical
  LZOS.agf       LZOS glasses (tabulated indices), named LZ_<name> as OpticStudio's LZOS catalog:
                 specs/lzos/optical
  LIGHTPATH.agf  LightPath infrared glasses (tabulated): specs/lightpath/infrared
  CORNING.agf    C79-80 (Corning 7980 fused silica, Malitson), EAGLEXG (tabulated)
  INFRARED.agf   crystals and infrared glasses under OpticStudio's INFRARED names
  MISC.agf       fused silica, crystals and common glasses under OpticStudio's MISC names
Zemax catalog names map to these files in src/glass/catalog.cpp (NIKON-HIKARI -> HIKARI, ...).

The output is AGF in lensopt's normalized form (ASCII, LF): per glass
  NM name formula MIL nd vd 0 status
  GC source: <database path>; <reference>
  CD C1 C2 ...       the database's coefficients verbatim (formula ids 101..109 = its formula 1..9,
                     glass/formulas.h), or l1 n1 l2 n2 ... for tabulated n (formula id 120)
  LD min_um max_um   the data's wavelength range
nd and vd are the vendor's (PROPERTIES/SPECS nd, Vd) where the data gives them; otherwise computed
from the formula at 587.5618, 486.1327 and 656.2725 nm (the test compares the two where both exist).
Regenerate rather than edit; tests/e2e/rii_catalogs.sh checks the files are this script's output.
"""

import hashlib
import math
import pathlib
import re
import sys

import yaml

D_UM, F_UM, C_UM = 0.5875618, 0.4861327, 0.6562725

# Catalog -> list of (name in the catalog, database path relative to RII_DIR).
CRYSTALS_INFRARED = [
    ("GERMANIUM", "main/Ge/nk/Burnett.yml"),
    ("SILICON", "main/Si/nk/Salzberg.yml"),
    ("ZNSE", "main/ZnSe/nk/Connolly.yml"),
    ("ZNS", "main/ZnS/nk/Debenham.yml"),
    ("CAF2", "main/CaF2/nk/Malitson.yml"),
    ("BAF2", "main/BaF2/nk/Malitson.yml"),
    ("MGF2", "main/MgF2/nk/Dodge-o.yml"),
    ("SAPPHIRE", "main/Al2O3/nk/Malitson-o.yml"),
    ("F_SILICA", "main/SiO2/nk/Malitson.yml"),
    ("CSI", "main/CsI/nk/Li.yml"),
    ("KBR", "main/KBr/nk/Li.yml"),
    ("NACL", "main/NaCl/nk/Li.yml"),
    ("LIF", "main/LiF/nk/Li.yml"),
    ("AMTIR1", "specs/ami/infrared/AMTIR-1.yml"),
    ("AMTIR2", "specs/ami/infrared/AMTIR-2.yml"),
    ("AMTIR3", "specs/ami/infrared/AMTIR-3.yml"),
    ("AMTIR6", "specs/ami/infrared/AMTIR-6.yml"),
    ("IG2", "specs/vitron/infrared/IG2.yml"),
    ("IG3", "specs/vitron/infrared/IG3.yml"),
    ("IG4", "specs/vitron/infrared/IG4.yml"),
    ("IG5", "specs/vitron/infrared/IG5.yml"),
    ("IG6", "specs/vitron/infrared/IG6.yml"),
]
MISC = [
    ("F_SILICA", "main/SiO2/nk/Malitson.yml"),
    ("SILICA", "main/SiO2/nk/Malitson.yml"),
    ("CAF2", "main/CaF2/nk/Malitson.yml"),
    ("BAF2", "main/BaF2/nk/Malitson.yml"),
    ("MGF2", "main/MgF2/nk/Dodge-o.yml"),
    ("SAPPHIRE", "main/Al2O3/nk/Malitson-o.yml"),
    ("LIF", "main/LiF/nk/Li.yml"),
    ("ZNSE", "main/ZnSe/nk/Connolly.yml"),
    ("ZNS", "main/ZnS/nk/Debenham.yml"),
    ("GERMANIUM", "main/Ge/nk/Burnett.yml"),
    ("SILICON", "main/Si/nk/Salzberg.yml"),
    ("SODA_LIME", "glass/misc/soda-lime/nk/Rubin-clear.yml"),
    ("ZBLAN", "glass/misc/ZBLAN/nk/Gan.yml"),
    ("BGG", "glass/misc/BGG/nk/Zelmon.yml"),
]
CORNING = [
    ("C79-80", "main/SiO2/nk/Malitson.yml"),
    ("EAGLEXG", "specs/corning/EagleXG.yml"),
]


def folder(sub: str, prefix: str = ""):
    """Every .yml of a database folder, named prefix + file stem, in name order."""
    return lambda root: [(prefix + p.stem, str(p.relative_to(root)))
                         for p in sorted((root / sub).glob("*.yml"))]


CATALOGS = [
    ("HIKARI", "Hikari (Nikon) glasses", lambda r: folder("specs/hikari/optical")(r)
     + folder("specs/hikari/SiO2")(r) + folder("specs/hikari/CaF")(r)),
    ("SUMITA", "Sumita glasses", folder("specs/sumita/optical")),
    # OpticStudio's LZOS catalog names them LZ_<name> (real files: GCAT LZOS, GLAS LZ_K8).
    ("LZOS", "LZOS glasses", folder("specs/lzos/optical", "LZ_")),
    ("LIGHTPATH", "LightPath infrared glasses", folder("specs/lightpath/infrared")),
    ("CORNING", "Corning glasses", lambda r: CORNING),
    ("INFRARED", "crystals and infrared materials", lambda r: CRYSTALS_INFRARED),
    ("MISC", "fused silica, crystals and common glasses", lambda r: MISC),
]


def short(value: float) -> str:
    if value == 0.0:
        return "0"
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def numbers(text) -> list:
    return [float(x) for x in str(text).split()]


def formula_index(fid: int, c: list, l: float) -> float:
    """The database's formulas (glass/formulas.h states them; this mirrors it for nd, vd)."""
    C = lambda i: c[i - 1] if i <= len(c) else 0.0  # noqa: E731
    pairs = lambda first: [(c[i - 1], c[i]) for i in range(first, len(c), 2)]  # noqa: E731
    l2 = l * l
    if fid == 101:
        return math.sqrt(1 + C(1) + sum(b * l2 / (l2 - s * s) for b, s in pairs(2)))
    if fid == 102:
        return math.sqrt(1 + C(1) + sum(b * l2 / (l2 - s) for b, s in pairs(2)))
    if fid == 103:
        return math.sqrt(C(1) + sum(b * l**e for b, e in pairs(2)))
    if fid == 104:
        n2 = C(1)
        if len(c) >= 5:
            n2 += C(2) * l ** C(3) / (l2 - C(4) ** C(5))
        if len(c) >= 9:
            n2 += C(6) * l ** C(7) / (l2 - C(8) ** C(9))
        n2 += sum(b * l**e for b, e in pairs(10))
        return math.sqrt(n2)
    if fid == 105:
        return C(1) + sum(b * l**e for b, e in pairs(2))
    if fid == 107:
        big = 1 / (l2 - 0.028)
        return C(1) + C(2) * big + C(3) * big * big + C(4) * l2 + C(5) * l2**2 + C(6) * l2**3
    if fid == 120:
        ls, ns = c[0::2], c[1::2]
        if l in ls:
            return ns[ls.index(l)]
        upper = next((i for i, x in enumerate(ls) if x >= l), len(ls))
        lo = max(0, min(upper - 2, len(ls) - 4))
        idx = range(lo, min(lo + 4, len(ls)))
        n = 0.0
        for a in idx:
            w = 1.0
            for b in idx:
                if a != b:
                    w *= (l - ls[b]) / (ls[a] - ls[b])
            n += w * ns[a]
        return n
    raise ValueError(f"formula {fid} not handled")


def read_glass(root: pathlib.Path, rel: str):
    data = yaml.safe_load((root / rel).read_text(encoding="utf-8"))
    entry = None
    for d in data.get("DATA", []):
        t = d["type"]
        m = re.fullmatch(r"formula (\d)", t)
        if m:
            fid = 100 + int(m.group(1))
            coeffs = numbers(d["coefficients"])
            lo, hi = numbers(d["wavelength_range"])
            entry = (fid, coeffs, lo, hi)
            break
        if t in ("tabulated n", "tabulated nk"):
            # Sorted by wavelength: a few files list two rows out of order (LZOS CTK8, OF1).
            rows = sorted(numbers(r) for r in str(d["data"]).strip().splitlines())
            coeffs = []
            for r in rows:
                coeffs += [r[0], r[1]]
            entry = (120, coeffs, rows[0][0], rows[-1][0])
            break
    if entry is None:
        return None
    props = data.get("PROPERTIES") or data.get("SPECS") or {}
    nd = props.get("nd")
    vd = props.get("Vd")
    status = 2 if "obsolete" in rel else 0
    if props.get("glass_status") == "preferred":
        status = 1
    refs = re.sub(r"<[^>]+>", "", re.sub(r"<br\s*/?>", " ", str(data.get("REFERENCES", "")))).split("\n")
    ref = " ".join(x.strip() for x in refs if x.strip())
    return {"formula": entry[0], "cd": entry[1], "ld": (entry[2], entry[3]), "nd": nd, "vd": vd,
            "status": status, "ref": ref}


def make(root: pathlib.Path, out_dir: pathlib.Path, name: str, what: str, members) -> int:
    lines = [
        f"CC lensopt glass catalog {name}: {what}.",
        "CC Generated by tools/make-rii-catalogs.py from the refractiveindex.info database (CC0 1.0),",
        "CC polyanskiy/refractiveindex.info-database folder database/data; each glass's GC line",
        "CC names its file and reference. Formula ids 101..109 are the database's formulas 1..9,",
        "CC 120 tabulated n (lensopt's extension of AGF, glass/formulas.h). Regenerate, do not edit.",
    ]
    count = 0
    for glass_name, rel in members:
        g = read_glass(root, rel)
        if g is None:
            print(f"{name}: {rel}: no formula or tabulated n; left out", file=sys.stderr)
            continue
        lo, hi = g["ld"]
        nd, vd = g["nd"], g["vd"]
        if nd is None or vd is None:
            if lo <= F_UM and hi >= C_UM:
                n_d = formula_index(g["formula"], g["cd"], D_UM)
                n_f = formula_index(g["formula"], g["cd"], F_UM)
                n_c = formula_index(g["formula"], g["cd"], C_UM)
                nd, vd = round(n_d, 6), round((n_d - 1) / (n_f - n_c), 4)
            else:
                # An infrared material: nd and vd are not defined in its range; 0 = none.
                nd, vd = 0.0, 0.0
        digest = hashlib.sha256((root / rel).read_bytes()).hexdigest()[:16]
        mil = round(1000 * (nd - 1)) * 1000 + round(10 * vd) if nd > 0 else 0
        lines.append(f"NM {glass_name} {g['formula']} {mil} {short(nd)} {short(vd)} 0 {g['status']}")
        ref = g["ref"].encode("ascii", "replace").decode("ascii")
        lines.append(f"GC source: {rel} (sha256 {digest}); {ref}"[:400])
        lines.append("CD " + " ".join(short(x) for x in g["cd"]))
        lines.append(f"LD {short(lo)} {short(hi)}")
        count += 1
    lines[0] = f"CC lensopt glass catalog {name}: {what}, {count} glasses."
    text = "\n".join(lines) + "\n"
    (out_dir / f"{name}.agf").write_text(text, encoding="ascii", newline="\n")
    return count


def main() -> int:
    root_dir = pathlib.Path(__file__).resolve().parent.parent
    rii = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else root_dir.parent / "shared/data/rii"
    out_dir = pathlib.Path(sys.argv[2]) if len(sys.argv) > 2 else root_dir / "catalogs"
    if not (rii / "specs").is_dir():
        print(f"no refractiveindex.info data in {rii}", file=sys.stderr)
        return 1
    for name, what, members in CATALOGS:
        count = make(rii, out_dir, name, what, members(rii))
        print(f"{name}: {count} glasses -> {out_dir / (name + '.agf')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
