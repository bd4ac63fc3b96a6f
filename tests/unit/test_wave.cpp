// Wave optics (analysis/wavefront.h, analysis/wave.h) against closed forms: an aberration-free
// slow singlet (checked by its own OPD) gives the diffraction-limited MTF, the Airy ring and a
// Strehl ratio of 1; a known defocus gives its quadratic OPD and the closed-form Strehl; the RMS
// wavefront's Jet derivatives match central finite differences.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <cmath>

#include "lensopt/analysis/wave.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "test_support.h"

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
