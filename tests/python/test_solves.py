"""Solves and variables from Python (issue 31 item 2): Surface.vary, pickup_curvature,
pickup_thickness and solve read and set on a loaded lens, Lens.apply_solves(), and
lensopt.optimize honouring them as `lensopt optimize` does."""

import tempfile
import unittest
from pathlib import Path

from support import LENSES, ROOT, lensopt

ACHROMAT_300 = ROOT / "tests" / "data" / "achromat_ac254_100_300mm.toml"
QUICK = dict(rings=6, fields=5, glass_search="none", max_iterations=15)


class Solves(unittest.TestCase):
    def test_read_set_and_round_trip(self):
        lens = lensopt.load_lens(str(ACHROMAT_300))
        s = lens.surfaces
        self.assertEqual(s[1].vary, [])
        self.assertIsNone(s[3].solve)
        s[1].vary = ["radius", "glass"]
        s[3].solve = {"thickness": "marginal_height", "height_mm": 0.0}
        s[2].pickup_thickness = {"surface": 2, "scale": 0.5, "offset_mm": 0.5}
        self.assertEqual(s[1].vary, ["radius", "glass"])
        self.assertEqual(s[3].solve, {"thickness": "marginal_height", "height_mm": 0.0})
        self.assertEqual(s[2].pickup_thickness, {"surface": 2, "scale": 0.5, "offset_mm": 0.5})
        written = s[3].thickness_mm
        lens.apply_solves()
        # The paraxial image of the 300 mm object lies ~50 mm behind the written 97.1 mm.
        self.assertGreater(lens.surfaces[3].thickness_mm, written + 20.0)
        self.assertEqual(lens.surfaces[2].thickness_mm, 0.5 * lens.surfaces[1].thickness_mm + 0.5)
        with tempfile.TemporaryDirectory() as tmp:
            for ext in ("toml", "zmx"):
                path = Path(tmp) / f"solves.{ext}"
                lensopt.save_lens(lens, str(path))
                back = lensopt.load_lens(str(path))
                self.assertEqual(back.surfaces[1].vary, ["radius", "glass"], ext)
                self.assertEqual(back.surfaces[3].solve, s[3].solve, ext)
                self.assertEqual(back.surfaces[2].pickup_thickness, s[2].pickup_thickness, ext)
                self.assertAlmostEqual(back.surfaces[3].thickness_mm,
                                       lens.surfaces[3].thickness_mm, delta=1e-9)
        with self.assertRaises(lensopt.LensoptError):
            s[1].vary = ["radious"]
        with self.assertRaises(lensopt.LensoptError):
            s[2].pickup_curvature = {"surface": 1, "offset_mm": 1.0}

    def test_optimize_keeps_a_pickup_and_reports_the_variables(self):
        lens = lensopt.load_lens(str(LENSES / "cooke.toml"))
        lens.surfaces[3].pickup_curvature = {"surface": 3, "scale": -1.0}
        lens.apply_solves()
        self.assertEqual(lens.surfaces[3].curvature_per_mm, -lens.surfaces[2].curvature_per_mm)
        result = lensopt.optimize(lens, **QUICK)
        self.assertFalse(result.kept_start)
        out = result.lens.surfaces
        self.assertEqual(out[3].curvature_per_mm, -out[2].curvature_per_mm)
        self.assertEqual(out[3].pickup_curvature, {"surface": 3, "scale": -1.0})
        self.assertTrue(any("picked up: c4 = -1 x c3" in line for line in result.log))


if __name__ == "__main__":
    unittest.main()
