"""lensopt.torch: gradients (torch.autograd.gradcheck in double precision) and agreement with
`lensopt render`. Skipped with a message when python3-torch is not installed."""

import tempfile
import unittest
import warnings
from pathlib import Path

import numpy as np

from support import EXECUTABLE, FULL, FULL_REASON, HAVE_TORCH, LENSES, lensopt

if HAVE_TORCH:
    import torch

    import lensopt.torch as lt


def doublet():
    return lensopt.load_lens(str(LENSES / "doublet.toml"))


@unittest.skipUnless(HAVE_TORCH, "python3-torch is not installed: the torch tests are skipped")
class ImageFormationGradients(unittest.TestCase):
    def setUp(self):
        torch.manual_seed(0)
        # continuous glasses: the quantized forward pass is piecewise constant in g, so finite
        # differences only see the straight-through gradient with continuous glasses.
        self.module = lt.ImageFormation(doublet(), glass_mode="continuous", rings=4, fields=5,
                                        grid_size=33, threads=2)

    def test_gradcheck_lens_variables(self):
        images = torch.rand(1, 3, 18, 24, dtype=torch.float64)
        weights = torch.randn(2, 1, 3, 18, 24, dtype=torch.float64)
        x = self.module.x

        def f(x_):
            # The image formation as a function of x alone (the module's state otherwise),
            # projected on two random output directions: gradcheck then compares the full
            # Jacobian wrt x of these (central differences per variable) with two backward
            # passes, in double precision. (Over every output pixel its fallback needs one
            # backward per pixel; the projections keep the test at seconds.)
            out = self.module._form(x_, images)
            return (out[None] * weights).sum(dim=(1, 2, 3, 4))

        self.assertTrue(torch.autograd.gradcheck(f, (x,), eps=1e-6, atol=1e-6, rtol=1e-4,
                                                 fast_mode=False))

    def test_gradcheck_image(self):
        images = torch.rand(2, 3, 18, 24, dtype=torch.float64, requires_grad=True)
        self.module.x.requires_grad_(False)
        try:
            self.assertTrue(torch.autograd.gradcheck(self.module, (images,), eps=1e-6, atol=1e-7,
                                                     fast_mode=True))
        finally:
            self.module.x.requires_grad_(True)

    def test_gradcheck_grey_image_with_alpha(self):
        images = torch.rand(1, 2, 18, 20, dtype=torch.float64, requires_grad=True)
        self.assertTrue(torch.autograd.gradcheck(self.module, (images,), eps=1e-6, atol=1e-7,
                                                 fast_mode=True))

    def test_rfft2_adjoint(self):
        # The blur's kernel spectra: rfft2 with zero padding and its own adjoint (irfft2 with the
        # doubled columns halved), for even and odd FFT widths and heights.
        for shape, size in (((2, 3, 4, 5), (7, 8)), ((3, 5, 5), (6, 9)), ((4, 4), (4, 5))):
            x = torch.rand(*shape, dtype=torch.float64, requires_grad=True)
            self.assertTrue(torch.autograd.gradcheck(
                lambda v: lt._Rfft2Function.apply(v, *size), (x,), eps=1e-6, atol=1e-8))
            np.testing.assert_allclose(lt._Rfft2Function.apply(x, *size).detach().numpy(),
                                       torch.fft.rfft2(x, s=size).detach().numpy(), atol=1e-14)

    @unittest.skipUnless(FULL, FULL_REASON)
    def test_lens_losses_gradcheck(self):
        param = self.module.param
        x = self.module.x.detach().clone().requires_grad_(True)
        opts = dict(rings=4, fields=3, glass_mode="continuous")
        self.assertTrue(torch.autograd.gradcheck(lambda v: lt.spot_loss(v, param, **opts), (x,),
                                                 eps=1e-6, atol=1e-7, rtol=1e-4))
        self.assertTrue(torch.autograd.gradcheck(
            lambda v: lt.lens_loss_terms(v, param, **opts), (x,), eps=1e-6, atol=1e-7, rtol=1e-4))
        total = lt.lens_loss(x, param, **opts)
        terms = lt.lens_loss_terms(x, param, **opts)
        self.assertAlmostEqual(total.item(), (terms[0] + 100 * terms[1] + 100 * terms[2]
                                              + 0.01 * terms[3]).item(), places=12)
        self.assertGreater(lt.l_GV(x, param, **opts).item(), -1e-300)

    @unittest.skipUnless(FULL, FULL_REASON)
    def test_jacobians_exposed(self):
        optics = self.module.optics(derivatives=True)
        n = self.module.param.size
        self.assertEqual(optics["d_psf"].shape[-1], n)
        self.assertEqual(optics["d_relative_illumination"].shape, (5, n))
        np.testing.assert_allclose(optics["psf"].sum(axis=(2, 3)), 1.0, atol=1e-12)


@unittest.skipUnless(HAVE_TORCH, "python3-torch is not installed: the torch tests are skipped")
class ImageOperationsInTorch(unittest.TestCase):
    """The image operations run in torch; they must equal lensopt's C++ renderer (Imaging.render)
    and its adjoints (Imaging.backward) for the same optics, and follow the input's device."""

    def setUp(self):
        torch.manual_seed(1)
        self.module = lt.ImageFormation(doublet(), glass_mode="continuous", rings=4, fields=5,
                                        grid_size=33, threads=2)

    def cpp(self, images, crop=None):
        """Imaging.render of each image (the C++ renderer, float64 scenes)."""
        self.module._prepare(self.module.x, derivatives=True)
        scenes = images.detach().permute(0, 2, 3, 1).numpy()
        out = [self.module.imaging.render(s, crop) for s in scenes]
        return torch.from_numpy(np.stack(out)).permute(0, 3, 1, 2)

    def check_forward(self, channels, crop=None, **options):
        module = self.module
        if options:
            module = self.module = lt.ImageFormation(doublet(), glass_mode="continuous", rings=4,
                                                     fields=5, grid_size=33, threads=2, **options)
        images = torch.rand(2, channels, 30, 44, dtype=torch.float64)
        with torch.no_grad():
            ours = module(images, crop)
        expected = self.cpp(images, crop)
        self.assertEqual(ours.shape, expected.shape)
        # Both in float64; they differ by the FFT sizes and summation orders only.
        np.testing.assert_allclose(ours.numpy(), expected.numpy(), rtol=0, atol=1e-12)
        # Not the identity: the blur, RI and warp changed the image.
        x0, y0, w, h = crop if crop else (0, 0, 44, 30)
        self.assertGreater((ours - images[..., y0:y0 + h, x0:x0 + w]).abs().max(), 1e-3)

    def test_forward_equals_cpp_renderer(self):
        self.check_forward(3)

    def test_forward_equals_cpp_renderer_crop_and_rgba(self):
        self.check_forward(4, crop=(7, 5, 20, 17))

    def test_forward_equals_cpp_renderer_grey_alpha(self):
        self.check_forward(2, crop=(0, 12, 44, 18))

    def test_forward_equals_cpp_renderer_without_maps(self):
        self.check_forward(3, crop=(3, 4, 25, 20), relative_illumination=False,
                           distortion=False)

    def test_backward_equals_cpp_adjoint(self):
        module = self.module
        images = torch.rand(2, 3, 30, 44, dtype=torch.float64, requires_grad=True)
        crop = (4, 3, 36, 24)
        weights = torch.rand(2, 3, 24, 36, dtype=torch.float64)
        (module(images, crop) * weights).sum().backward()
        module._prepare(module.x, derivatives=True)
        gx = np.zeros(module.param.size)
        gi = []
        for scene, g in zip(images.detach().permute(0, 2, 3, 1).numpy(),
                            weights.permute(0, 2, 3, 1).numpy()):
            a, b = module.imaging.backward(scene, crop, g, True)
            gx += a
            gi.append(b)
        # The C++ adjoint takes the output gradient in float32: agreement to ~1e-7 relative.
        scale = np.abs(gx).max()
        self.assertGreater(scale, 0)
        np.testing.assert_allclose(module.x.grad.numpy(), gx, rtol=0, atol=1e-5 * scale)
        ours = images.grad.permute(0, 2, 3, 1).numpy()
        np.testing.assert_allclose(ours, np.stack(gi), rtol=0, atol=1e-6)

    def test_device_and_dtype_follow_the_input(self):
        images = torch.rand(1, 3, 30, 44)
        out = self.module(images)
        self.assertEqual((out.dtype, out.device), (torch.float32, images.device))
        # On the 'meta' device (shapes only, no data) the forward runs: the image path never
        # copies the images to the CPU or numpy (that fails on 'meta'), only the optics are.
        meta = torch.empty(2, 4, 30, 44, device="meta", dtype=torch.float32)
        out = self.module(meta, (2, 3, 21, 17))
        self.assertEqual(out.device.type, "meta")
        self.assertEqual((out.shape, out.dtype), ((2, 4, 17, 21), torch.float32))
        meta64 = torch.empty(1, 1, 30, 44, device="meta", dtype=torch.float64)
        self.assertEqual(self.module(meta64).dtype, torch.float64)

    def test_in_place_update_of_x_resamples_the_optics(self):
        # An optimizer changes x in place: the next forward must see the new lens.
        images = torch.rand(1, 3, 30, 44, dtype=torch.float64)
        with torch.no_grad():
            before = self.module(images)
            self.module.x[7] += 1e-3  # defocus
            after = self.module(images)
        self.assertGreater((after - before).abs().max().item(), 1e-6)

    def test_bad_crop_is_an_error(self):
        with self.assertRaisesRegex(ValueError, "not inside"):
            self.module(torch.rand(1, 3, 20, 20), (10, 10, 20, 5))


@unittest.skipUnless(HAVE_TORCH, "python3-torch is not installed: the torch tests are skipped")
class Float32ImagesByLensoptsImageFormation(unittest.TestCase):
    """float32 images on the CPU are formed by lensopt's C++ image formation and its adjoint
    (Imaging.render_images / backward_images, image_ops="auto"): the joint optimization's code,
    reading only the window of the images a crop needs. It must agree with the torch operations
    (image_ops="torch", which the tests above hold to the C++ renderer) run in float64, to float32
    rounding, forward and backward (wrt x and the images), for crops at the corners and inside."""

    CROPS = (None, (0, 0, 20, 16), (35, 20, 25, 20), (22, 12, 16, 14))

    def modules(self, **options):
        kw = dict(glass_mode="continuous", rings=4, fields=5, grid_size=33, threads=2, **options)
        return lt.ImageFormation(doublet(), **kw), lt.ImageFormation(doublet(), image_ops="torch",
                                                                     **kw)

    def check(self, channels, **options):
        torch.manual_seed(3)
        ours, ref = self.modules(**options)
        images = torch.rand(2, channels, 40, 60)
        for crop in self.CROPS:
            with self.subTest(crop=crop):
                a = images.clone().requires_grad_(True)
                b = images.double().requires_grad_(True)
                out_a, out_b = ours(a, crop), ref(b, crop)
                self.assertEqual((out_a.dtype, out_a.shape), (torch.float32, out_b.shape))
                weights = torch.randn(out_b.shape, dtype=torch.float64)
                (out_a.double() * weights).sum().backward()
                (out_b * weights).sum().backward()
                np.testing.assert_allclose(out_a.detach().double().numpy(), out_b.detach().numpy(),
                                           rtol=0, atol=2e-6)
                scale = ref.x.grad.abs().max().item()
                self.assertGreater(scale, 0)
                np.testing.assert_allclose(ours.x.grad.numpy(), ref.x.grad.numpy(), rtol=0,
                                           atol=1e-5 * scale)
                scale = b.grad.abs().max().item()
                np.testing.assert_allclose(a.grad.double().numpy(), b.grad.numpy(), rtol=0,
                                           atol=1e-5 * scale)
                ours.x.grad = ref.x.grad = None
        # The torch operations never ran for `ours`: it never fetched the optics' values.
        self.assertIsNone(ours._values)

    def test_rgb(self):
        self.check(3)

    def test_rgba(self):
        self.check(4)

    def test_grey_alpha(self):
        self.check(2)

    def test_without_maps(self):
        self.check(3, relative_illumination=False, distortion=False)

    def test_reads_only_the_window_a_crop_needs(self):
        # Every pixel outside Imaging.scene_window is NaN: the crop and its gradients are the
        # same (finite) values as with the clean images.
        module, _ = self.modules()
        images = torch.rand(1, 3, 40, 60)
        crop = (22, 12, 16, 14)
        module._prepare(module.x, derivatives=True)
        x0, y0, w, h = module.imaging.scene_window(60, 40, 3, crop)
        self.assertLess(w * h, 60 * 40)
        poisoned = torch.full_like(images, float("nan"))
        poisoned[..., y0:y0 + h, x0:x0 + w] = images[..., y0:y0 + h, x0:x0 + w]
        outs, grads = [], []
        for im in (images, poisoned):
            im = im.clone().requires_grad_(True)
            out = module(im, crop)
            (out * out).sum().backward()
            outs.append(out.detach())
            grads.append((module.x.grad.clone(), im.grad))
            module.x.grad = None
        self.assertTrue(torch.isfinite(outs[1]).all())
        self.assertTrue(torch.equal(outs[0], outs[1]))
        self.assertTrue(torch.equal(grads[0][0], grads[1][0]))
        self.assertTrue(torch.equal(grads[0][1], grads[1][1]))

    def test_image_gradient_without_lens_derivatives(self):
        # x frozen (requires_grad False): the optics are sampled without Jets and the backward
        # gives the images' gradient alone, the same as with the lens gradient.
        images = torch.rand(2, 3, 40, 60)
        weights = torch.randn(2, 3, 14, 16)
        grads = []
        for frozen in (False, True):
            module, _ = self.modules()
            module.x.requires_grad_(not frozen)
            im = images.clone().requires_grad_(True)
            (module(im, (22, 12, 16, 14)) * weights).sum().backward()
            self.assertEqual(module._prepared[1], not frozen)  # Jets only for the lens gradient
            self.assertEqual(module.x.grad is None, frozen)
            grads.append(im.grad)
        # The same up to the optics' last bits (values-only sampling is in double, not Jets).
        scale = grads[0].abs().max().item()
        self.assertGreater(scale, 0)
        np.testing.assert_allclose(grads[1].numpy(), grads[0].numpy(), rtol=0, atol=1e-6 * scale)

    def test_image_ops_option(self):
        ours, ref = self.modules()
        self.assertEqual((ours.image_ops, ref.image_ops), ("auto", "torch"))
        with self.assertRaisesRegex(ValueError, "image_ops"):
            lt.ImageFormation(doublet(), image_ops="gpu")


@unittest.skipUnless(HAVE_TORCH, "python3-torch is not installed: the torch tests are skipped")
class ImageFormationMatchesCli(unittest.TestCase):
    @unittest.skipUnless(FULL, FULL_REASON)
    def test_forward_equals_lensopt_render(self):
        import subprocess

        rng = np.random.default_rng(5)
        image = rng.random((36, 48, 3), dtype=np.float32)
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / "in" / "scene.exr"
            src.parent.mkdir()
            lensopt.write_image(str(src), image)
            subprocess.run([EXECUTABLE, "render", str(LENSES / "doublet.toml"), str(src), "-o",
                            str(Path(tmp) / "out"), "-q"], check=True, capture_output=True)
            expected = lensopt.read_image(str(Path(tmp) / "out" / "scene.exr"))
        # `lensopt render`'s sampling: 32 rings, 21 fields, KDE support 2.
        module = lt.ImageFormation(doublet(), rings=32, support_bins=2)
        with torch.no_grad():
            out = module(torch.from_numpy(image).permute(2, 0, 1)[None])
        ours = out[0].permute(1, 2, 0).numpy()
        self.assertEqual(out.dtype, torch.float32)
        np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-5)

    @unittest.skipUnless(FULL, FULL_REASON)
    def test_training_step_moves_the_lens(self):
        module = lt.ImageFormation(doublet(), rings=4, fields=5, grid_size=33, threads=2,
                                   freeze=["glasses"])
        optimizer = torch.optim.Adam(module.parameters(), lr=1e-3)
        images = torch.rand(2, 3, 18, 24)
        x0 = module.x.detach().clone()
        loss = ((module(images) - images) ** 2).mean() + 0.1 * module.lens_loss(rings=4, fields=3)
        loss.backward()
        glass = [i for i, g in enumerate(module.param.groups) if g == "glasses"]
        self.assertTrue((module.x.grad[glass] == 0).all())
        optimizer.step()
        self.assertFalse(torch.equal(module.x.detach(), x0))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.assertEqual(len(module.lens().surfaces), len(doublet().surfaces))


if __name__ == "__main__":
    unittest.main()
