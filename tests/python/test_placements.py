"""3D placements from Python (issue 32): decenters, tilts, order and coordinate breaks read and set
on a loaded lens with the TOML reader's checks; a Python-built decentred lens is the TOML-loaded
one bit for bit (the same TOML text, the same analyze JSON). Fields off the y axis (x) too."""

import json
import math
import unittest

from support import LENSES, lensopt

COOKE = LENSES / "zmx" / "cooke_triplet_50.zmx"


def placed_toml(base_text):
    """The Cooke triplet's TOML with surface 6 decentred and tilted (tilt first, the frame restored
    after it) and a coordinate break before surface 2, written by hand in the TOML format."""
    lines = base_text.splitlines()
    out, surface = [], 0
    for line in lines:
        if line.strip() == "[[surfaces]]":
            surface += 1
            if surface == 2:  # the break goes before the second surface
                out += ["[[surfaces]]", "thickness_mm = 0.0",
                        "coordinate_break = { decenter_x_mm = 0.05, tilt_y_deg = 0.2, "
                        'order = "tilt-first" }', ""]
            out.append(line)
            if surface == 6:
                out.append("decenter_tilt = { decenter_y_mm = -0.03, tilt_x_deg = 0.1, "
                           "tilt_z_deg = 15.0, restore_frame = true }")
            continue
        out.append(line)
    return "\n".join(out) + "\n"


class Placements(unittest.TestCase):
    def setUp(self):
        self.lens = lensopt.load_lens(COOKE)

    def build_in_python(self):
        lens = lensopt.load_lens(COOKE)
        s = lens.surfaces[5]  # surface 6, before the break shifts the numbering
        s.decenter_y_mm = -0.03
        s.tilt_x_deg = 0.1
        s.tilt_z_deg = 15.0
        s.restore_frame = True
        lens.surfaces[5] = s
        self.assertEqual(lens.add_coordinate_break(1, decenter_x_mm=0.05, tilt_y_deg=0.2,
                                                   order="tilt-first"), 1)
        return lens

    def test_python_built_lens_equals_the_toml_one_bit_for_bit(self):
        built = self.build_in_python()
        text = placed_toml(self.lens.to_toml())
        loaded = lensopt.parse_lens(text, source_name="placed.toml")
        self.assertTrue(built.breaks_symmetry())
        self.assertEqual(built.to_toml(), loaded.to_toml())
        a = json.loads(lensopt.analyze(built, rings=6).to_json())
        b = json.loads(lensopt.analyze(loaded, rings=6).to_json())
        # The reports name their source (the .zmx path against "placed.toml"); all else is equal.
        self.assertNotEqual(a.pop("source"), b.pop("source"))
        self.assertEqual(a, b)
        s = built.surfaces[6]
        self.assertEqual((s.decenter_x_mm, s.decenter_y_mm), (0.0, -0.03))
        self.assertEqual((s.tilt_x_deg, s.tilt_y_deg, s.tilt_z_deg), (0.1, 0.0, 15.0))
        self.assertEqual(s.order, "decenter-first")
        self.assertTrue(s.restore_frame)
        cb = built.surfaces[1]
        self.assertTrue(cb.coordinate_break)
        self.assertEqual(cb.order, "tilt-first")

    def test_the_toml_readers_checks(self):
        s = self.lens.surfaces[2]
        with self.assertRaisesRegex(lensopt.LensoptError, "decenter-first"):
            s.order = "tilt-last"
        with self.assertRaisesRegex(lensopt.LensoptError, "not finite"):
            s.tilt_x_deg = math.nan
        with self.assertRaisesRegex(lensopt.LensoptError, ">= 0"):
            s.obscuration_mm = -1.0
        self.lens.add_coordinate_break(0, thickness_mm=1.0, tilt_x_deg=1.0)
        cb = self.lens.surfaces[0]
        with self.assertRaisesRegex(lensopt.LensoptError, "coordinate break"):
            cb.restore_frame = True
        with self.assertRaisesRegex(lensopt.LensoptError, "index"):
            self.lens.add_coordinate_break(99)

    def test_field_off_the_y_axis(self):
        y = lensopt.load_lens(COOKE)
        y.specs.fields = [lensopt.FieldPoint(14.0)]
        x = lensopt.load_lens(COOKE)
        x.specs.fields = [lensopt.FieldPoint(0.0, x=14.0)]
        self.assertEqual(x.specs.fields[0].azimuth_deg, 90.0)
        ry = json.loads(lensopt.analyze(y, rings=6).to_json())
        rx = json.loads(lensopt.analyze(x, rings=6).to_json())
        self.assertEqual(rx["rms_spot_um"], ry["rms_spot_um"])
        self.assertAlmostEqual(rx["image_centroid_x_mm"][0], ry["centroid_y_mm"][0], delta=1e-12)
        self.assertEqual(rx["field_x"], [14.0])
        # The TOML text carries fields_x and reads back.
        again = lensopt.parse_lens(x.to_toml(), source_name="x.toml")
        self.assertEqual(again.specs.fields[0].x, 14.0)


if __name__ == "__main__":
    unittest.main()
