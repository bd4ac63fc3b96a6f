"""An afocal lens analysed from Python is measured in angle, as `lensopt analyze` measures it, and
every Python function that measures an image plane refuses it by name.

Before this, lensopt.analyze on the shipped Keplerian telescope returned an AnalysisReport with an
EFL of 1.4e17 mm and RMS "spots" of about 1670 um on an image plane the lens does not have: a
false figure at no error. A lens that forms no image at all (afocal, but not flagged) now raises,
as the CLI exits 1 for it."""

import json
import subprocess
import tempfile
import unittest
from pathlib import Path

from support import EXECUTABLE, ROOT, lensopt

KEPLERIAN = ROOT / "tests" / "data" / "afocal" / "keplerian_telescope.zmx"


def keplerian():
    return lensopt.load_lens(str(KEPLERIAN))


class AfocalAnalysis(unittest.TestCase):
    def test_analyze_is_the_clis_afocal_report(self):
        report = lensopt.analyze(keplerian(), threads=1)
        self.assertIsInstance(report, lensopt.AfocalReport)
        cli = subprocess.run([EXECUTABLE, "analyze", str(KEPLERIAN), "--json", "--threads", "1"],
                             check=True, capture_output=True, text=True).stdout
        # The same serializer on the same numbers: the same JSON, key for key.
        self.assertEqual(report.to_dict(), json.loads(cli))
        # The paraxial M = -f1 / f2 of the telescope (test_afocal's reference): -4.
        self.assertAlmostEqual(report.angular_magnification, -4.0, places=9)
        self.assertEqual(report.first_order.angular_magnification, report.angular_magnification)
        self.assertGreater(report.mean_rms_angular_spot_mrad, 0.0)
        weights = [f.weight for f in report.fields]
        mean = sum(f.weight * f.rms_angular_spot_mrad for f in report.fields) / sum(weights)
        self.assertAlmostEqual(report.mean_rms_angular_spot_mrad, mean, delta=1e-12 * mean)
        self.assertIn("angular magnification", report.to_text())

    def test_analyze_agrees_with_optimize(self):
        # The figure optimize reports for its result is analyze's (one implementation).
        lens = keplerian()
        result = lensopt.optimize(lens, max_iterations=5)
        self.assertTrue(result.afocal)
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "k.toml"
            lensopt.save_lens(result.lens, str(out))
            after = lensopt.analyze(lensopt.load_lens(str(out)))
        self.assertAlmostEqual(after.mean_rms_angular_spot_mrad, result.final_angular_spot_mrad,
                               delta=1e-9 * result.final_angular_spot_mrad)

    def test_image_plane_functions_refuse_it(self):
        lens = keplerian()
        calls = {
            "lensopt.spots": lambda: lensopt.spots(lens),
            "lensopt.psfs": lambda: lensopt.psfs(lens),
            "lensopt.field_data": lambda: lensopt.field_data(lens),
            "lensopt.prescription": lambda: lensopt.prescription(lens),
            "lensopt.chromatic_focal_shift": lambda: lensopt.chromatic_focal_shift(lens),
            "lensopt.lateral_colour": lambda: lensopt.lateral_colour(lens),
            "lensopt.encircled_energy": lambda: lensopt.encircled_energy(lens),
            "lensopt.field_sweep": lambda: lensopt.field_sweep(lens),
            "lensopt.tolerance": lambda: lensopt.tolerance(lens, trials=2),
            "render": lambda: lensopt.Renderer(lens),
            "joint image formation": lambda: lensopt.Imaging(lensopt.Parameterization(lens)),
        }
        for name, call in calls.items():
            with self.subTest(name):
                with self.assertRaises(lensopt.LensoptError) as caught:
                    call()
                message = str(caught.exception)
                self.assertIn(name, message)
                self.assertIn("cannot take an afocal lens", message)
                self.assertIn("keplerian_telescope.zmx", message)
        with self.assertRaises(lensopt.LensoptError) as caught:
            lensopt.analyze(lens, mtf_frequencies=[10.0])
        self.assertIn("mtf_frequencies does not apply to an afocal lens", str(caught.exception))

    def test_a_lens_without_an_image_raises(self):
        # The same telescope without the afocal flag: no finite focal length, so no image plane
        # to measure spots on. The CLI exits 1 (check_forms_image); Python raises the same text.
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "unflagged.toml"
            lensopt.save_lens(keplerian(), str(path))
            toml = path.read_text()
            self.assertIn("afocal = true", toml)
            path.write_text(toml.replace("afocal = true", "afocal = false"))
            lens = lensopt.load_lens(str(path))
            with self.assertRaises(lensopt.LensoptError) as caught:
                lensopt.analyze(lens)
            cli = subprocess.run([EXECUTABLE, "analyze", str(path)], capture_output=True,
                                 text=True)
        self.assertIn("it is afocal", str(caught.exception))
        self.assertNotEqual(cli.returncode, 0)
        self.assertIn("it is afocal", cli.stderr)


if __name__ == "__main__":
    unittest.main()
