"""Design targets from Python: lensopt.optimize(targets=..., focus_only=...) resolves them as
`lensopt optimize --target` does (one resolve_optimize_options), and reports them as the CLI."""

import json
import math
import subprocess
import tempfile
import unittest
from pathlib import Path

from support import EXECUTABLE, ROOT, lensopt

# The AC254-100 achromat at a 300 mm object (tests/data; lenses/zmx/achromat_ac254_100.zmx with
# [system] object_distance_mm = 300).
ACHROMAT_300 = ROOT / "tests" / "data" / "achromat_ac254_100_300mm.toml"
QUICK = dict(rings=6, fields=5, glass_search="none", max_iterations=15)


def paraxial_efl(lens):
    return lensopt.analyze(lens).efl_mm


class OptimizeTargets(unittest.TestCase):
    def test_achromat_keeps_or_reaches_its_focal_length(self):
        lens = lensopt.load_lens(str(ACHROMAT_300))
        efl = paraxial_efl(lens)
        self.assertGreater(efl, 99.0)
        kept = lensopt.optimize(lens, **QUICK)
        self.assertLessEqual(abs(paraxial_efl(kept.lens) - efl), 1e-6)
        self.assertLess(kept.final_spot_um, kept.start_spot_um)
        row = kept.targets[0]
        self.assertEqual(row["quantity"], "efl_mm")
        self.assertTrue(row["default"])
        self.assertTrue(row["pass"])
        self.assertTrue(kept.targets_pass)

        to90 = lensopt.optimize(lens, targets=["efl_mm=90"], **QUICK)
        self.assertLessEqual(abs(paraxial_efl(to90.lens) - 90.0), 1e-6)
        self.assertLess(to90.final_spot_um, to90.start_spot_um)
        row = to90.targets[0]
        self.assertEqual((row["quantity"], row["relation"], row["bound"]), ("efl_mm", "=", 90.0))
        self.assertFalse(row["start_pass"])
        self.assertAlmostEqual(row["start"], efl, delta=1e-9)
        self.assertTrue(row["pass"])

    def test_same_as_the_cli(self):
        lens = lensopt.load_lens(str(ACHROMAT_300))
        py = lensopt.optimize(lens, targets=["efl_mm=95", "total_track_mm<=150"], **QUICK)
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "out.toml"
            text = subprocess.run(
                [EXECUTABLE, "optimize", str(ACHROMAT_300), "-o", str(out), "--json", "-q",
                 "--rings", "6", "--fields", "5", "--glass-search", "none",
                 "--max-iterations", "15", "--target", "efl_mm=95",
                 "--target", "total_track_mm<=150"],
                check=True, capture_output=True, text=True).stdout
        cli = json.loads(text)
        self.assertEqual(py.targets, cli["targets"])
        self.assertEqual(py.final_spot_um, cli["final_mean_rms_spot_um"])

    def test_focus_only_and_bad_targets(self):
        lens = lensopt.load_lens(str(ACHROMAT_300))
        focus = lensopt.optimize(lens, focus_only=True, **QUICK)
        self.assertGreater(focus.iterations, 0)
        self.assertLess(focus.final_spot_um, 0.5 * focus.start_spot_um)
        for a, b in zip(focus.lens.surfaces[:-1], lens.surfaces[:-1]):
            self.assertTrue(math.isclose(a.thickness_mm, b.thickness_mm, rel_tol=1e-9))
        with self.assertRaises(lensopt.LensoptError) as caught:
            lensopt.optimize(lens, targets=["focal=100"], **QUICK)
        self.assertIn("unknown target quantity 'focal'", str(caught.exception))


if __name__ == "__main__":
    unittest.main()
