"""The consistency suite's Python side: lensopt.field_data, lensopt.spots and lensopt.psfs against
`lensopt analyze --json` on every lens the project ships or keeps as test data (the paper's and
others': real .zmx files of other projects, optiland's lenses). One field-optics product
(analysis/field_optics.h) computes them all, so they agree to the bit."""

import json
import subprocess
import unittest
import warnings

import numpy as np

from support import EXECUTABLE, LENSES, ROOT, lensopt

CORPUS = (sorted(LENSES.glob("*.toml")) + sorted((LENSES / "zmx").glob("*.zmx")) +
          sorted((ROOT / "tests" / "data" / "zmx-real").glob("*.zmx")) +
          sorted((ROOT / "tests" / "data" / "independent").glob("*.toml")))


def analyze_cli(path, rings, fields):
    out = subprocess.run([EXECUTABLE, "analyze", "--json", "--rings", str(rings), "--fields",
                          str(fields), str(path)], capture_output=True, text=True)
    if out.returncode != 0:
        return None, out.stderr
    return json.loads(out.stdout), ""


class FieldDataMatchesAnalyze(unittest.TestCase):
    def test_corpus(self):
        checked = 0
        for path in CORPUS:
            with self.subTest(lens=path.name):
                expected, why = analyze_cli(path, 8, 7)
                if expected is None:
                    # Refused by the CLI with a message: Python must refuse it too.
                    with self.assertRaises(Exception), warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        lensopt.field_data(lensopt.load_lens(str(path)), rings=8, fields=7)
                    continue
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    lens = lensopt.load_lens(str(path))
                data = lensopt.field_data(lens, rings=8, fields=7)
                spots = lensopt.spots(lens, rings=8, fields=7)
                self.assertEqual(data["fields_deg"], expected["fields_deg"])
                self.assertEqual(data["field_values"], expected["field_values"])
                self.assertEqual(data["centroid_y_mm"], expected["centroid_y_mm"])
                # None where the CLI writes null (an edge ray fails): never a made-up 0.
                self.assertEqual(data["relative_illumination"], expected["relative_illumination"])
                self.assertEqual([100.0 * d for d in data["distortion"]],
                                 expected["distortion_percent"])
                self.assertEqual(spots["rms_spot_um"], expected["rms_spot_um"])
                self.assertEqual(spots["failed_rays"], expected["ray_failures_per_field"])
                if all(n > 0 for n in spots["traced_rays"]):
                    psf = lensopt.psfs(lens, rings=8, fields=7, grid_size=33)
                    self.assertEqual(psf["centroid_y_mm"], expected["centroid_y_mm"])
                    # Each channel sums to 1, or to 0 where its whole spot is outside the grid.
                    sums = psf["psf"].sum(axis=(2, 3))
                    self.assertTrue(np.all((np.abs(sums - 1.0) < 1e-12) | (sums == 0.0)), sums)
                checked += 1
        self.assertGreaterEqual(checked, 20)


if __name__ == "__main__":
    unittest.main()
