"""Python and the CLI resolve the same options the same way (issue 29).

lensopt.optimize used the paper's bounds on every lens where `lensopt optimize` derives bounds
for an as-written lens (the double Gauss .zmx kept its start in Python after a 373 um soft phase,
and reached 6.67 um from the CLI); analyze(wave=True) sampled 64 pupil cells against the CLI's
128; tolerance ignored the lens's [tolerance] distribution, compensator and seed. Each entry
point now resolves its defaults with the CLI's function (optimize/optimizer.h
resolve_optimize_options, tolerance.h tolerance_options_for, AnalyzeOptions), and these tests
hold the numbers equal.
"""

import json
import math
import subprocess
import tempfile
import unittest
import warnings
from pathlib import Path

from support import EXECUTABLE, LENSES, lensopt


def load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return lensopt.load_lens(str(path))


def cli_json(*args):
    run = subprocess.run([EXECUTABLE, *map(str, args)], capture_output=True, text=True)
    if run.returncode != 0:
        raise AssertionError(f"lensopt {' '.join(map(str, args))}: exit {run.returncode}\n"
                             f"{run.stderr}")
    return json.loads(run.stdout)


def same(a, b):
    """Equal to the bit, or within 1e-12 relative (the same code on the same thread count)."""
    return a == b or abs(a - b) <= 1e-12 * max(1.0, abs(a), abs(b))


class OptimizeMatchesCli(unittest.TestCase):
    def test_double_gauss_zmx_defaults(self):
        path = LENSES / "zmx" / "double_gauss_100.zmx"
        with tempfile.TemporaryDirectory() as tmp:
            expected = cli_json("optimize", path, "-o", Path(tmp) / "dg.toml", "--json", "-q")
        result = lensopt.optimize(load(path))
        self.assertEqual(expected["bounds"]["mode"], "lens")
        self.assertFalse(expected["kept_start"])
        # The defect was Python keeping the start (373 um soft phase, -4.24 mm glass) where the
        # CLI improves it: the CLI must improve the design, and Python must equal it. (With the
        # .zmx's model glasses on OpticStudio's model, issue 30, the start is 7.92 um and the
        # design, on catalog glasses, 7.70 um; on the paper's model it was 8.54 -> 6.67 um.)
        self.assertLess(expected["final_mean_rms_spot_um"], expected["start_mean_rms_spot_um"])
        self.assertEqual(result.kept_start, expected["kept_start"])
        self.assertEqual(result.iterations, expected["iterations"])
        self.assertEqual(result.loss_evaluations, expected["loss_evaluations"])
        self.assertEqual(list(result.glasses), expected["glasses"])
        self.assertTrue(same(result.start_spot_um, expected["start_mean_rms_spot_um"]),
                        (result.start_spot_um, expected["start_mean_rms_spot_um"]))
        self.assertTrue(same(result.final_spot_um, expected["final_mean_rms_spot_um"]),
                        (result.final_spot_um, expected["final_mean_rms_spot_um"]))
        for ours, theirs in zip(result.final_field_spot_um, expected["final_rms_spot_um"],
                                strict=True):
            self.assertTrue(same(ours, theirs), (ours, theirs))
        self.assertTrue(result.constraints_pass)

    def test_paper_bounds_on_request(self):
        # bounds="paper" is `--bounds paper`; a short run of both with the same overrides.
        path = LENSES / "cooke.toml"
        args = dict(max_iterations=3, max_rounds=1, rings=4, fields=3)
        with tempfile.TemporaryDirectory() as tmp:
            expected = cli_json("optimize", path, "-o", Path(tmp) / "c.toml", "--json", "-q",
                                "--bounds", "lens", "--max-iterations", 3, "--rings", 4,
                                "--fields", 3, "--constraints", "paper")
        result = lensopt.optimize(load(path), bounds="lens", paper_penalties=True,
                                  max_iterations=3, rings=4, fields=3)
        self.assertEqual(expected["bounds"]["mode"], "lens")
        self.assertEqual(result.iterations, expected["iterations"])
        self.assertTrue(same(result.final_spot_um, expected["final_mean_rms_spot_um"]))
        with self.assertRaisesRegex(lensopt.LensoptError, "bounds"):
            lensopt.optimize(load(path), bounds="loose", **args)


class AnalyzeWaveMatchesCli(unittest.TestCase):
    def test_wave_numbers_identical_with_defaults(self):
        path = LENSES / "cooke.toml"
        expected = cli_json("analyze", path, "--wave", "--json", "--rings", 8, "--fields", 3)
        report = lensopt.analyze(load(path), wave=True, rings=8, fields=3)
        ours = report.to_dict()
        self.assertEqual(ours["wave"]["pupil_samples"], 128)
        self.assertEqual(ours["wave"], expected["wave"])
        self.assertEqual(ours, expected)

    def test_mode_as_written(self):
        path = LENSES / "zmx" / "double_gauss_100.zmx"
        expected = cli_json("analyze", path, "--json", "--rings", 4, "--mode", "paper")
        self.assertEqual(lensopt.analyze(load(path), rings=4, mode="paper").to_dict(), expected)


class ToleranceMatchesCli(unittest.TestCase):
    def test_tolerance_table_applies_in_python(self):
        text = (LENSES / "cooke.toml").read_text()
        text += ('\n[tolerance]\ndistribution = "normal"\ncompensator = "none"\nseed = 7\n'
                 'trials = 12\nmax_spot_um = 40\n')
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "cooke-tol.toml"
            path.write_text(text)
            expected = cli_json("tolerance", path, "--json", "--rings", 4, "--fields", 3,
                                "--no-sensitivity", "-q", "--threads", 2)
            report = lensopt.tolerance(load(path), rings=4, fields=3, sensitivity=False, jobs=2)
        ours = report.to_dict()
        self.assertEqual(len(report.trial_spots_um), 12)
        self.assertEqual((ours["seed"], ours["trials"], ours["distribution"], ours["compensator"]),
                         (7, 12, "normal", "none"))
        # Everything but the wall times.
        del ours["timing"], expected["timing"]
        self.assertEqual(ours, expected)
        self.assertFalse(any(math.isnan(s) for s in report.trial_spots_um))

    def test_surface_tolerances_and_inverse_sensitivity(self):
        # The options of docs/tolerance.md: Python's tolerances= and inverse_drop_um= are the
        # CLI's --surface-tilt-arcmin, --decenter-mm and --inverse-drop-um.
        path = LENSES / "cooke.toml"
        expected = cli_json("tolerance", path, "--json", "--rings", 4, "--fields", 2,
                            "--trials", 3, "-q", "--threads", 2, "--surface-tilt-arcmin", 1,
                            "--decenter-mm", 0.01, "--inverse-drop-um", 2)
        report = lensopt.tolerance(load(path), rings=4, fields=2, trials=3, jobs=2,
                                   tolerances={"surface_tilt_arcmin": 1, "decenter_mm": 0.01},
                                   inverse_drop_um=2)
        ours = report.to_dict()
        del ours["timing"], expected["timing"]
        self.assertEqual(ours, expected)
        self.assertTrue(any(row["parameter"].startswith("tstx") for row in ours["sensitivity"]))
        self.assertTrue(all(row["inverse_limit"] is not None for row in ours["sensitivity"]))
        with self.assertRaisesRegex(lensopt.LensoptError, "unknown tolerance"):
            lensopt.tolerance(load(path), trials=1, tolerances={"wedge": 1})


if __name__ == "__main__":
    unittest.main()
