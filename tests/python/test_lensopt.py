"""The Python package against the CLI and against closed forms (no torch needed)."""

import json
import math
import os
import subprocess
import sys
import tempfile
import unittest
import warnings
from pathlib import Path

import numpy as np

from support import BASELINES, EXECUTABLE, LENSES, ZMX, lensopt


def load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return lensopt.load_lens(str(path))


def cli(*args):
    return subprocess.run([EXECUTABLE, *map(str, args)], check=True, capture_output=True,
                          text=True).stdout


class AnalyzeMatchesCli(unittest.TestCase):
    def test_baselines_and_zmx(self):
        lenses = BASELINES + ZMX
        self.assertGreaterEqual(len(lenses), 6)
        for path in lenses:
            with self.subTest(lens=path.name):
                expected = json.loads(cli("analyze", "--json", path))
                report = lensopt.analyze(load(path))
                self.assertEqual(report.to_dict(), expected)
                # The attributes are the same numbers as the JSON fields.
                self.assertEqual(report.efl_mm, expected["efl_mm"])
                self.assertEqual([f.field_deg for f in report.fields], expected["fields_deg"])
                self.assertEqual(report.mean_rms_spot_um, expected["mean_rms_spot_um"])
                self.assertIsNone(report.wave)
                self.assertIsNone(report.zernike_waves)

    def test_wave_and_zernike_match_cli(self):
        path = LENSES / "doublet.toml"
        for order in ("fringe", "standard"):
            with self.subTest(order=order):
                expected = json.loads(cli("analyze", "--json", "--zernike", 9, "--zernike-order",
                                          order, "--pupil-samples", 16, "--mtf-freqs", "10,40",
                                          "--fields", 3, "--rings", 4, path))
                report = lensopt.analyze(load(path), rings=4, fields=3, zernike_terms=9,
                                         zernike_order=order, pupil_samples=16,
                                         mtf_frequencies=[10, 40])
                self.assertEqual(report.to_dict(), expected)
                self.assertEqual(report.wave, expected["wave"])
                self.assertEqual(report.wave["zernike_ordering"], order)
                z = report.zernike_waves
                wavelengths = len(expected["wave"]["wavelengths_nm"])
                self.assertEqual(z.shape, (3, wavelengths, 9))  # fields, wavelengths, terms
                for h, field in enumerate(expected["wave"]["fields"]):
                    for w, mono in enumerate(field["per_wavelength"]):
                        np.testing.assert_array_equal(z[h, w], mono["zernike_waves"])
        # wave=True without a fit: the wave section, no coefficients.
        report = lensopt.analyze(load(path), rings=4, fields=3, wave=True, pupil_samples=16)
        self.assertGreater(report.wave["mean_strehl"], 0)
        self.assertNotIn("zernike_terms", report.wave)
        self.assertIsNone(report.zernike_waves)
        with self.assertRaises(lensopt.LensoptError):
            lensopt.analyze(load(path), zernike_terms=9, zernike_order="annular")


class Lenses(unittest.TestCase):
    def test_fast_lens_as_written_loads_with_a_warning(self):
        # optiland's lens_floa.zmx: its FLOA stop gives a paraxial F/0.49936 (below the F/0.5 of
        # an image-space NA of 1); it loads, with a warning naming the file and the value, and
        # its relative illumination (edge rays fail) is None, not 0.
        path = LENSES.parent / "tests" / "data" / "zmx-real" / "optiland_lens_floa.zmx"
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            lens = lensopt.load_lens(str(path))
        fast = [str(w.message) for w in caught if "0.49936" in str(w.message)]
        self.assertEqual(len(fast), 1)
        self.assertIn("optiland_lens_floa.zmx", fast[0])
        report = lensopt.analyze(lens, rings=8)
        self.assertIsNone(report.fields[0].relative_illumination)
        self.assertGreater(report.fields[0].failed_rays, 0)

    def test_round_trip_every_writable_format(self):
        lens = load(LENSES / "cooke.toml")
        with tempfile.TemporaryDirectory() as tmp:
            for ext in (".toml", ".zmx"):
                out = Path(tmp) / f"cooke{ext}"
                lensopt.save_lens(lens, str(out))
                back = load(out)
                self.assertEqual(len(back.surfaces), len(lens.surfaces))
                for a, b in zip(lens.surfaces, back.surfaces):
                    self.assertEqual(a.curvature_per_mm, b.curvature_per_mm)
                    self.assertEqual(a.thickness_mm, b.thickness_mm)
                    self.assertEqual(a.material.label, b.material.label)
            self.assertEqual(lensopt.parse_lens(lens.to_toml()).to_toml(), lens.to_toml())

    def test_edit_in_place(self):
        lens = load(LENSES / "doublet.toml")
        before = lensopt.analyze(lens, rings=4, fields=3).mean_rms_spot_um
        lens.surfaces[-1].thickness_mm += 0.5  # defocus
        lens.specs.f_number = 2.8
        lens.surfaces[0].material = lensopt.Material.model(1.7, 50.0)
        self.assertEqual(lens.surfaces[-1].material.kind, "air")
        self.assertEqual(lens.surfaces[0].material.kind, "model")
        after = lensopt.analyze(lens, rings=4, fields=3)
        self.assertNotEqual(after.mean_rms_spot_um, before)
        self.assertAlmostEqual(after.f_number, 2.8, places=9)
        glass = lensopt.Material.catalog("S-LAL12")
        self.assertEqual(glass.kind, "catalog")
        self.assertAlmostEqual(glass.nd, 1.6779, places=4)

    def test_errors_carry_file_and_line(self):
        text = '[lens]\nname = "x"\n\n[[surfaces]]\nradius_mm = "oops"\n'
        with self.assertRaises(lensopt.LensoptError) as caught:
            lensopt.parse_lens(text, "toml", "bad.toml")
        self.assertTrue(str(caught.exception).startswith("bad.toml:"), str(caught.exception))
        self.assertGreater(caught.exception.line, 0)
        self.assertIsInstance(caught.exception, ValueError)
        with self.assertRaises(lensopt.LensoptError) as caught:
            lensopt.Material.catalog("S-LAL1Z")
        self.assertIn("S-LAL12", str(caught.exception))  # the closest names
        # A missing file is Python's FileNotFoundError, as open() raises it (issue 31).
        with self.assertRaises(FileNotFoundError):
            lensopt.load_lens(str(LENSES / "missing.toml"))


class Tracing(unittest.TestCase):
    def setUp(self):
        self.lens = load(LENSES / "doublet.toml")
        self.report = lensopt.analyze(self.lens, rings=4, fields=3, ray_aiming=False)

    def test_pupil_rays_equal_explicit_rays(self):
        theta = math.radians(10.0)
        pupil = np.array([[0.0, 0.0], [0.3, -0.5], [0.0, 1.0]])
        via_pupil = lensopt.trace_pupil(self.lens, 10.0, pupil, ray_aiming=False)
        r_ep = self.report.epd_mm / 2
        z_ep = self.report.entrance_pupil_z_mm
        positions = np.column_stack([pupil[:, 0] * r_ep, pupil[:, 1] * r_ep, np.full(3, z_ep)])
        directions = np.tile([0.0, math.sin(theta), math.cos(theta)], (3, 1))
        explicit = lensopt.trace_rays(self.lens, positions, directions)
        np.testing.assert_allclose(explicit["positions"], via_pupil["positions"], rtol=0,
                                   atol=1e-12)
        self.assertTrue((explicit["status"] == 0).all())
        self.assertEqual(explicit["positions"].shape, (3, 3))

    def test_on_axis_chief_ray_stays_on_axis(self):
        out = lensopt.trace_rays(self.lens, np.array([[0.0, 0.0, -5.0]]),
                                 np.array([[0.0, 0.0, 2.0]]))
        np.testing.assert_array_equal(out["positions"][0, :2], [0.0, 0.0])
        np.testing.assert_allclose(out["directions"][0], [0.0, 0.0, 1.0])

    def test_spots_psfs_and_field_data_agree_with_analyze(self):
        report = lensopt.analyze(self.lens, rings=8, fields=5)
        spots = lensopt.spots(self.lens, rings=8, fields=5)
        self.assertEqual(spots["rms_spot_um"], [f.rms_spot_um for f in report.fields])
        data = lensopt.field_data(self.lens, rings=8, fields=5)
        np.testing.assert_allclose(np.array(data["distortion"]) * 100,
                                   [f.distortion_percent for f in report.fields], atol=1e-12)
        self.assertEqual(data["relative_illumination"],
                         [f.relative_illumination for f in report.fields])
        p = lensopt.psfs(self.lens, rings=8, fields=5, grid_size=33)
        self.assertEqual(p["psf"].shape, (5, 3, 33, 33))
        np.testing.assert_allclose(p["psf"].sum(axis=(2, 3)), 1.0, atol=1e-12)


class Rendering(unittest.TestCase):
    def test_maps_on_axis(self):
        r = lensopt.Renderer(load(LENSES / "doublet.toml"), rings=4, fields=5)
        maps = r.maps(41, 31)
        self.assertEqual(maps["relative_illumination"].shape, (31, 41))
        # The centre pixel lies on the axis: no dimming, no distortion.
        self.assertAlmostEqual(maps["relative_illumination"][15, 20], 1.0, places=12)
        self.assertAlmostEqual(maps["distortion"][15, 20], 0.0, places=12)
        self.assertLess(maps["relative_illumination"][0, 0], 1.0)

    def test_maps_of_no_pixels_raise(self):
        # Issue 34: maps(0, 0) returned a NaN pitch instead of raising.
        r = lensopt.Renderer(load(LENSES / "doublet.toml"), rings=4, fields=5)
        for width, height in [(0, 0), (0, 10), (10, 0), (-1, 5)]:
            with self.assertRaises(ValueError):
                r.maps(width, height)

    def test_psf_kind(self):
        lens = load(LENSES / "doublet.toml")
        geometric = lensopt.Renderer(lens, rings=4, fields=3)
        self.assertEqual(geometric.psf["kind"], "geometric")
        self.assertEqual(geometric.psf["diffraction"].shape, (3, 3))
        self.assertFalse(geometric.psf["diffraction"].any())
        self.assertEqual(geometric.psf["pupil_samples"], 0)
        # The Doublet's full-field spot does not fit the 260 um PSF window (the CLI warns too).
        self.assertTrue(any("PSF window" in w for w in geometric.psf["warnings"]),
                        geometric.psf["warnings"])
        cooke = lensopt.Renderer(load(LENSES / "cooke.toml"), rings=4, fields=3)
        self.assertFalse(any("PSF window" in w for w in cooke.psf["warnings"]))
        diffraction = lensopt.Renderer(lens, rings=4, fields=3, psf="diffraction",
                                       pupil_samples=16)
        self.assertTrue(diffraction.psf["diffraction"].all())
        self.assertEqual(diffraction.psf["pupil_samples"], 16)
        self.assertGreaterEqual(diffraction.psf["fft_n"], 32)
        auto = lensopt.Renderer(lens, rings=4, fields=3, psf="auto", pupil_samples=16)
        self.assertEqual(auto.psf["kind"], "auto")
        self.assertEqual(auto.psf["diffraction_channels"], int(auto.psf["diffraction"].sum()))
        # The renderer holds the chosen PSFs: auto renders like geometric where it chose none,
        # like diffraction where it chose all.
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / "in" / "scene.exr"
            src.parent.mkdir()
            lensopt.write_image(str(src), np.full((36, 48, 3), 0.5, dtype=np.float32))
            cli("render", LENSES / "doublet.toml", src, "-o", Path(tmp) / "out", "-q", "--psf",
                "auto", "--pupil-samples", 64)
            settings = json.loads((Path(tmp) / "out" / "render_metrics.json").read_text())[
                "settings"]
        cli_auto = lensopt.Renderer(lens, psf="auto")
        self.assertEqual(settings["psf"]["kind"], "auto")
        self.assertEqual(settings["psf"]["diffraction_channels"],
                         cli_auto.psf["diffraction_channels"])
        chosen = [[f[c] == "diffraction" for c in "RGB"] for f in settings["psf"]["chosen"]]
        np.testing.assert_array_equal(cli_auto.psf["diffraction"], chosen)
        with self.assertRaises(lensopt.LensoptError):
            lensopt.Renderer(lens, psf="wave")

    def test_render_matches_cli(self):
        rng = np.random.default_rng(3)
        image = rng.random((36, 48, 3), dtype=np.float32)
        lens_path = LENSES / "doublet.toml"
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / "in" / "scene.exr"
            src.parent.mkdir()
            lensopt.write_image(str(src), image)
            cli("render", lens_path, src, "-o", Path(tmp) / "out", "-q")
            expected = lensopt.read_image(str(Path(tmp) / "out" / "scene.exr"))
        ours = lensopt.render(load(lens_path), image)
        self.assertEqual(ours.dtype, np.float32)
        np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-6)


class Optimization(unittest.TestCase):
    def test_design_loss_gradient_matches_finite_differences(self):
        lens = load(LENSES / "doublet.toml")
        param = lensopt.Parameterization(lens)
        x = param.from_lens(lens)
        opts = dict(rings=4, fields=3, glass_mode="continuous")
        g = param.design_loss(x, **opts)["gradient"]
        for j in range(param.size):
            h = 1e-6
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            fd = (param.design_loss(xp, gradient=False, **opts)["total"]
                  - param.design_loss(xm, gradient=False, **opts)["total"]) / (2 * h)
            self.assertAlmostEqual(g[j], fd, delta=1e-5 * max(1.0, abs(fd)), msg=param.names[j])
        # The parameterization round-trips the lens.
        np.testing.assert_allclose(param.from_lens(param.to_lens(x)), x, atol=1e-9)

    def test_optimize_and_tolerance_run(self):
        lens = load(LENSES / "doublet.toml")
        lens.surfaces[-1].thickness_mm += 0.3
        result = lensopt.optimize(lens, max_iterations=3, max_rounds=1, rings=4, fields=3)
        self.assertLessEqual(result.final_spot_um, result.start_spot_um)
        self.assertEqual(len(result.lens.surfaces), len(lens.surfaces))
        report = lensopt.tolerance(lens, trials=8, rings=4, fields=3, sensitivity=False, jobs=2)
        self.assertEqual(len(report.trial_spots_um), 8)
        self.assertGreater(report.nominal_spot_um, 0)
        self.assertEqual(report.to_dict()["lens"], report.lens_name)

    def test_wavefront_merit(self):
        lens = load(LENSES / "doublet.toml")
        param = lensopt.Parameterization(lens)
        x = param.from_lens(lens)
        opts = dict(rings=4, fields=3, glass_mode="continuous", merit="wavefront",
                    wavefront_pupil_samples=8, weight_ray_path=0.0, weight_ray_angle=0.0,
                    weight_glass=0.0)
        d = param.design_loss(x, **opts)
        self.assertEqual(d["merit"], "wavefront")
        self.assertEqual(len(d["field_wavefront_waves"]), 3)
        self.assertAlmostEqual(d["total"], d["wavefront_waves"], delta=1e-12)
        self.assertAlmostEqual(d["wavefront_waves"], np.mean(d["field_wavefront_waves"]),
                               delta=1e-12)
        self.assertNotIn("wavefront_waves", param.design_loss(x, rings=4, fields=3))
        for j in range(param.size):
            h = 1e-4 * max(1.0, abs(x[j]))
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            fd = (param.design_loss(xp, gradient=False, **opts)["total"]
                  - param.design_loss(xm, gradient=False, **opts)["total"]) / (2 * h)
            self.assertAlmostEqual(d["gradient"][j], fd, delta=1e-4 * max(1.0, abs(fd)),
                                   msg=param.names[j])
        with self.assertRaises(lensopt.LensoptError):
            param.design_loss(x, merit="strehl")
        lens.surfaces[-1].thickness_mm += 0.3
        result = lensopt.optimize(lens, max_iterations=3, max_rounds=1, rings=4, fields=3,
                                  merit="wavefront", wavefront_pupil_samples=8)
        self.assertGreater(result.start_wavefront_waves, 0)
        self.assertLess(result.final_wavefront_waves, result.start_wavefront_waves)
        spot = lensopt.optimize(lens, max_iterations=1, max_rounds=1, rings=4, fields=3)
        self.assertEqual(spot.start_wavefront_waves, 0)


if __name__ == "__main__":
    unittest.main()


class PassiveOpenMpThreads(unittest.TestCase):
    def test_import_sets_passive_wait_unless_set(self):
        # In a fresh interpreter (libgomp not yet loaded): the package sets OMP_WAIT_POLICY before
        # it loads _lensopt, so libgomp runs with a spin count of 0; a user's value is kept.
        code = ("import os, sys; sys.path[:0] = sys.argv[1:]; import lensopt; "
                "print(os.environ['OMP_WAIT_POLICY'])")
        paths = [str(Path(lensopt.__file__).resolve().parents[1])]
        env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
        env["OMP_DISPLAY_ENV"] = "verbose"
        run = subprocess.run([sys.executable, "-c", code, *paths], env=env, capture_output=True,
                             text=True, check=True)
        self.assertEqual(run.stdout.strip(), "PASSIVE")
        self.assertIn("GOMP_SPINCOUNT = '0'", run.stderr)
        env["OMP_WAIT_POLICY"] = "active"
        run = subprocess.run([sys.executable, "-c", code, *paths], env=env, capture_output=True,
                             text=True, check=True)
        self.assertEqual(run.stdout.strip(), "active")
        self.assertNotIn("GOMP_SPINCOUNT = '0'", run.stderr)

    def test_warns_when_openmp_was_loaded_first(self):
        # torch (or anything linking libgomp) imported first: libgomp has read its settings, the
        # package cannot make its threads wait passively, and says so (unless the user set
        # OMP_WAIT_POLICY). ctypes loads libgomp without torch, which may be absent.
        code = ("import ctypes, ctypes.util, sys, warnings; sys.path[:0] = sys.argv[1:]; "
                "ctypes.CDLL(ctypes.util.find_library('gomp') or 'libgomp.so.1'); "
                "warnings.simplefilter('always'); import lensopt")
        paths = [str(Path(lensopt.__file__).resolve().parents[1])]
        env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
        run = subprocess.run([sys.executable, "-c", code, *paths], env=env, capture_output=True,
                             text=True, check=True)
        # The package throttles that libgomp's spinning (parked threads): nothing to warn about.
        self.assertNotIn("was loaded before lensopt", run.stderr)
        env["OMP_WAIT_POLICY"] = "PASSIVE"
        run = subprocess.run([sys.executable, "-c", code, *paths], env=env, capture_output=True,
                             text=True, check=True)
        self.assertNotIn("was loaded before lensopt", run.stderr)
        # Imported first, as the package recommends: no warning.
        code_first = "import sys, warnings; sys.path[:0] = sys.argv[1:]; import lensopt"
        env.pop("OMP_WAIT_POLICY")
        run = subprocess.run([sys.executable, "-W", "always", "-c", code_first, *paths], env=env,
                             capture_output=True, text=True, check=True)
        self.assertNotIn("was loaded before lensopt", run.stderr)

    def test_libgomp_loaded_first_is_throttled(self):
        # torch loads libgomp (RTLD_GLOBAL) before lensopt can set OMP_WAIT_POLICY, so libgomp's
        # threads would spin 300,000 iterations after every parallel region. The package then
        # keeps CPUs + 1 libgomp threads idle: libgomp, managing more threads than CPUs, spins
        # only 100 iterations (the libgomp manual, GOMP_SPINCOUNT). Seen here as the threads of
        # the process: CPUs + 1 more after the import (the parking thread and its team's CPUs
        # workers) than with OMP_WAIT_POLICY or GOMP_SPINCOUNT set by the user, when nothing is
        # parked (new thread ids, counted after a thread was started and joined: ThreadSanitizer,
        # tools/tsan-python.sh, starts its background thread at the first thread creation). Fails
        # without the parking (main before this branch: the same count in all three).
        code = ("import ctypes, ctypes.util, os, sys, threading; sys.path[:0] = sys.argv[1:]; "
                "ctypes.CDLL(ctypes.util.find_library('gomp') or 'libgomp.so.1', "
                "mode=os.RTLD_GLOBAL); t = threading.Thread(target=len, args=((),)); t.start(); "
                "t.join(); before = set(os.listdir('/proc/self/task')); "
                "import lensopt; print(len(set(os.listdir('/proc/self/task')) - before), "
                "len(os.sched_getaffinity(0)))")
        paths = [str(Path(lensopt.__file__).resolve().parents[1])]
        env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY",
                                                                 "GOMP_SPINCOUNT")}
        added = {}
        for name, value in ((None, None), ("OMP_WAIT_POLICY", "PASSIVE"),
                            ("GOMP_SPINCOUNT", "1000")):
            run_env = dict(env) if name is None else {**env, name: value}
            run = subprocess.run([sys.executable, "-c", code, *paths], env=run_env,
                                 capture_output=True, text=True, check=True)
            added[name], cpus = map(int, run.stdout.split())
        self.assertEqual(added["OMP_WAIT_POLICY"], added["GOMP_SPINCOUNT"])
        self.assertEqual(added[None] - added["OMP_WAIT_POLICY"], cpus + 1)
