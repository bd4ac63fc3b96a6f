"""Python on par with the CLI (issue 31, item 7): system data editable on a loaded lens, paths as
str or pathlib.Path, FileNotFoundError for a missing file, lenses and ImageFormation copied and
pickled, tolerance(threads=)."""

import copy
import math
import pickle
import tempfile
import unittest
from pathlib import Path

from support import HAVE_TORCH, LENSES, ROOT, lensopt

if HAVE_TORCH:
    import torch

    import lensopt.torch as lt

ACHROMAT = LENSES / "zmx" / "achromat_ac254_100.zmx"


def quiet_analyze(lens):
    return lensopt.analyze(lens, rings=6)


class SystemData(unittest.TestCase):
    def setUp(self):
        self.lens = lensopt.load_lens(ACHROMAT)  # a pathlib.Path

    def test_f_number_takes_effect_on_a_zmx(self):
        # The .zmx has ENPD; f_number used to be kept and silently ignored.
        before = quiet_analyze(self.lens)
        self.assertEqual(self.lens.specs.mode, "as-written")
        self.assertEqual(self.lens.specs.aperture, "epd")
        self.lens.specs.f_number = 2 * before.f_number
        self.assertEqual(self.lens.specs.aperture, "f-number")
        after = quiet_analyze(self.lens)
        self.assertAlmostEqual(after.f_number, 2 * before.f_number, places=9)
        self.assertAlmostEqual(after.epd_mm, before.epd_mm / 2, places=9)
        self.assertNotEqual(after.mean_rms_spot_um, before.mean_rms_spot_um)

    def test_aperture_fields_object_wavelengths(self):
        s = self.lens.specs
        s.aperture = "epd"
        s.aperture_value = 10.0
        self.assertAlmostEqual(quiet_analyze(self.lens).epd_mm, 10.0, places=12)
        s.fields = [0.0, lensopt.FieldPoint(1.5, 2.0)]
        r = quiet_analyze(self.lens)
        self.assertEqual([f.field_deg for f in r.fields], [0.0, 1.5])
        self.assertEqual([f.value for f in s.fields], [0.0, 1.5])
        self.assertEqual(s.half_field_deg, 1.5)
        s.object_distance_mm = 300.0
        r = quiet_analyze(self.lens)
        self.assertEqual(r.object_distance_mm, 300.0)
        s.object_distance_mm = math.inf
        s.wavelengths_nm = [486.1, 587.6, 656.3, 550.0]
        self.assertEqual(len(s.wavelength_channels), 4)
        s.primary_wavelength_nm = 550.0
        self.assertEqual(quiet_analyze(self.lens).primary_wavelength_nm, 550.0)
        # The edits survive a TOML round trip.
        back = lensopt.parse_lens(self.lens.to_toml())
        self.assertEqual(back.specs.aperture_value, 10.0)
        self.assertEqual([f.weight for f in back.specs.fields], [1.0, 2.0])

    def test_values_a_mode_would_not_trace_raise(self):
        with self.assertRaises(lensopt.LensoptError):
            self.lens.specs.half_field_deg = 3.0  # the fields are written: set specs.fields
        with self.assertRaises(lensopt.LensoptError):
            self.lens.specs.aperture = "f-stop"
        with self.assertRaises(lensopt.LensoptError):
            self.lens.specs.object_distance_mm = -5.0
        paper = lensopt.load_lens(LENSES / "doublet.toml")
        self.assertEqual(paper.specs.mode, "paper")
        for name, value in (("fields", [0.0, 5.0]), ("object_distance_mm", 500.0),
                            ("aperture", "epd"), ("aperture_value", 4.0)):
            with self.assertRaises(lensopt.LensoptError, msg=name) as caught:
                setattr(paper.specs, name, value)
            self.assertIn("as-written", str(caught.exception))
        paper.specs.half_field_deg = 20.0  # the paper's mode traces it
        self.assertEqual(quiet_analyze(paper).fields[-1].field_deg, 20.0)


class Paths(unittest.TestCase):
    def test_pathlib_everywhere(self):
        lens = lensopt.load_lens(LENSES / "doublet.toml")
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "d.zmx"
            lensopt.save_lens(lens, out)
            back = lensopt.load_lens(out)
            self.assertEqual(len(back.surfaces), len(lens.surfaces))
            image = Path(tmp) / "x.png"
            import numpy as np

            lensopt.write_image(image, np.full((4, 5, 3), 0.5, dtype=np.float32))
            self.assertEqual(lensopt.read_image(image).shape, (4, 5, 3))

    def test_missing_file_raises_file_not_found(self):
        for call in (lensopt.load_lens, lensopt.read_image):
            for path in ("no/such/lens.toml", Path("no/such/lens.zmx")):
                with self.assertRaises(FileNotFoundError) as caught:
                    call(path)
                self.assertEqual(caught.exception.filename, str(path))


class Copies(unittest.TestCase):
    def test_lens_pickles(self):
        lens = lensopt.load_lens(ROOT / "tests" / "data" / "zmx-real" / "thorlabs_AC254-100-A.zmx")
        back = pickle.loads(pickle.dumps(lens))
        self.assertEqual(back.to_toml(), lens.to_toml())
        self.assertEqual(back.source_path, lens.source_path)
        self.assertEqual(quiet_analyze(back).to_dict(), quiet_analyze(lens).to_dict())

    @unittest.skipUnless(HAVE_TORCH, "python3-torch is not installed")
    def test_image_formation_deepcopies_and_pickles(self):
        module = lt.ImageFormation(lensopt.load_lens(LENSES / "doublet.toml"), rings=4, fields=3,
                                   grid_size=17, threads=1, freeze=("glasses",))
        with torch.no_grad():
            module.x[0] += 1e-3  # a state that is not the lens's
        module.eval()
        images = torch.rand(1, 3, 18, 24)
        expected = module(images)
        for copied in (copy.deepcopy(module), pickle.loads(pickle.dumps(module))):
            self.assertIsNot(copied.imaging, module.imaging)
            self.assertTrue(torch.equal(copied.x.detach(), module.x.detach()))
            self.assertFalse(copied.training)
            self.assertTrue(torch.equal(copied(images), expected))
            # Independent: changing the copy leaves the original alone; frozen stays frozen.
            with torch.no_grad():
                copied.x[0] += 1.0
            self.assertFalse(torch.equal(copied.x.detach(), module.x.detach()))
            copied(images).sum().backward()
            frozen = list(module.param.select(["glasses"]))
            self.assertTrue(bool((copied.x.grad[frozen] == 0).all()))


class Tolerance(unittest.TestCase):
    def test_threads_as_the_cli(self):
        lens = lensopt.load_lens(LENSES / "doublet.toml")
        one = lensopt.tolerance(lens, trials=6, rings=4, fields=3, sensitivity=False, threads=1)
        two = lensopt.tolerance(lens, trials=6, rings=4, fields=3, sensitivity=False, threads=2)
        self.assertEqual(one.trials_csv(), two.trials_csv())  # seeded per trial
        self.assertEqual(lensopt.tolerance(lens, trials=6, rings=4, fields=3, sensitivity=False,
                                           jobs=2).trials_csv(), two.trials_csv())
        with self.assertRaises(lensopt.LensoptError):
            lensopt.tolerance(lens, trials=6, threads=1, jobs=2)


if __name__ == "__main__":
    unittest.main()
