#!/usr/bin/env python3
"""Perturbed starting points for the optimizer's acceptance runs (issue 3).

Every curvature and every thickness of a baseline lens is multiplied by its own factor drawn
uniformly from [0.9, 1.1] (Python's random.Random(seed)); glasses, stop and specs are kept.
Writes lenses/starts/<lens>-seed<N>.toml. Usage: tools/make-starts.py [seeds...] (default 1-5).
"""
import random
import sys
import tomllib
from pathlib import Path

root = Path(__file__).resolve().parent.parent
seeds = [int(s) for s in sys.argv[1:]] or [1, 2, 3, 4, 5]


def number(v):
    return repr(float(v))


for name in ("doublet", "cooke", "tessar"):
    lens = tomllib.loads((root / "lenses" / f"{name}.toml").read_text())
    for seed in seeds:
        rng = random.Random(seed)
        out = [f"# {name} baseline with every curvature and thickness scaled by a factor drawn",
               f"# uniformly from [0.9, 1.1] with Python random.Random({seed}) (tools/make-starts.py).",
               "[lens]", f'name = "{lens["lens"]["name"]} (perturbed, seed {seed})"',
               f'catalog = "{lens["lens"].get("catalog", "ohara")}"', "", "[specs]"]
        for key, value in lens.get("specs", {}).items():
            out.append(f"{key} = {value!r}".replace("'", '"'))
        for s in lens["surfaces"]:
            out += ["", "[[surfaces]]"]
            if "curvature_per_mm" in s:
                c = s["curvature_per_mm"]
            else:
                r = s["radius_mm"]
                c = 0.0 if isinstance(r, str) or r == float("inf") else 1.0 / r
            factor_c = rng.uniform(0.9, 1.1)
            factor_t = rng.uniform(0.9, 1.1)
            c *= factor_c
            out.append(f"curvature_per_mm = {number(c)}")
            out.append(f"thickness_mm = {number(s['thickness_mm'] * factor_t)}")
            if "material" in s:
                m = s["material"]
                out.append(f'material = "{m}"' if isinstance(m, str) else
                           f"material = {{ nd = {m['nd']!r}, vd = {m['vd']!r} }}")
            if s.get("stop"):
                out.append("stop = true")
        (root / "lenses" / "starts" / f"{name}-seed{seed}.toml").write_text("\n".join(out) + "\n")
        print(f"lenses/starts/{name}-seed{seed}.toml")
