// The mtf target (optimize/targets.h): the polychromatic geometric MTF of a field at a frequency,
// tangential, sagittal or their average (OpticStudio's GMTT, GMTS, GMTA), on a lens that is not
// one of the paper's baselines (lenses/zmx/cooke_triplet_50.zmx, as written). Its value against
// the geometric MTF of analyze --wave (analysis/wave.cpp, a separate double-only implementation)
// and against the Fourier transform of the spot written here from the traced ray intercepts; its
// residual Jacobian (Jets) against central finite differences on the optimizer's mirrored
// quadrature and on a full grid; the --target text and [[optimize.targets]] keys with their
// errors; and a run that raises a field's MTF to a bound.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <fstream>
#include <string>

#include "lensopt/analysis/wave.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace test_optimize_mtf {

using namespace lensopt;

namespace {

// The Cooke triplet f/5, f = 50 mm, fields 0, 14, 20 deg, F, d, C with equal weights.
Lens cooke_50() {
  return read_lens(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx");
}

DesignTarget mtf_target(double value, double freq, int field, MtfOrientation o,
                        TargetRelation relation = TargetRelation::kEqual) {
  DesignTarget t;
  t.quantity = TargetQuantity::kMtf;
  t.relation = relation;
  t.value = value;
  t.frequency_cpmm = freq;
  t.field = field;
  t.orientation = o;
  return t;
}

// The polychromatic geometric MTF written out from the ray intercepts on the image plane: per
// wavelength the line spread of the spot along y (tangential, the field's direction) or x
// (sagittal), transformed at nu: OTF_w = sum_i a_i exp(-2 pi i nu y_i) / sum_i a_i over the rays
// of `grid` that arrived (a_i the cell's area weight); OTF = sum_w omega_w OTF_w / sum_w omega_w;
// MTF = |OTF|. The image coordinates are absolute (not relative to a reference point): a common
// shift of every ray is a phase factor of the OTF, which the modulus drops.
struct IndependentMtf {
  double tangential = 0.0, sagittal = 0.0;
  int rays = 0;  // arrived, over all wavelengths
};
IndependentMtf spot_transform_mtf(const TraceSystem<double>& sys, int h, double nu,
                                  const PupilGrid& grid, const std::vector<double>& omega) {
  const std::complex<double> i_unit(0.0, 1.0);
  std::complex<double> t(0.0), s(0.0);
  double omega_sum = 0.0;
  IndependentMtf out;
  for (int w = 0; w < sys.wavelength_count; ++w) {
    RayBundle<double> rays;
    start_rays(sys, h, w, rays, &grid.samples);
    trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                 static_cast<RayRecord<double>*>(nullptr));
    std::complex<double> tw(0.0), sw(0.0);
    double a_sum = 0.0;
    for (std::size_t i = 0; i < grid.size(); ++i) {
      if (rays.status[i] != kRayOk) continue;
      ++out.rays;
      a_sum += grid.weight[i];
      tw += grid.weight[i] * std::exp(-2.0 * kPi * nu * rays.y[i] * i_unit);
      sw += grid.weight[i] * std::exp(-2.0 * kPi * nu * rays.x[i] * i_unit);
    }
    const double o = omega.empty() ? 1.0 : omega[w];
    t += o * tw / a_sum;
    s += o * sw / a_sum;
    omega_sum += o;
  }
  out.tangential = std::abs(t / omega_sum);
  out.sagittal = std::abs(s / omega_sum);
  return out;
}

}  // namespace

TEST_CASE("mtf target: analyze's geometric MTF and the spot's transform, per field and azimuth") {
  const Lens lens = cooke_50();
  REQUIRE(lens.specs.mode == SpecMode::kAsWritten);
  const TraceOptions sampling;  // as check_targets and analyze trace the lens
  const TraceSystem<double> sys = prepare_lens_system(lens, sampling);
  REQUIRE(sys.fields_deg.size() == 3);
  const std::vector<double> omega = lens_wavelength_weights(lens, sys.wavelength_count);
  for (const double freq : {10.0, 30.0, 50.0}) {
    std::vector<DesignTarget> targets;
    for (int field = 1; field <= 3; ++field)
      for (MtfOrientation o :
           {MtfOrientation::kTangential, MtfOrientation::kSagittal, MtfOrientation::kAverage})
        targets.push_back(mtf_target(0.5, freq, field, o));
    const TargetReport report = check_targets(lens, targets, sampling);
    REQUIRE(report.rows.size() == 9);
    // analyze --wave on the report's 32 x 32 grid (the same rays), and at its default 128.
    WaveOptions wo;
    wo.threads = 1;
    wo.wavelength_weights = omega;
    wo.pupil_samples = 32;
    const WaveReport wave32 = analyze_wave(sys, wo, {freq});
    wo.pupil_samples = 128;
    const WaveReport wave128 = analyze_wave(sys, wo, {freq});
    const PupilGrid grid = make_pupil_grid(32);
    for (int field = 0; field < 3; ++field) {
      const double t = report.rows[3 * field + 0].value, s = report.rows[3 * field + 1].value,
                   a = report.rows[3 * field + 2].value;
      const IndependentMtf ind = spot_transform_mtf(sys, field, freq, grid, omega);
      MESSAGE("cooke_triplet_50 field ", field + 1, " (", sys.fields_deg[field], " deg) at ", freq,
              " c/mm: target T ", t, " S ", s, "; analyze (32) T ",
              wave32.fields[field].geo_mtf_t[0], " S ", wave32.fields[field].geo_mtf_s[0],
              "; analyze (128) T ", wave128.fields[field].geo_mtf_t[0], " S ",
              wave128.fields[field].geo_mtf_s[0], "; spot transform T ", ind.tangential, " S ",
              ind.sagittal);
      CHECK(ind.rays == 3 * static_cast<int>(grid.size()));  // every ray arrived
      // The independent transform of the ray intercepts: 1e-12.
      CHECK(std::abs(t - ind.tangential) <= 1e-12);
      CHECK(std::abs(s - ind.sagittal) <= 1e-12);
      CHECK(std::abs(a - 0.5 * (ind.tangential + ind.sagittal)) <= 1e-12);
      // analyze on the same grid: 1e-12; on its default 128 x 128 grid the value differs by
      // the sampling (measured up to 1.4e-3 here, field 3 tangential at 10 c/mm): 3e-3.
      CHECK(std::abs(t - wave32.fields[field].geo_mtf_t[0]) <= 1e-12);
      CHECK(std::abs(s - wave32.fields[field].geo_mtf_s[0]) <= 1e-12);
      CHECK(std::abs(t - wave128.fields[field].geo_mtf_t[0]) <= 3e-3);
      CHECK(std::abs(s - wave128.fields[field].geo_mtf_s[0]) <= 3e-3);
      CHECK(t > 0.0);
      CHECK(t < 1.0);
    }
    // The axial field is rotationally symmetric: T = S.
    CHECK(std::abs(report.rows[0].value - report.rows[1].value) <= 1e-12);
  }
  // Tangential follows the field's direction, not the lens's y axis: the 14 deg field put on x
  // (and at 45 deg) has the T and S of the 14 deg field on y (a rotationally symmetric lens).
  const std::vector<DesignTarget> pair = {mtf_target(0.5, 30.0, 2, MtfOrientation::kTangential),
                                          mtf_target(0.5, 30.0, 2, MtfOrientation::kSagittal)};
  const TargetReport on_y = check_targets(lens, pair, sampling);
  REQUIRE(std::abs(on_y.rows[0].value - on_y.rows[1].value) > 0.1);  // T and S differ there
  for (const double azimuth_deg : {90.0, 45.0}) {
    Lens turned = lens;
    FieldPoint& f = turned.specs.fields.at(1);
    REQUIRE(f.value == 14.0);
    f.x = 14.0 * std::sin(azimuth_deg * kPi / 180.0);
    f.value = 14.0 * std::cos(azimuth_deg * kPi / 180.0);
    if (azimuth_deg == 90.0) f.value = 0.0;
    const TargetReport r = check_targets(turned, pair, sampling);
    INFO("field 2 at azimuth ", azimuth_deg, " deg: T ", r.rows[0].value, " S ", r.rows[1].value);
    CHECK(std::abs(r.rows[0].value - on_y.rows[0].value) <= 1e-9);
    CHECK(std::abs(r.rows[1].value - on_y.rows[1].value) <= 1e-9);
  }
}

TEST_CASE("mtf target: residual Jacobians (Jets) match central finite differences") {
  const Lens lens = cooke_50();
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  const std::vector<double> x = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  const TraceOptions sampling;
  // Equalities with value 0: each residual is u_q * MTF = MTF / nu (targets.h).
  const std::vector<DesignTarget> targets = {
      mtf_target(0.0, 30.0, 2, MtfOrientation::kTangential),
      mtf_target(0.0, 30.0, 3, MtfOrientation::kSagittal),
      mtf_target(0.0, 20.0, 3, MtfOrientation::kAverage),
      mtf_target(0.0, 50.0, 1, MtfOrientation::kTangential),
  };
  using J = ceres::Jet<double, 24>;
  REQUIRE(param.size() <= 24);
  for (const GlassMode mode : {GlassMode::kFixed, GlassMode::kContinuous}) {
    for (const bool mirrored : {true, false}) {
      TargetSampling ts;
      // The optimizer's wavefront quadrature (mirrored) and a full 24 x 24 grid.
      ts.wavefront_grid = mirrored ? make_pupil_quadrature(6, 8, true) : make_pupil_grid(24);
      const int count = target_residual_count(targets, 3);
      REQUIRE(count == 4);
      auto residuals = [&](const std::vector<double>& xs) {
        std::vector<double> r(count);
        REQUIRE(evaluate_targets<double>(param, xs.data(), mode, glasses, sampling, targets, ts,
                                         1.0, 0.0, r.data()));
        return r;
      };
      std::vector<J> xj(param.size());
      for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
      std::vector<J> rj(count);
      REQUIRE(evaluate_targets<J>(param, xj.data(), mode, glasses, sampling, targets, ts, 1.0, 0.0,
                                  rj.data()));
      const std::vector<double> r0 = residuals(x);
      // Central differences with one Richardson step (error O(h^4)), h = 1e-5.
      std::vector<std::vector<double>> fd(count, std::vector<double>(param.size()));
      for (int i = 0; i < param.size(); ++i) {
        auto central = [&](double h) {
          std::vector<double> plus = x, minus = x;
          plus[i] += h;
          minus[i] -= h;
          const std::vector<double> rp = residuals(plus), rm = residuals(minus);
          std::vector<double> d(count);
          for (int row = 0; row < count; ++row) d[row] = (rp[row] - rm[row]) / (2 * h);
          return d;
        };
        const std::vector<double> d1 = central(1e-5), d2 = central(5e-6);
        for (int row = 0; row < count; ++row) fd[row][i] = (4 * d2[row] - d1[row]) / 3;
      }
      const std::string grid_name = mirrored ? "mirrored quadrature" : "full 24 x 24 grid";
      const std::string mode_name =
          mode == GlassMode::kFixed ? "fixed glasses" : "continuous glasses";
      for (int row = 0; row < count; ++row) {
        // The Jet's value is the double's, to rounding (the Jet operations round differently).
        CHECK(std::abs(rj[row].a - r0[row]) <= 1e-12 * std::abs(r0[row]));
        CHECK(r0[row] > 0.0);
        double largest = 0.0;
        for (int i = 0; i < param.size(); ++i) largest = std::max(largest, std::abs(fd[row][i]));
        double worst = 0.0;
        int checked = 0;
        for (int i = 0; i < param.size(); ++i) {
          const LensVariable& v = param.variables()[i];
          // Relative to the derivative, or to 1e-3 of the row's largest for the tiny ones.
          const double err =
              std::abs(rj[row].v[i] - fd[row][i]) / std::max(std::abs(fd[row][i]), 1e-3 * largest);
          worst = std::max(worst, err);
          checked += std::abs(fd[row][i]) >= 1e-3 * largest;
          INFO(grid_name, ", ", mode_name, ", ", target_text(targets[row]), ", ", v.name, ": jet ",
               rj[row].v[i], " fd ", fd[row][i]);
          CHECK(err <= 1e-6);
          if (mode == GlassMode::kFixed && v.group == "glasses") CHECK(rj[row].v[i] == 0.0);
        }
        MESSAGE(grid_name, ", ", mode_name, ", ", target_text(targets[row]), ": value ",
                r0[row] * targets[row].frequency_cpmm, ", ", checked,
                " derivatives checked, worst relative difference to FD ", worst);
        CHECK(checked >= 8);
      }
    }
  }
}

TEST_CASE("mtf target: --target text, [[optimize.targets]] keys and their errors") {
  const DesignTarget t =
      parse_target("mtf >= 0.4, freq=30, field=2, orientation=sagittal", SourceLocation{});
  CHECK(t.quantity == TargetQuantity::kMtf);
  CHECK(t.relation == TargetRelation::kAtLeast);
  CHECK(t.value == 0.4);
  CHECK(t.frequency_cpmm == 30.0);
  CHECK(t.field == 2);
  CHECK(t.orientation == MtfOrientation::kSagittal);
  CHECK(target_text(t) == "mtf(30 c/mm, sagittal)[field 2] >= 0.4");
  CHECK(parse_target("mtf>=0.4,freq=30", SourceLocation{}).orientation == MtfOrientation::kAverage);
  CHECK(parse_target("mtf>=0.5,freq=30,field=1,orientation=t", SourceLocation{}).orientation ==
        MtfOrientation::kTangential);
  auto message = [](const std::string& text) {
    try {
      parse_target(text, SourceLocation{"--target"});
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  CHECK(message("mtf>=0.4").find("frequency in cycles/mm") != std::string::npos);
  CHECK(message("mtf>=0.4,freq=0").find("frequency in cycles/mm") != std::string::npos);
  CHECK(message("mtf>=1.5,freq=30").find("[0, 1]") != std::string::npos);
  CHECK(message("efl_mm=100,freq=30").find("mtf targets only") != std::string::npos);
  CHECK(message("mtf>=0.4,freq=30,orientation=diagonal").find("tangential, sagittal or average") !=
        std::string::npos);
  // The same quantity at another frequency or orientation is another target.
  const DesignTarget u = parse_target("mtf >= 0.4, freq=30, field=2", SourceLocation{});
  CHECK_FALSE(same_target(t, u));
  CHECK(same_target(t, t));

  const Lens base = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  const std::filesystem::path path = test::temp_root() / "mtf-targets.toml";
  {
    std::ofstream out(path);
    out << format_lens_toml(base)
        << "\n[[optimize.targets]]\nmtf = \">= 0.3\"\nfrequency_cpmm = 20\n"
           "orientation = \"tangential\"\nfield = 1\n";
  }
  const ResolvedOptimizeOptions r = resolve_optimize_options(read_lens(path), OptimizeOverrides{});
  std::vector<DesignTarget> mtf;
  for (const DesignTarget& d : r.options.targets)
    if (d.quantity == TargetQuantity::kMtf) mtf.push_back(d);
  REQUIRE(mtf.size() == 1);
  CHECK(mtf[0].frequency_cpmm == 20.0);
  CHECK(mtf[0].orientation == MtfOrientation::kTangential);
  CHECK(mtf[0].value == 0.3);
  CHECK(mtf[0].field == 1);
  const std::filesystem::path bad = test::temp_root() / "mtf-bad.toml";
  {
    std::ofstream out(bad);
    out << format_lens_toml(base) << "\n[[optimize.targets]]\nmtf = \">= 0.3\"\n";
  }
  try {
    resolve_optimize_options(read_lens(bad), OptimizeOverrides{});
    FAIL("accepted");
  } catch (const Error& e) {
    const std::string m = e.what();
    INFO(m);
    CHECK(m.find("mtf-bad.toml:") != std::string::npos);
    CHECK(m.find("frequency") != std::string::npos);
  }
}

TEST_CASE("mtf target: optimize raises a field's tangential MTF to a bound") {
  const Lens lens = cooke_50();
  const TraceOptions sampling;
  const DesignTarget goal =
      mtf_target(0.5, 30.0, 2, MtfOrientation::kTangential, TargetRelation::kAtLeast);
  const double start = check_targets(lens, {goal}, sampling).rows[0].value;
  OptimizeOptions o;
  o.glass_search = GlassSearch::kNone;
  o.verbose = false;
  o.loss = bounds_for(lens, o.loss, BoundsMode::kAuto);
  o.targets = targets_with_defaults(lens, {goal});
  const OptimizeResult r = optimize_lens(lens, o);
  const TargetRow* before = nullptr;
  const TargetRow* after = nullptr;
  for (const TargetRow& t : r.start_targets.rows)
    if (t.target.quantity == TargetQuantity::kMtf) before = &t;
  for (const TargetRow& t : r.final_targets.rows)
    if (t.target.quantity == TargetQuantity::kMtf) after = &t;
  REQUIRE(before != nullptr);
  REQUIRE(after != nullptr);
  // The written lens, measured again as analyze measures it.
  const double written = check_targets(r.lens, {goal}, sampling).rows[0].value;
  MESSAGE("cooke_triplet_50 field 2 (14 deg), tangential geometric MTF at 30 c/mm: ", start, " -> ",
          after->value, " (written lens ", written, "), bound 0.5; mean spot ", r.start_spot_um,
          " -> ", r.final_spot_um, " um");
  CHECK(before->value == doctest::Approx(start).epsilon(1e-12));
  CHECK(start < 0.2);  // 0.148 at the start
  CHECK_FALSE(before->pass);
  CHECK(after->pass);
  CHECK(after->value >= 0.5);
  CHECK(written == doctest::Approx(after->value).epsilon(1e-9));
  CHECK(r.final_constraints.all_pass());
  // The default target holds the lens's own focal length.
  for (const TargetRow& t : r.final_targets.rows)
    if (t.target.quantity == TargetQuantity::kEflMm) CHECK(t.pass);
}

}  // namespace test_optimize_mtf
