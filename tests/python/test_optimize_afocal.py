"""An afocal lens optimizes from Python as from the CLI (issue 31, item 3): lensopt.optimize goes
through the same resolve_optimize_options and optimize_lens, so the shipped Keplerian telescope
gives the CLI's angular spot and keeps (or reaches) its angular magnification."""

import json
import subprocess
import tempfile
import unittest
from pathlib import Path

from support import EXECUTABLE, ROOT, lensopt

KEPLERIAN = ROOT / "tests" / "data" / "afocal" / "keplerian_telescope.zmx"
QUICK = dict(max_iterations=20)


class OptimizeAfocal(unittest.TestCase):
    def test_same_as_the_cli(self):
        lens = lensopt.load_lens(str(KEPLERIAN))
        py = lensopt.optimize(lens, targets=["angular_magnification=-5"], **QUICK)
        self.assertTrue(py.afocal)
        self.assertLess(py.final_angular_spot_mrad, 0.5 * py.start_angular_spot_mrad)
        self.assertEqual(py.start_spot_um, 0.0)  # no image plane
        row = py.targets[0]
        self.assertEqual((row["quantity"], row["bound"]), ("angular_magnification", -5.0))
        self.assertLessEqual(abs(row["final"] + 5.0), 1e-6)
        self.assertTrue(py.targets_pass)
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "out.toml"
            text = subprocess.run(
                [EXECUTABLE, "optimize", str(KEPLERIAN), "-o", str(out), "--json", "-q",
                 "--max-iterations", "20", "--target", "angular_magnification=-5"],
                check=True, capture_output=True, text=True).stdout
        cli = json.loads(text)
        self.assertTrue(cli["afocal"])
        self.assertEqual(py.final_angular_spot_mrad, cli["final_mean_rms_angular_spot_mrad"])
        self.assertEqual(py.final_field_angular_spot_mrad, cli["final_rms_angular_spot_mrad"])
        self.assertEqual(py.targets, cli["targets"])


if __name__ == "__main__":
    unittest.main()
