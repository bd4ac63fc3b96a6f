"""The designer's reports from Python (issue 31): lensopt.prescription, chromatic_focal_shift,
lateral_colour, encircled_energy and field_sweep return what `lensopt analyze --prescription
--encircled-energy --json` writes, and the chromatic focal shift of a thin singlet is the
thin-lens hand computation f(F) - f(C) = -f / V."""

import json
import subprocess
import unittest

from support import EXECUTABLE, LENSES, lensopt

THIN_SINGLET = """
[lens]
name = "thin singlet"
[specs]
wavelengths_nm = [486.1327, 587.5618, 656.2725]
dispersion = "abbe"
[system]
mode = "as-written"
primary_wavelength_nm = 587.5618
aperture = "epd"
aperture_value = 10.0
field_type = "angle"
fields = [0.0, 1.0]
[[surfaces]]
radius_mm = inf
thickness_mm = 0.0
stop = true
[[surfaces]]
radius_mm = 100.0
thickness_mm = 0.02
material = { nd = 1.5168, vd = 64.17 }
[[surfaces]]
radius_mm = -107.5268817204301
thickness_mm = 90.0
"""


class ReportsMatchTheCli(unittest.TestCase):
    def test_cooke(self):
        path = LENSES / "zmx" / "cooke_triplet_50.zmx"
        out = subprocess.run([EXECUTABLE, "analyze", "--json", "--prescription",
                              "--encircled-energy", "--pupil-samples", "32", str(path)],
                             capture_output=True, text=True)
        self.assertEqual(out.returncode, 0, out.stderr)
        cli = json.loads(out.stdout)
        lens = lensopt.load_lens(str(path))
        self.assertEqual(lensopt.prescription(lens), cli["prescription"])
        self.assertEqual(lensopt.chromatic_focal_shift(lens), cli["chromatic_focal_shift"])
        self.assertEqual(lensopt.lateral_colour(lens), cli["lateral_colour"])
        ee = lensopt.encircled_energy(lens, pupil_samples=32)
        self.assertEqual(ee, cli["encircled_energy"])
        for field in ee["fields"]:
            self.assertLessEqual(field["geometric_r50_um"], field["geometric_r80_um"])
            self.assertAlmostEqual(field["geometric"][-1], 1.0, places=12)
        # The field sweep on analyze's own fields: analyze's RMS spot and distortion.
        sweep = lensopt.field_sweep(lens, fields=0, mtf=False)
        self.assertEqual(sweep["rms_spot_um"], cli["rms_spot_um"])
        self.assertEqual(sweep["distortion_percent"], cli["distortion_percent"])
        fine = lensopt.field_sweep(lens, fields=5, frequencies=[20.0], pupil_samples=32)
        self.assertEqual(len(fine["fields_deg"]), 5)
        self.assertEqual(len(fine["mtf_t"]), 1)
        self.assertTrue(all(0.0 <= v <= 1.0 for v in fine["mtf_t"][0] + fine["mtf_s"][0]))

    def test_thin_singlet_focal_shift(self):
        lens = lensopt.parse_lens(THIN_SINGLET)
        shift = lensopt.chromatic_focal_shift(lens)
        self.assertEqual(shift["wavelengths_nm"], [486.1327, 587.5618, 656.2725])
        # The model glass holds nd at the d line and nF - nC = (nd - 1) / vd.
        n_d, v = 1.5168, 64.17
        power = 1.0 / 100.0 + 1.0 / 107.5268817204301
        f_d = 1.0 / ((n_d - 1.0) * power)
        df_um = shift["shift_um"][0] - shift["shift_um"][2]
        # -f / V is the first order in the dispersion: the next term is of relative order
        # dn / (nd - 1) = 1 / V (the C++ test checks the exact thin-lens formula to 1e-5).
        self.assertLess(df_um, 0.0)
        self.assertAlmostEqual(df_um / (-f_d / v * 1e3), 1.0, delta=1.0 / v)
        with self.assertRaises(lensopt.LensoptError):
            lensopt.chromatic_focal_shift(lens, band=(700.0, 400.0))


if __name__ == "__main__":
    unittest.main()
