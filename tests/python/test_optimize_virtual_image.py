"""A diverging lens's virtual-image bounds from Python (min_virtual_image_mm=,
max_virtual_image_mm=), resolved as `lensopt optimize --min-virtual-image-mm /
--max-virtual-image-mm` resolves them; refused on a lens with a real image."""

import unittest

from support import LENSES, ROOT, lensopt

LD1464 = ROOT / "tests" / "data" / "zmx-real" / "thorlabs_LD1464-A.zmx"


class OptimizeVirtualImage(unittest.TestCase):
    def test_bounds_given_are_the_run_bounds(self):
        lens = lensopt.load_lens(str(LD1464))
        lens.specs.fields = [0.0, 2.0, 4.0]  # the vendor file has its axis only
        r = lensopt.optimize(lens, targets=["efl_mm=-50"], min_virtual_image_mm=30,
                             max_virtual_image_mm=80, max_iterations=3, rings=4,
                             glass_search="none")
        self.assertTrue(any("within [30, 80] mm" in line for line in r.log), r.log)

    def test_refused_on_a_real_image(self):
        lens = lensopt.load_lens(str(LENSES / "doublet.toml"))
        with self.assertRaises(lensopt.LensoptError) as e:
            lensopt.optimize(lens, max_virtual_image_mm=80, max_iterations=1)
        self.assertIn("real image", str(e.exception))


if __name__ == "__main__":
    unittest.main()
