// Wave optics (analysis/wavefront.h, analysis/wave.h) against closed forms: an aberration-free
// slow singlet (checked by its own OPD) gives the diffraction-limited MTF, the Airy ring and a
// Strehl ratio of 1; a known defocus gives its quadratic OPD and the closed-form Strehl; the RMS
// wavefront's Jet derivatives match central finite differences.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "lensopt/analysis/wave.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/analysis/zernike.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "test_support.h"

namespace test_wave {

using namespace lensopt;

namespace {

// f = 100 mm f/40 plano-convex singlet (convex side first, stop in front), one wavelength
// (given twice: the model needs two) and a 0.5 deg half field: its wavefront error is below a
// thousandth of a wave. Its image plane is 2.9 um short of the paraxial focus: tests refocus.
Lens slow_singlet() {
  const char* text = R"(
[lens]
name = "slow-singlet"
[specs]
f_number = 40.0
half_field_deg = 0.5
sensor_diagonal_mm = 1.7453292519943295
wavelengths_nm = [587.56, 587.56]
channels = ["G", "G"]
dispersion = "abbe"
[[surfaces]]
radius_mm = inf
thickness_mm = 1.0
stop = true
[[surfaces]]
radius_mm = 51.68
thickness_mm = 4.0
material = { nd = 1.5168, vd = 64.17 }
[[surfaces]]
radius_mm = inf
thickness_mm = 97.36
)";
  return parse_lens_toml(text, "slow-singlet");
}

TraceSystem<double> prepare(const Lens& lens, int fields = 2) {
  TraceOptions options;
  options.fields = fields;
  return prepare_system(make_trace_lens(lens), lens.specs, options);
}

}  // namespace

TEST_CASE("wave: pupil grid weights add up to the unit disk's area") {
  for (int n : {16, 64, 128}) {
    const PupilGrid grid = make_pupil_grid(n);
    double area = 0;
    for (double w : grid.weight) area += w * (2.0 / n) * (2.0 / n);
    CAPTURE(n);
    CHECK(area == doctest::Approx(kPi).epsilon(2e-4));
  }
}

TEST_CASE("wave: the polar pupil quadrature integrates polynomials up to its degree exactly") {
  // int_disk x^a y^b dA for even a, b: 2 Gamma((a+1)/2) Gamma((b+1)/2) / ((a+b+2) Gamma((a+b)/2+1))
  // (0 when a or b is odd).
  auto exact = [](int a, int b) {
    if (a % 2 || b % 2) return 0.0;
    return 2.0 * std::tgamma((a + 1) / 2.0) * std::tgamma((b + 1) / 2.0) /
           ((a + b + 2) * std::tgamma((a + b) / 2.0 + 1.0));
  };
  for (const auto& [rings, half] : std::vector<std::pair<int, int>>{{1, 1}, {3, 6}, {6, 12}}) {
    const int degree = std::min(4 * rings - 1, 2 * half - 1);
    for (bool mirrored : {false, true}) {
      const PupilGrid q = make_pupil_quadrature(rings, half, mirrored);
      REQUIRE(q.size() == static_cast<std::size_t>(rings * half * (mirrored ? 1 : 2)));
      CHECK(q.mirrored == mirrored);
      for (std::size_t i = 0; i < q.size(); ++i) {
        const double r2 = q.samples.x[i] * q.samples.x[i] + q.samples.y[i] * q.samples.y[i];
        CHECK(r2 < 1.0);
        if (mirrored) CHECK(q.samples.x[i] > 0.0);
      }
      // Every monomial up to the rule's degree; a mirrored rule only the even ones in x_p
      // (those its mirror images double).
      for (int a = 0; a <= degree; ++a)
        for (int b = 0; a + b <= degree; ++b) {
          if (mirrored && a % 2) continue;
          double sum = 0;
          for (std::size_t i = 0; i < q.size(); ++i)
            sum += q.weight[i] * std::pow(q.samples.x[i], a) * std::pow(q.samples.y[i], b);
          CAPTURE(rings);
          CAPTURE(half);
          CAPTURE(a);
          CAPTURE(b);
          CHECK(sum == doctest::Approx(exact(a, b)).epsilon(1e-12).scale(1.0));
        }
    }
  }
  // One degree beyond: r^{4 R} is not integrated exactly (the rule's degree is sharp).
  const PupilGrid q = make_pupil_quadrature(3, 12, false);
  double sum = 0;
  for (std::size_t i = 0; i < q.size(); ++i)
    sum += q.weight[i] *
           std::pow(q.samples.x[i] * q.samples.x[i] + q.samples.y[i] * q.samples.y[i], 6);
  CHECK(std::abs(sum - kPi / 7.0) > 1e-6);
  CHECK_THROWS_AS(make_pupil_quadrature(0, 4, true), Error);
}

TEST_CASE("wave: the aberration-free singlet gives the diffraction-limited MTF, Airy ring, S = 1") {
  const Lens lens = slow_singlet();
  const TraceSystem<double> sys = prepare(lens);
  const double lambda_mm = 587.56e-6;
  const double f_number = lens.specs.f_number;
  const double cutoff = 1.0 / (lambda_mm * f_number);
  std::vector<double> freqs;
  for (int k = 0; k <= 40; ++k) freqs.push_back(cutoff * k / 40.0);
  WaveOptions options;
  options.pupil_samples = 128;
  options.focus_shift_mm = sys.bfl_mm - sys.lens.thickness_mm.back();
  const WaveReport r = analyze_wave(sys, options, freqs, {0});
  const MonoWave& mono = r.fields[0].mono[0];
  INFO("RMS ", mono.rms_waves, " P-V ", mono.pv_waves, " strehl ", mono.strehl);
  CHECK(mono.rms_waves < 0.01);  // the premise: aberration-free by its own OPD
  CHECK(mono.strehl == doctest::Approx(1.0).epsilon(1e-3));
  CHECK(mono.cutoff_t_cyc_mm == doctest::Approx(cutoff).epsilon(2e-3));
  double worst = 0;
  for (std::size_t k = 0; k < freqs.size(); ++k) {
    const double expected = diffraction_limited_mtf(freqs[k] / cutoff);
    worst = std::max({worst, std::abs(r.fields[0].mtf_t[k] - expected),
                      std::abs(r.fields[0].mtf_s[k] - expected)});
  }
  INFO("worst MTF error ", worst);
  CHECK(worst < 1e-3);

  // First dark ring: the first minimum of the PSF along x, finely sampled (padding 16), located as
  // the root of the parabola through the signed amplitudes (sqrt of the intensity, negative beyond
  // the zero) of the three samples around it.
  options.pupil_samples = 64;
  options.padding = 16;
  options.keep_psf = true;
  const WaveReport fine = analyze_wave(sys, options, {}, {0});
  const MonoWave& m = fine.fields[0].mono[0];
  const int size = m.fft_n;
  const float* row = &m.psf[static_cast<std::size_t>(size / 2) * size];
  int k = size / 2 + 1;
  while (k + 1 < size && row[k + 1] < row[k]) ++k;
  double a = std::sqrt(row[k - 1]), b = std::sqrt(row[k]), c = -std::sqrt(row[k + 1]);
  if (a < std::abs(c)) b = -b;  // the zero lies between k - 1 and k
  const double qa = 0.5 * (a + c) - b, qb = 0.5 * (c - a), qc = b;
  const double root = std::sqrt(qb * qb - 4 * qa * qc);
  const double r1 = (-qb + root) / (2 * qa), r2 = (-qb - root) / (2 * qa);
  const double offset = std::abs(r1) < std::abs(r2) ? r1 : r2;  // the root within (-1, 1)
  const double ring_um = (k - size / 2 + offset) * std::abs(m.psf_dx_um);
  const double airy_um = 1.22 * lambda_mm * 1e3 * f_number;
  INFO("ring ", ring_um, " um, Airy ", airy_um, " um");
  CHECK(ring_um == doctest::Approx(airy_um).epsilon(0.01));
}

TEST_CASE("wave: the MTF between OTF samples is interpolated to O(cell^4)") {
  // The Tessar at f/2 on axis, at its primary wavelength: an aberrated OTF that falls from 1 to
  // ~0.25 by 30 cycles/mm, while a 128-cell pupil grid samples it every 6.7 cycles/mm. Read at 10
  // and 30 cycles/mm it must agree with a 512-cell grid (samples every 1.7 cycles/mm) within
  // 2e-3; linear interpolation between the samples was off by 0.010 here (0.035 at 64 cells).
  Lens lens = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  lens.specs.wavelengths_nm = {lens.specs.primary_wavelength_nm};
  lens.specs.wavelength_channels = default_wavelength_channels(lens.specs.wavelengths_nm);
  const TraceSystem<double> sys = prepare_lens_system(lens, TraceOptions{});
  WaveOptions options;
  options.geometric = false;
  options.pupil_samples = 128;
  const WaveReport coarse = analyze_wave(sys, options, {10.0, 30.0}, {0});
  options.pupil_samples = 512;
  const WaveReport fine = analyze_wave(sys, options, {10.0, 30.0}, {0});
  for (std::size_t k = 0; k < 2; ++k) {
    const double coarse_t = coarse.fields[0].mtf_t[k], fine_t = fine.fields[0].mtf_t[k];
    INFO("frequency ", k, ": MTF ", coarse_t, " (128 cells) vs ", fine_t, " (512 cells)");
    CHECK(std::abs(coarse_t - fine_t) < 2e-3);
    CHECK(std::abs(coarse.fields[0].mtf_s[k] - fine.fields[0].mtf_s[k]) < 2e-3);
  }
  CHECK(fine.fields[0].mtf_t[1] < 0.3);  // the premise: strongly aberrated
}

TEST_CASE("wave: a known defocus gives its quadratic OPD and the closed-form Strehl ratio") {
  const Lens lens = slow_singlet();
  const TraceSystem<double> sys = prepare(lens);
  const double lambda_mm = 587.56e-6;
  const double sin_u = 1.0 / (2.0 * lens.specs.f_number);
  const double cos_u = std::sqrt(1.0 - sin_u * sin_u);
  const double focus = sys.bfl_mm - sys.lens.thickness_mm.back();  // to the paraxial focus F
  // Exit pupil to F (the wavefront's radius of curvature).
  const double radius = focus - exit_pupil_from_image_mm(sys.lens, 587.56);
  const PupilGrid grid = make_pupil_grid(64);
  RayBundle<double> rays;
  RayRecord<double> record;
  // The quadratic coefficient of a least squares fit W = a + b rho^2.
  auto quadratic = [&](double shift) {
    const ReferenceSphere<double> sphere = reference_sphere(sys, 0, shift);
    const Wavefront<double> wf = compute_wavefront(sys, 0, 0, grid, sphere, shift, rays, record);
    double s0 = 0, s1 = 0, s2 = 0, t0 = 0, t1 = 0;
    for (std::size_t i = 0; i < grid.size(); ++i) {
      if (!wf.ok[i]) continue;
      const double r2 =
          grid.samples.x[i] * grid.samples.x[i] + grid.samples.y[i] * grid.samples.y[i];
      const double a = grid.weight[i];
      s0 += a;
      s1 += a * r2;
      s2 += a * r2 * r2;
      t0 += a * wf.opd_waves[i];
      t1 += a * r2 * wf.opd_waves[i];
    }
    return (s0 * t1 - s1 * t0) / (s0 * s2 - s1 * s1);
  };
  const double intrinsic = quadratic(focus);  // the singlet's own (spherical aberration's) part
  for (double nominal : {0.15, 0.3}) {
    CAPTURE(nominal);
    // Image plane dz beyond F: the sphere about F + dz with radius R + dz meets the marginal ray
    // (angle u_m) at t from F, t^2 + 2 t dz cos u + dz^2 = (R + dz)^2, while the converging
    // wavefront's sphere about F is at R: W(1) - W(0) = -(t - R) / lambda = -W020.
    const double dz = nominal * lambda_mm / (1.0 - cos_u);
    const double t =
        -dz * cos_u + std::sqrt(dz * dz * cos_u * cos_u + radius * radius + 2 * radius * dz);
    const double w020 = (t - radius) / lambda_mm;
    CAPTURE(w020);
    CHECK(-(quadratic(focus + dz) - intrinsic) == doctest::Approx(w020).epsilon(0.01));

    WaveOptions options;
    options.pupil_samples = 128;
    options.focus_shift_mm = focus + dz;
    const WaveReport r = analyze_wave(sys, options, {}, {0});
    const double x = kPi * w020;
    const double closed = std::pow(std::sin(x) / x, 2);
    CHECK(r.fields[0].mono[0].strehl == doctest::Approx(closed).epsilon(0.01));
  }
}

TEST_CASE("wave: RMS wavefront derivatives match central finite differences") {
  const Lens lens = read_lens(lensopt::test::source_dir() / "lenses/cooke.toml");
  TraceOptions options;
  options.fields = 3;
  const PupilGrid grid = make_pupil_grid(12);
  auto rms = [&](const Lens& l) {
    const TraceSystem<double> sys = prepare_system(make_trace_lens(l), l.specs, options);
    return mean_rms_wavefront(sys, grid);
  };
  std::vector<PrescriptionVariable> variables;
  for (const PrescriptionVariable& v : all_prescription_variables(lens))
    if (v.kind == PrescriptionVariable::Kind::kCurvature ||
        v.kind == PrescriptionVariable::Kind::kThickness)
      variables.push_back(v);
  constexpr int kWidth = 16;
  REQUIRE(variables.size() <= static_cast<std::size_t>(kWidth));
  using J = ceres::Jet<double, kWidth>;
  const TraceLens<J> lens_j =
      convert_trace_lens<J>(make_trace_lens(lens), variables, 0, static_cast<int>(variables.size()),
                            [](double v, int j) { return J(v, j); });
  const TraceSystem<J> sys_j = prepare_system(lens_j, lens.specs, options);
  const J value = mean_rms_wavefront(sys_j, grid);
  CHECK(value.a == doctest::Approx(rms(lens)).epsilon(1e-12));
  INFO("mean RMS wavefront ", value.a, " waves");
  for (std::size_t j = 0; j < variables.size(); ++j) {
    const PrescriptionVariable& v = variables[j];
    const double x0 = variable_value(lens, v);
    const double scale = v.kind == PrescriptionVariable::Kind::kCurvature ? 0.05 : 1.0;
    auto central = [&](double h) {
      Lens plus = lens, minus = lens;
      set_variable_value(plus, v, x0 + h);
      set_variable_value(minus, v, x0 - h);
      return (rms(plus) - rms(minus)) / (2 * h);
    };
    const double h = 2e-5 * scale;
    const double fd = (4 * central(h / 2) - central(h)) / 3;
    INFO("d/d", v.name(), ": jet ", value.v[j], " fd ", fd);
    CHECK(std::abs(value.v[j] - fd) <= 1e-6 * std::max(std::abs(fd), 1e-3));
  }
}

TEST_CASE("wave: Zernike orderings follow Noll (Standard) and the Fringe table") {
  const double x = 0.3, y = -0.5;
  const double r2 = x * x + y * y, r = std::sqrt(r2), t = std::atan2(y, x);
  using Z = ZernikeOrdering;
  // Standard (Noll): Z2 = 2 r cos, Z3 = 2 r sin, Z4 = sqrt3 (2r^2-1), Z5 = sqrt6 r^2 sin 2t,
  // Z6 = sqrt6 r^2 cos 2t, Z7 = sqrt8 (3r^3-2r) sin t, Z11 = sqrt5 (6r^4-6r^2+1).
  CHECK(zernike_value(Z::kStandard, 1, x, y) == doctest::Approx(1.0));
  CHECK(zernike_value(Z::kStandard, 2, x, y) == doctest::Approx(2 * r * std::cos(t)));
  CHECK(zernike_value(Z::kStandard, 3, x, y) == doctest::Approx(2 * r * std::sin(t)));
  CHECK(zernike_value(Z::kStandard, 4, x, y) == doctest::Approx(std::sqrt(3.0) * (2 * r2 - 1)));
  CHECK(zernike_value(Z::kStandard, 5, x, y) ==
        doctest::Approx(std::sqrt(6.0) * r2 * std::sin(2 * t)));
  CHECK(zernike_value(Z::kStandard, 6, x, y) ==
        doctest::Approx(std::sqrt(6.0) * r2 * std::cos(2 * t)));
  CHECK(zernike_value(Z::kStandard, 7, x, y) ==
        doctest::Approx(std::sqrt(8.0) * (3 * r2 * r - 2 * r) * std::sin(t)));
  CHECK(zernike_value(Z::kStandard, 11, x, y) ==
        doctest::Approx(std::sqrt(5.0) * (6 * r2 * r2 - 6 * r2 + 1)));
  // Fringe: Z4 = 2r^2-1, Z5 = r^2 cos 2t, Z9 = 6r^4-6r^2+1, Z10 = r^3 cos 3t, Z16 = R_6^0,
  // Z36 = R_10^0, Z37 = R_12^0 (the set ends there).
  CHECK(zernike_value(Z::kFringe, 4, x, y) == doctest::Approx(2 * r2 - 1));
  CHECK(zernike_value(Z::kFringe, 5, x, y) == doctest::Approx(r2 * std::cos(2 * t)));
  CHECK(zernike_value(Z::kFringe, 9, x, y) == doctest::Approx(6 * r2 * r2 - 6 * r2 + 1));
  CHECK(zernike_value(Z::kFringe, 10, x, y) == doctest::Approx(r2 * r * std::cos(3 * t)));
  CHECK(zernike_value(Z::kFringe, 16, x, y) ==
        doctest::Approx(20 * std::pow(r, 6) - 30 * r2 * r2 + 12 * r2 - 1));
  const ZernikeTerm z37 = zernike_term(Z::kFringe, 37);
  CHECK(z37.n == 12);
  CHECK(z37.m == 0);
  const ZernikeTerm z36 = zernike_term(Z::kFringe, 36);
  CHECK(z36.n == 10);
  CHECK(z36.m == 0);
  const ZernikeTerm z35 = zernike_term(Z::kFringe, 35);  // R_9^1 sin
  CHECK(z35.n == 9);
  CHECK(z35.m == 1);
  CHECK(z35.sine);
  CHECK_THROWS_AS(zernike_term(Z::kFringe, 38), Error);
  CHECK(zernike_term(Z::kStandard, 38).n == 8);  // Noll goes on: Z37 = R_8^0, Z38 = R_8^2
  CHECK_THROWS_AS(zernike_term(Z::kFringe, 0), Error);
  CHECK_THROWS_AS(parse_zernike_ordering("zygo"), Error);
  // Standard terms have unit RMS over the disk (fine grid, area weights).
  const PupilGrid grid = make_pupil_grid(256);
  for (int j : {1, 4, 8, 11, 22, 36}) {
    double s = 0, a = 0;
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const double v = zernike_value(Z::kStandard, j, grid.samples.x[i], grid.samples.y[i]);
      s += grid.weight[i] * v * v;
      a += grid.weight[i];
    }
    CAPTURE(j);
    CHECK(std::sqrt(s / a) == doctest::Approx(1.0).epsilon(2e-3));
  }
}

TEST_CASE("wave: a wavefront made of known Zernike terms is recovered to 1e-10") {
  const PupilGrid grid = make_pupil_grid(48);
  for (const ZernikeOrdering ordering : {ZernikeOrdering::kFringe, ZernikeOrdering::kStandard}) {
    const int terms = ordering == ZernikeOrdering::kFringe ? 37 : 45;
    Wavefront<double> wf;
    wf.opd_waves.assign(grid.size(), 0.0);
    wf.ok.assign(grid.size(), 1);
    std::vector<double> truth(terms);
    for (int j = 1; j <= terms; ++j) truth[j - 1] = 0.3 * std::sin(1.7 * j) / j;
    int excluded = 0;
    for (std::size_t i = 0; i < grid.size(); ++i) {
      // A vignetted top edge: its values are garbage and must not enter the fit.
      if (grid.samples.y[i] > 0.85) {
        wf.ok[i] = 0;
        wf.opd_waves[i] = 1e6;
        ++excluded;
        continue;
      }
      for (int j = 1; j <= terms; ++j)
        wf.opd_waves[i] +=
            truth[j - 1] * zernike_value(ordering, j, grid.samples.x[i], grid.samples.y[i]);
    }
    REQUIRE(excluded > 0);
    const ZernikeFit fit = fit_zernike(wf, grid, terms, ordering);
    CAPTURE(zernike_ordering_name(ordering));
    CHECK(fit.samples == static_cast<int>(grid.size()) - excluded);
    double worst = 0;
    for (int j = 0; j < terms; ++j)
      worst = std::max(worst, std::abs(fit.coefficients_waves[j] - truth[j]));
    INFO("worst coefficient error ", worst);
    CHECK(worst < 1e-10);
    CHECK(fit.residual_rms_waves < 1e-10);
    // Fewer terms than the wavefront holds leave a misfit.
    CHECK(fit_zernike(wf, grid, 10, ordering).residual_rms_waves > 1e-3);
  }
}

TEST_CASE("wave: wavefront_mm_per_wave is the RMS spot per wave of RMS wavefront of a defocus") {
  // The aberration-free slow singlet with its image plane dz beyond the paraxial focus F: the
  // RMS radius of its rays about the chief ray's point (the wavefront's own image positions, on
  // the quadrature) over its RMS wavefront is 4 sqrt(6) N' lambda, N' = (R + dz) / (2 r_p) the
  // f-number of the cone from the exit pupil (radius r_p, at R before F) to the plane: the
  // sphere about the plane's point has radius R + dz, so W020 = r_p^2 dz / (2 R (R + dz)) /
  // lambda while the spot grows as r_p dz / R. At dz -> 0 that is wavefront_mm_per_wave.
  const Lens lens = slow_singlet();
  const TraceSystem<double> sys = prepare(lens);
  const double focus = sys.bfl_mm - sys.lens.thickness_mm.back();
  const double radius = focus - exit_pupil_from_image_mm(sys.lens, 587.56);
  const PupilGrid q = make_pupil_quadrature(8, 16, false);
  RayBundle<double> rays;
  RayRecord<double> record;
  const double unit = wavefront_mm_per_wave(sys);
  CHECK(unit == doctest::Approx(4 * std::sqrt(6.0) * 40.0 * 587.5618e-6).epsilon(1e-3).scale(0));
  for (double dz : {2.0, 10.0, 30.0}) {  // W020 ~ dz / (8 N^2 lambda): 0.27, 1.3 and 4 waves
    const ReferenceSphere<double> sphere = reference_sphere(sys, 0, focus + dz);
    const Wavefront<double> wf = compute_wavefront(sys, 0, 0, q, sphere, focus + dz, rays, record);
    double sum = 0, weight = 0;
    for (std::size_t i = 0; i < q.size(); ++i) {
      REQUIRE(wf.ok[i]);
      sum +=
          q.weight[i] * (wf.image_x_mm[i] * wf.image_x_mm[i] + wf.image_y_mm[i] * wf.image_y_mm[i]);
      weight += q.weight[i];
    }
    const double spot_mm = std::sqrt(sum / weight);
    CAPTURE(dz);
    CAPTURE(wf.rms_waves);
    CHECK(wf.rms_waves > 0.07);  // far above the singlet's own (< 1e-3 waves)
    CHECK(spot_mm / wf.rms_waves ==
          doctest::Approx(unit * (radius + dz) / radius).epsilon(5e-3).scale(0));
  }
}

TEST_CASE("wave: a known defocus gives the Zernike defocus term of the OPD's quadratic term") {
  const Lens lens = slow_singlet();
  const TraceSystem<double> sys = prepare(lens);
  const double lambda_mm = 587.56e-6;
  const double sin_u = 1.0 / (2.0 * lens.specs.f_number);
  const double cos_u = std::sqrt(1.0 - sin_u * sin_u);
  const double focus = sys.bfl_mm - sys.lens.thickness_mm.back();
  const double radius = focus - exit_pupil_from_image_mm(sys.lens, 587.56);
  const PupilGrid grid = make_pupil_grid(64);
  RayBundle<double> rays;
  RayRecord<double> record;
  auto wavefront = [&](double shift) {
    const ReferenceSphere<double> sphere = reference_sphere(sys, 0, shift);
    return compute_wavefront(sys, 0, 0, grid, sphere, shift, rays, record);
  };
  // The least squares W = a + b rho^2 (the OPD's quadratic term b).
  auto quadratic = [&](const Wavefront<double>& wf) {
    double s0 = 0, s1 = 0, s2 = 0, t0 = 0, t1 = 0;
    for (std::size_t i = 0; i < grid.size(); ++i) {
      if (!wf.ok[i]) continue;
      const double r2 =
          grid.samples.x[i] * grid.samples.x[i] + grid.samples.y[i] * grid.samples.y[i];
      const double a = grid.weight[i];
      s0 += a;
      s1 += a * r2;
      s2 += a * r2 * r2;
      t0 += a * wf.opd_waves[i];
      t1 += a * r2 * wf.opd_waves[i];
    }
    return (s0 * t1 - s1 * t0) / (s0 * s2 - s1 * s1);
  };
  const Wavefront<double> at_focus = wavefront(focus);
  const double c4_focus =
      fit_zernike(at_focus, grid, 4, ZernikeOrdering::kFringe).coefficients_waves[3];
  const double dz = 0.3 * lambda_mm / (1.0 - cos_u);
  const double t =
      -dz * cos_u + std::sqrt(dz * dz * cos_u * cos_u + radius * radius + 2 * radius * dz);
  const double w020 = (t - radius) / lambda_mm;
  const Wavefront<double> defocused = wavefront(focus + dz);
  const double b = quadratic(defocused);
  // On axis the 4-term fit spans {1, x, y, rho^2}: Fringe Z4 = 2 rho^2 - 1 gives b = 2 c4,
  // Standard Z4 = sqrt3 (2 rho^2 - 1) gives b = 2 sqrt3 c4.
  const ZernikeFit fringe = fit_zernike(defocused, grid, 4, ZernikeOrdering::kFringe);
  const ZernikeFit standard = fit_zernike(defocused, grid, 4, ZernikeOrdering::kStandard);
  CHECK(2 * fringe.coefficients_waves[3] == doctest::Approx(b).epsilon(1e-9));
  CHECK(2 * std::sqrt(3.0) * standard.coefficients_waves[3] == doctest::Approx(b).epsilon(1e-9));
  // And the defocus added is the closed form's W020 (the singlet's own spherical removed).
  CAPTURE(w020);
  CHECK(-2 * (fringe.coefficients_waves[3] - c4_focus) == doctest::Approx(w020).epsilon(0.01));

  // analyze_wave reports the same fit per field and wavelength.
  WaveOptions options;
  options.pupil_samples = 64;
  options.focus_shift_mm = focus + dz;
  options.zernike_terms = 4;
  const WaveReport r = analyze_wave(sys, options, {}, {0});
  REQUIRE(r.fields[0].mono[0].zernike_waves.size() == 4);
  CHECK(r.fields[0].mono[0].zernike_waves[3] ==
        doctest::Approx(fringe.coefficients_waves[3]).epsilon(1e-12));
  const std::string json = format_wave_json(r);
  CHECK(json.find("\"zernike_waves\"") != std::string::npos);
  CHECK(json.find("\"zernike_ordering\":\"fringe\"") != std::string::npos);
  CHECK(format_wave_text(r).find("Zernike fringe coefficients") != std::string::npos);
}

}  // namespace test_wave
