// The adjoint (reverse-mode) gradient of the mean spot against the Jet gradient (forward mode,
// itself checked against finite differences in test_gradient.cpp) and against central finite
// differences: the three baselines and the .zmx lenses, with and without ray aiming and scaling;
// and the adjoint gradient of the lens design loss l_lens against its Jet gradient.
#include <doctest/doctest.h>

#include <cmath>

#include "lensopt/analysis/spot_adjoint.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/profile_bounds.h"
#include "test_support.h"
#include "trace_checks.h"

namespace test_spot_adjoint {

using namespace lensopt;

namespace {

using test::mean_spot;
using test::worst_relative;

// The adjoint equals the Jet gradient within 1e-9 relative; the value equals the evaluation.
void check_against_jets(const Lens& lens, const TraceOptions& options) {
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  const SpotGradient jets = mean_spot_gradient_auto(trace_lens, lens.specs, variables, options);
  const SpotGradient adjoint =
      mean_spot_gradient_adjoint<8>(trace_lens, lens.specs, variables, options);
  REQUIRE(adjoint.gradient.size() == variables.size());
  CHECK(adjoint.mean_rms_spot_mm == doctest::Approx(mean_spot(lens, options)).epsilon(1e-12));
  const double worst = worst_relative(adjoint.gradient, jets.gradient);
  for (std::size_t i = 0; i < variables.size(); ++i)
    INFO(variables[i].name(), ": adjoint ", adjoint.gradient[i], " jets ", jets.gradient[i]);
  INFO(lens.name, ": worst relative difference ", worst);
  CHECK(worst < 1e-9);
}

}  // namespace

TEST_CASE("spot adjoint: equals the Jet gradient on the baselines (full sampling, aiming on)") {
  for (const char* name : {"doublet", "cooke", "tessar"}) {
    const Lens lens = read_lens(test::source_dir() / "lenses" / (std::string(name) + ".toml"));
    check_against_jets(lens, TraceOptions{});
  }
}

TEST_CASE("spot adjoint: without ray aiming, without scaling, and on the .zmx lenses") {
  for (const char* name : {"doublet", "cooke", "tessar"}) {
    const Lens lens = read_lens(test::source_dir() / "lenses" / (std::string(name) + ".toml"));
    TraceOptions options;
    options.rings = 12;
    options.fields = 7;
    options.ray_aiming = false;
    check_against_jets(lens, options);
    options.ray_aiming = true;
    options.scale_to_spec = false;
    check_against_jets(lens, options);
  }
  for (const char* name : {"achromat_ac254_100", "cooke_triplet_50", "double_gauss_100"}) {
    const Lens lens =
        read_zmx(test::source_dir() / "lenses" / "zmx" / (std::string(name) + ".zmx")).lens;
    TraceOptions options;
    options.rings = 12;
    options.fields = 7;
    for (bool aiming : {true, false}) {
      options.ray_aiming = aiming;
      check_against_jets(lens, options);
    }
  }
}

TEST_CASE("spot adjoint: matches central finite differences, and a single thread") {
  // The Cooke at reduced sampling: every variable against a Richardson-extrapolated central
  // difference (as test_gradient.cpp), with and without ray aiming.
  const Lens lens = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  for (bool aiming : {true, false}) {
    TraceOptions options;
    options.rings = 10;
    options.fields = 5;
    options.ray_aiming = aiming;
    const SpotGradient g =
        mean_spot_gradient_adjoint<24>(make_trace_lens(lens), lens.specs, variables, options);
    const std::vector<double> fd =
        test::mean_spot_central_differences(lens, variables, options, 0.05);
    const double worst = worst_relative(g.gradient, fd);
    INFO("aiming ", aiming, ": worst relative error against finite differences ", worst);
    CHECK(worst < 1e-5);
    // One thread gives the same numbers (per-field sums added in field order).
    TraceOptions one = options;
    one.threads = 1;
    const SpotGradient g1 =
        mean_spot_gradient_adjoint<24>(make_trace_lens(lens), lens.specs, variables, one);
    for (std::size_t i = 0; i < variables.size(); ++i) CHECK(g1.gradient[i] == g.gradient[i]);
  }
}

TEST_CASE("spot adjoint: rays that fail contribute nothing (Jets agree)") {
  // A field so wide that some rays miss or reflect totally: failed rays leave the spot, and the
  // adjoint must leave them out exactly as the Jets do.
  Lens lens = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  lens.specs.half_field_deg = 42.0;
  TraceOptions options;
  options.rings = 12;
  options.fields = 7;
  const SpotResult<double> spots =
      evaluate_spots(prepare_system(make_trace_lens(lens), lens.specs, options));
  MESSAGE("failed rays at 42 deg: ", spots.total_failed);
  check_against_jets(lens, options);
}

namespace {

// The adjoint gradient of l_lens equals the Jet gradient within 1e-9 relative, and the terms agree.
void check_design(const LensParameterization& param, const std::vector<double>& x, GlassMode mode,
                  const TraceOptions& sampling, const DesignLossOptions& loss) {
  const DesignValueGradient adjoint = design_loss_gradient(param, x, mode, {}, sampling, loss);
  const DesignValueGradient jets = design_loss_gradient_jets(param, x, mode, {}, sampling, loss);
  CHECK(adjoint.finite == jets.finite);
  CHECK(adjoint.loss.total == doctest::Approx(jets.loss.total).epsilon(1e-12));
  CHECK(adjoint.loss.spot_mm == doctest::Approx(jets.loss.spot_mm).epsilon(1e-12));
  CHECK(adjoint.loss.ray_path_mm == doctest::Approx(jets.loss.ray_path_mm).epsilon(1e-12));
  CHECK(adjoint.loss.ray_angle == doctest::Approx(jets.loss.ray_angle).epsilon(1e-12));
  CHECK(adjoint.loss.failed_rays == jets.loss.failed_rays);
  const double worst = worst_relative(adjoint.gradient, jets.gradient);
  for (int i = 0; i < param.size(); ++i)
    INFO(param.variables()[i].name, ": adjoint ", adjoint.gradient[i], " jets ", jets.gradient[i]);
  INFO("path ", jets.loss.ray_path_mm, " angle ", jets.loss.ray_angle, "; worst ", worst);
  CHECK(worst < 1e-9);
}

}  // namespace

TEST_CASE("design adjoint: the gradient of l_lens equals the Jet gradient (active constraints)") {
  const GlassSpace glasses(*load_catalog("ohara"));
  for (const char* name : {"cooke-seed1", "tessar-seed2", "doublet-seed3"}) {
    const Lens lens =
        read_lens(test::source_dir() / "lenses" / "starts" / (std::string(name) + ".toml"));
    LensParameterization param(lens, glasses);
    const std::vector<double> x = param.from_lens(lens);
    TraceOptions sampling;
    sampling.rings = 6;
    sampling.fields = 3;
    DesignLossOptions loss;
    loss.min_image_clearance_mm = 14.0;  // the ray-path hinge active
    loss.max_ray_angle_deg = 20.0;       // the ray-angle hinge active
    loss.max_glass_mm = 2.0;
    for (GlassMode mode : {GlassMode::kQuantized, GlassMode::kContinuous})
      check_design(param, x, mode, sampling, loss);
    check_design(param, x, GlassMode::kQuantized, sampling, DesignLossOptions{});
    param.set_paraxial_image_solve(false);
    check_design(param, param.from_lens(lens), GlassMode::kQuantized, sampling, loss);
  }
}

TEST_CASE("design adjoint: rays that fail still pull through their records (Jets agree)") {
  // A wide field makes rays miss or reflect totally: their incidence records up to the failing
  // surface enter the angle penalty, with derivatives.
  Lens lens = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  lens.specs.half_field_deg = 42.0;
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  TraceOptions sampling;
  sampling.rings = 6;
  sampling.fields = 3;
  const DesignValueGradient jets = design_loss_gradient_jets(
      param, param.from_lens(lens), GlassMode::kQuantized, {}, sampling, DesignLossOptions{});
  MESSAGE("failed rays: ", jets.loss.failed_rays, " of ", jets.loss.rays);
  CHECK(jets.loss.failed_rays > 0);
  check_design(param, param.from_lens(lens), GlassMode::kQuantized, sampling, DesignLossOptions{});
}

TEST_CASE("design adjoint: the Adam comparison loop takes the same steps as with Jet gradients") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "starts" / "cooke-seed2.toml");
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x0 = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x0.data());
  OptimizeOptions options;
  options.sampling.rings = 4;
  options.sampling.fields = 3;
  const int steps = 12;
  const double lr = 5e-3;
  const AdamResult adam =
      adam_on_design_loss(param, x0, GlassMode::kFixed, glasses, options, lr, steps, 0.0);
  // The same Adam update on the Jet gradient (optimizer.cpp's loop before the adjoint).
  std::vector<double> x = x0, m(x.size(), 0.0), v(x.size(), 0.0);
  for (int step = 1; step <= steps; ++step) {
    const DesignValueGradient g = design_loss_gradient_jets(param, x, GlassMode::kFixed, glasses,
                                                            options.sampling, options.loss);
    for (std::size_t i = 0; i < x.size(); ++i) {
      m[i] = 0.9 * m[i] + 0.1 * g.gradient[i];
      v[i] = 0.999 * v[i] + 0.001 * g.gradient[i] * g.gradient[i];
      const double m_hat = m[i] / (1 - std::pow(0.9, step));
      const double v_hat = v[i] / (1 - std::pow(0.999, step));
      x[i] -= lr * m_hat / (std::sqrt(v_hat) + 1e-8);
    }
  }
  REQUIRE(adam.x.size() == x.size());
  for (std::size_t i = 0; i < x.size(); ++i) {
    INFO(param.variables()[i].name, ": adjoint ", adam.x[i], " jets ", x[i]);
    CHECK(std::abs(adam.x[i] - x[i]) <= 1e-9 * std::max(1.0, std::abs(x[i])));
  }
}

namespace {

// Every curved surface of `lens` an even asphere with a conic and a4..a16 terms that stay small
// at 40 % of the surface's radius (lensopt bench --aspherize's recipe), so that the adjoint
// meets the Newton intersection, rays that miss the profile and steep rims on every surface.
Lens aspherized(Lens lens) {
  for (Surface& s : lens.surfaces) {
    if (s.is_stop || s.curvature_per_mm == 0.0) continue;
    s.conic = -0.05;
    const double h = 0.4 / std::abs(s.curvature_per_mm);
    for (int j = 0; j < kAsphereOrders; ++j)
      s.asphere[j] = (j % 2 ? -1.0 : 1.0) * 1e-4 / std::pow(h, 2 * j + 4);
  }
  return lens;
}

Lens doublet_asphere() {
  return read_lens(test::source_dir() / "lenses" / "doublet-asphere.toml");
}

// The doublet's variables, each profile variable of its two aspheres, and the conic and a4 of
// its spherical second surface (seeded at 0: the surface becomes an asphere in the Jets).
std::vector<PrescriptionVariable> doublet_asphere_variables(const Lens& lens) {
  std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  variables.push_back({PrescriptionVariable::Kind::kConic, 1});
  variables.push_back({PrescriptionVariable::Kind::kAsphere, 1, 1});
  return variables;
}

}  // namespace

TEST_CASE("spot adjoint: aspheric and conic lenses equal the Jet gradient (k, a_2i included)") {
  const Lens asphere = doublet_asphere();
  TraceOptions options;
  options.rings = 10;
  options.fields = 5;
  // The adjoint runs (no Jet fallback) on conics and aspheres.
  CHECK(adjoint_supported(make_trace_lens(asphere)));
  for (bool aiming : {true, false}) {
    options.ray_aiming = aiming;
    // The lens's own variables (k and a_2i of both aspheres included) and the terms seeded at
    // 0 on the spherical surface 2, in the adjoint's second chunk of 16 (the Jets: one of 24).
    const std::vector<PrescriptionVariable> variables = doublet_asphere_variables(asphere);
    const TraceLens<double> trace_lens = make_trace_lens(asphere);
    const SpotGradient jets =
        mean_spot_gradient_auto(trace_lens, asphere.specs, variables, options);
    const SpotGradient adjoint =
        mean_spot_gradient_adjoint<16>(trace_lens, asphere.specs, variables, options);
    CHECK(adjoint.mean_rms_spot_mm == doctest::Approx(jets.mean_rms_spot_mm).epsilon(1e-12));
    const double worst = worst_relative(adjoint.gradient, jets.gradient);
    for (std::size_t i = 0; i < variables.size(); ++i)
      if (worst >= 1e-9)
        MESSAGE(variables[i].name(), ": adjoint ", adjoint.gradient[i], " jets ", jets.gradient[i]);
    INFO("aiming ", aiming, ": worst relative difference ", worst);
    CHECK(worst < 1e-9);
  }
  // A conic-only lens (k on both outer surfaces of the Cooke) and the aspherized Tessar, whose
  // rims make rays miss the profile (the adjoint must leave them out as the Jets do).
  Lens conic = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  conic.surfaces.front().conic = -0.6;
  conic.surfaces.back().conic = 1.5;
  check_against_jets(conic, options);
  const Lens tessar = aspherized(read_lens(test::source_dir() / "lenses" / "tessar.toml"));
  options.rings = 12;
  options.fields = 7;
  options.ray_aiming = true;
  const SpotResult<double> spots =
      evaluate_spots(prepare_system(make_trace_lens(tessar), tessar.specs, options));
  MESSAGE("aspherized Tessar: failed rays ", spots.total_failed);
  CHECK(spots.total_failed > 0);
  check_against_jets(tessar, options);
}

TEST_CASE("spot adjoint: aspheric doublet matches central finite differences") {
  const Lens lens = doublet_asphere();
  const std::vector<PrescriptionVariable> variables = doublet_asphere_variables(lens);
  TraceOptions options;
  options.rings = 8;
  options.fields = 4;
  const SpotGradient g =
      mean_spot_gradient_adjoint<24>(make_trace_lens(lens), lens.specs, variables, options);
  // Steps: as test_spot_adjoint's Cooke for the prescription; for k and a_2i one that moves the
  // sag at 5 mm (about the rays' largest height) by about 1e-6 mm (test_surface_profiles.cpp).
  std::vector<double> scale(variables.size(), 1.0), fd(variables.size());
  for (std::size_t i = 0; i < variables.size(); ++i) {
    const PrescriptionVariable& v = variables[i];
    if (v.kind == PrescriptionVariable::Kind::kCurvature) scale[i] = 0.05;
    if (v.kind == PrescriptionVariable::Kind::kVd) scale[i] = 40.0;
    if (v.kind == PrescriptionVariable::Kind::kConic) scale[i] = 50.0;
    if (v.kind == PrescriptionVariable::Kind::kAsphere)
      scale[i] = 5e-2 / std::pow(5.0, 2 * v.term + 2);
  }
  for (std::size_t i = 0; i < variables.size(); ++i) {
    const double x0 = variable_value(lens, variables[i]);
    auto central = [&](double h) {
      Lens plus = lens, minus = lens;
      set_variable_value(plus, variables[i], x0 + h);
      set_variable_value(minus, variables[i], x0 - h);
      return (mean_spot(plus, options) - mean_spot(minus, options)) / (2 * h);
    };
    const double h = 2e-5 * scale[i];
    fd[i] = (4 * central(h / 2) - central(h)) / 3;
  }
  // Each entry relative to its own size, or to 1e-4 of the largest scaled entry.
  double largest_scaled = 0;
  for (std::size_t i = 0; i < variables.size(); ++i)
    largest_scaled = std::max(largest_scaled, std::abs(fd[i]) * scale[i]);
  for (std::size_t i = 0; i < variables.size(); ++i) {
    const double denominator = std::max(std::abs(fd[i]), 1e-4 * largest_scaled / scale[i]);
    INFO(variables[i].name(), ": adjoint ", g.gradient[i], " fd ", fd[i]);
    CHECK(std::abs(g.gradient[i] - fd[i]) / denominator < 1e-5);
  }
}

TEST_CASE("spot gradients: k and a4 of a spherical surface seeded in a later chunk") {
  // The Doublet's 13 variables and the conic and a4 of its spherical surface 2, in chunks of 8:
  // both in the second chunk, or k2 in the first and a4_2 in the second. Every chunk traces
  // surface 2 as an asphere (with_profile_variables); before, the adjoint traced it as the first
  // chunk's sphere and lost the direct derivatives of k2 and a4_2 (about 4 % of d/dk2 left).
  const Lens lens = read_lens(test::source_dir() / "lenses/doublet.toml");
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  REQUIRE(!trace_lens.has_profiles());
  TraceOptions options;
  options.rings = 6;
  options.fields = 4;
  const PrescriptionVariable k2{PrescriptionVariable::Kind::kConic, 1};
  const PrescriptionVariable a4_2{PrescriptionVariable::Kind::kAsphere, 1, 1};
  // Central differences (Richardson) of the spherical lens in k2 and a4_2: 1e-6 mm of sag at 5 mm.
  const double fd_k = [&] {
    auto central = [&](const PrescriptionVariable& v, double h) {
      Lens plus = lens, minus = lens;
      set_variable_value(plus, v, h);
      set_variable_value(minus, v, -h);
      return (mean_spot(plus, options) - mean_spot(minus, options)) / (2 * h);
    };
    return (4 * central(k2, 5e-4) - central(k2, 1e-3)) / 3;
  }();
  const double fd_a = [&] {
    auto central = [&](double h) {
      Lens plus = lens, minus = lens;
      set_variable_value(plus, a4_2, h);
      set_variable_value(minus, a4_2, -h);
      return (mean_spot(plus, options) - mean_spot(minus, options)) / (2 * h);
    };
    const double h = 1e-6 / std::pow(5.0, 4);
    return (4 * central(h / 2) - central(h)) / 3;
  }();
  REQUIRE(std::abs(fd_k) > 0.0);
  REQUIRE(std::abs(fd_a) > 0.0);
  for (bool aiming : {true, false}) {
    options.ray_aiming = aiming;
    for (int layout = 0; layout < 2; ++layout) {
      std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
      REQUIRE(variables.size() == 13);
      if (layout == 0) {
        variables.push_back(k2);  // 13, 14: the second chunk
      } else {
        variables.insert(variables.begin() + 2, k2);  // the first chunk
      }
      variables.push_back(a4_2);
      const std::size_t ik = layout == 0 ? 13 : 2, ia = 14;
      const SpotGradient jets = mean_spot_gradient<8>(trace_lens, lens.specs, variables, options);
      const SpotGradient adjoint =
          mean_spot_gradient_adjoint<8>(trace_lens, lens.specs, variables, options);
      const SpotGradient one_chunk =
          mean_spot_gradient<16>(trace_lens, lens.specs, variables, options);
      INFO("aiming ", aiming, ", layout ", layout, ": d/dk2 jets ", jets.gradient[ik], " adjoint ",
           adjoint.gradient[ik], " fd ", fd_k, "; d/da4_2 jets ", jets.gradient[ia], " adjoint ",
           adjoint.gradient[ia], " fd ", fd_a);
      if (aiming) {
        CHECK(std::abs(jets.gradient[ik] - fd_k) < 1e-6 * std::abs(fd_k));
        CHECK(std::abs(jets.gradient[ia] - fd_a) < 1e-6 * std::abs(fd_a));
        CHECK(std::abs(adjoint.gradient[ik] - fd_k) < 1e-6 * std::abs(fd_k));
        CHECK(std::abs(adjoint.gradient[ia] - fd_a) < 1e-6 * std::abs(fd_a));
      }
      CHECK(worst_relative(adjoint.gradient, jets.gradient) < 1e-9);
      CHECK(worst_relative(one_chunk.gradient, jets.gradient) < 1e-9);
      CHECK(adjoint.mean_rms_spot_mm == doctest::Approx(jets.mean_rms_spot_mm).epsilon(1e-12));
    }
  }
}

TEST_CASE("design loss: the profile slope bound, adjoint and Jets against central differences") {
  // l_lens carries the profile bounds (lambda_PB l_PB, optimize/profile_bounds.h) for Adam as the
  // LM carries them as residuals. A 12 deg slope bound that the aspheric doublet's surfaces cross;
  // continuous glasses (the quantized map's glass derivative is a straight-through one, not the
  // finite difference of its steps).
  const GlassSpace glasses(*load_catalog("ohara"));
  const Lens lens = doublet_asphere();
  const LensParameterization param(lens, glasses, {"k1", "a4_1", "a6_1", "k2", "a4_2", "a4_5"});
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions sampling;
  sampling.rings = 4;
  sampling.fields = 3;
  DesignLossOptions with, without;
  with.max_surface_slope_deg = without.max_surface_slope_deg = 12.0;
  with.weight_profile = 100.0;
  without.weight_profile = 0.0;
  const DesignValueGradient a =
      design_loss_gradient(param, x, GlassMode::kContinuous, {}, sampling, with);
  const DesignValueGradient b =
      design_loss_gradient(param, x, GlassMode::kContinuous, {}, sampling, without);
  const DesignValueGradient jets =
      design_loss_gradient_jets(param, x, GlassMode::kContinuous, {}, sampling, with);
  Specs specs = lens.specs;
  auto l_pb = [&](const std::vector<double>& at) {
    return profile_bound_loss(param.to_trace_lens(at.data(), GlassMode::kContinuous, {}), specs,
                              12.0);
  };
  REQUIRE(a.loss.profile > 0.0);
  CHECK(a.loss.profile == doctest::Approx(l_pb(x)).epsilon(1e-14));
  CHECK(jets.loss.profile == doctest::Approx(a.loss.profile).epsilon(1e-14));
  CHECK(a.loss.total == doctest::Approx(b.loss.total + 100.0 * a.loss.profile).epsilon(1e-14));
  CHECK(worst_relative(a.gradient, jets.gradient) < 1e-9);
  // The profile term's gradient (adjoint with minus without) against central differences of l_PB.
  int active = 0;
  for (int i = 0; i < param.size(); ++i) {
    auto central = [&](double h) {
      std::vector<double> plus = x, minus = x;
      plus[i] += h;
      minus[i] -= h;
      return (l_pb(plus) - l_pb(minus)) / (2 * h);
    };
    const double fd = (4 * central(5e-7) - central(1e-6)) / 3;
    const double g = (a.gradient[i] - b.gradient[i]) / 100.0;
    active += std::abs(fd) > 1e-6;
    INFO("variable ", i, ": adjoint ", g, " fd ", fd);
    CHECK(std::abs(g - fd) <= 1e-6 * std::max(std::abs(fd), 1e-3));
  }
  CHECK(active >= 4);
}

TEST_CASE("design adjoint: aspheric lenses, with profile variables (Jets agree)") {
  const GlassSpace glasses(*load_catalog("ohara"));
  TraceOptions sampling;
  sampling.rings = 6;
  sampling.fields = 3;
  DesignLossOptions loss;
  loss.min_image_clearance_mm = 14.0;  // the ray-path hinge active
  loss.max_ray_angle_deg = 20.0;       // the ray-angle hinge active
  const Lens lens = doublet_asphere();
  const LensParameterization param(lens, glasses,
                                   {"k1", "a4_1", "a6_1", "a8_1", "k2", "a4_2", "k5", "a4_5"});
  for (GlassMode mode : {GlassMode::kQuantized, GlassMode::kContinuous})
    check_design(param, param.from_lens(lens), mode, sampling, loss);
  check_design(param, param.from_lens(lens), GlassMode::kQuantized, sampling, DesignLossOptions{});
  // The aspherized Tessar at a wide field: rays that miss a profile or reflect totally pull
  // through their records up to the failing surface.
  Lens tessar = aspherized(read_lens(test::source_dir() / "lenses" / "tessar.toml"));
  tessar.specs.half_field_deg = 35.0;
  const LensParameterization tessar_param(tessar, glasses, {"k1", "a4_1", "a6_3", "k8"});
  const DesignValueGradient jets =
      design_loss_gradient_jets(tessar_param, tessar_param.from_lens(tessar), GlassMode::kQuantized,
                                {}, sampling, DesignLossOptions{});
  MESSAGE("aspherized Tessar at 35 deg: failed rays ", jets.loss.failed_rays, " of ",
          jets.loss.rays);
  CHECK(jets.loss.failed_rays > 0);
  check_design(tessar_param, tessar_param.from_lens(tessar), GlassMode::kQuantized, sampling,
               DesignLossOptions{});
}

namespace {

// The Cooke triplet of lenses/zmx (its own wavelengths F, d, C and fields 0, 14, 20 deg) with
// unequal wavelength and field weights.
Lens weighted_cooke() {
  Lens lens = read_zmx(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx").lens;
  lens.specs.wavelength_weights = {1.0, 3.0, 0.5};
  REQUIRE(lens.specs.fields.size() == 3);
  lens.specs.fields[0].weight = 0.5;
  lens.specs.fields[1].weight = 2.0;
  lens.specs.fields[2].weight = 1.0;
  return lens;
}

// The weighted mean RMS spot by hand, from the raw weights (no normalization) in two passes:
//   ybar_h = sum omega_w y / sum omega_w,  S_h^2 = sum omega_w ((y - ybar_h)^2 + x^2) / sum
//   omega_w, mean = sum_h phi_h S_h / sum_h phi_h.
double hand_weighted_spot(const Lens& lens, const TraceOptions& options) {
  const TraceSystem<double> sys = prepare_system(make_trace_lens(lens), lens.specs, options);
  const std::vector<double>& omega = lens.specs.wavelength_weights;
  double mean = 0.0, phi_sum = 0.0;
  RayBundle<double> rays;
  for (std::size_t h = 0; h < sys.fields_deg.size(); ++h) {
    std::vector<double> xs, ys, ws;
    for (int w = 0; w < sys.wavelength_count; ++w) {
      start_rays(sys, static_cast<int>(h), w, rays);
      trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                   static_cast<RayRecord<double>*>(nullptr));
      for (std::size_t i = 0; i < rays.size(); ++i)
        if (rays.status[i] == kRayOk) {
          xs.push_back(rays.x[i]);
          ys.push_back(rays.y[i]);
          ws.push_back(omega.empty() ? 1.0 : omega[w]);
        }
    }
    double sw = 0.0, swy = 0.0;
    for (std::size_t i = 0; i < ys.size(); ++i) {
      sw += ws[i];
      swy += ws[i] * ys[i];
    }
    const double ybar = swy / sw;
    double s2 = 0.0;
    for (std::size_t i = 0; i < ys.size(); ++i)
      s2 += ws[i] * ((ys[i] - ybar) * (ys[i] - ybar) + xs[i] * xs[i]);
    const double phi = sys.field_weights[h];
    mean += phi * std::sqrt(s2 / sw);
    phi_sum += phi;
  }
  return mean / phi_sum;
}

}  // namespace

TEST_CASE("spot weights: the mean spot is the weighted mean over fields and wavelengths") {
  const Lens lens = weighted_cooke();
  TraceOptions options;
  options.rings = 12;
  const double weighted = mean_spot(lens, options);
  const double hand = hand_weighted_spot(lens, options);
  CHECK(weighted == doctest::Approx(hand).epsilon(1e-12));
  // The weights matter here.
  Lens equal = lens;
  equal.specs.wavelength_weights.clear();
  for (FieldPoint& f : equal.specs.fields) f.weight = 1.0;
  const double unweighted = mean_spot(equal, options);
  MESSAGE("Cooke 50: weighted mean spot ", weighted * 1000, " um, unweighted ", unweighted * 1000,
          " um");
  CHECK(std::abs(weighted - unweighted) > 1e-3 * unweighted);
  // Weights are relative: all scaled by 7 give the same mean.
  Lens scaled_weights = lens;
  for (double& w : scaled_weights.specs.wavelength_weights) w *= 7.0;
  for (FieldPoint& f : scaled_weights.specs.fields) f.weight *= 7.0;
  CHECK(mean_spot(scaled_weights, options) == doctest::Approx(weighted).epsilon(1e-14));
  // Equal weights written out give the unweighted spot bit for bit (every field too).
  Lens written = equal;
  written.specs.wavelength_weights = {2.0, 2.0, 2.0};
  for (FieldPoint& f : written.specs.fields) f.weight = 3.0;
  const SpotResult<double> a =
      evaluate_spots(prepare_system(make_trace_lens(equal), equal.specs, options));
  const SpotResult<double> b =
      evaluate_spots(prepare_system(make_trace_lens(written), written.specs, options));
  CHECK(a.mean_rms_spot_mm == b.mean_rms_spot_mm);
  for (std::size_t h = 0; h < a.rms_spot_mm.size(); ++h) {
    CHECK(a.rms_spot_mm[h] == b.rms_spot_mm[h]);
    CHECK(a.centroid_y_mm[h] == b.centroid_y_mm[h]);
  }
  // A field of weight 0 leaves the mean: the mean of the other two.
  Lens dropped = lens;
  dropped.specs.fields[1].weight = 0.0;
  CHECK(mean_spot(dropped, options) ==
        doctest::Approx(hand_weighted_spot(dropped, options)).epsilon(1e-12));
}

TEST_CASE("spot weights: adjoint, Jets and central differences agree with unequal weights") {
  const Lens lens = weighted_cooke();
  TraceOptions options;
  options.rings = 10;
  for (bool aiming : {true, false}) {
    options.ray_aiming = aiming;
    check_against_jets(lens, options);
  }
  // Unequal wavelength weights with equal field weights.
  Lens wavelengths_only = lens;
  for (FieldPoint& f : wavelengths_only.specs.fields) f.weight = 1.0;
  check_against_jets(wavelengths_only, options);
  // With vignetting factors as well (the adjoint's pupil start terms carry them).
  Lens vignetted = lens;
  vignetted.specs.fields[1].vignetting = {0.0, 0.04, 0.05, 0.1, 0.0};
  vignetted.specs.fields[2].vignetting = {0.0, 0.06, 0.02, 0.25, 0.0};
  options.ray_aiming = true;
  check_against_jets(vignetted, options);
  // Central differences (Richardson-extrapolated, as above) for every curvature and thickness
  // (not the zero spaces; the lens's catalog glasses tie nd and vd to the catalog, so those are
  // left to the Jets).
  options.rings = 8;
  std::vector<PrescriptionVariable> variables;
  for (const PrescriptionVariable& v : all_prescription_variables(vignetted))
    if (v.kind == PrescriptionVariable::Kind::kCurvature ||
        (v.kind == PrescriptionVariable::Kind::kThickness && variable_value(vignetted, v) > 0.1))
      variables.push_back(v);
  REQUIRE(!variables.empty());
  const SpotGradient g = mean_spot_gradient_adjoint<24>(make_trace_lens(vignetted), vignetted.specs,
                                                        variables, options);
  const std::vector<double> fd =
      test::mean_spot_central_differences(vignetted, variables, options, 0.05);
  const double worst = worst_relative(g.gradient, fd);
  INFO("worst relative error against finite differences ", worst);
  CHECK(worst < 1e-5);
}

TEST_CASE("spot weights: the design loss weighs wavelengths as the analysis (adjoint = Jets)") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "starts" / "cooke-seed1.toml");
  const std::size_t count = lens.specs.wavelengths_nm.size();
  lens.specs.wavelength_weights.clear();
  for (std::size_t i = 0; i < count; ++i) lens.specs.wavelength_weights.push_back(1.0 + i % 4);
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions sampling;
  sampling.rings = 6;
  sampling.fields = 3;
  check_design(param, x, GlassMode::kQuantized, sampling, DesignLossOptions{});
  // l_S is the analysis's weighted mean spot of the same system (3 fields 0..hfov, no scaling).
  DesignLoss<double> loss;
  evaluate_design<double>(param, x.data(), GlassMode::kQuantized, {}, sampling, DesignLossOptions{},
                          nullptr, nullptr, &loss);
  TraceOptions topt = sampling;
  topt.scale_to_spec = false;
  Specs specs = lens.specs;
  specs.mode = SpecMode::kPaper;
  const double analysis =
      evaluate_spots(
          prepare_system(param.to_trace_lens(x.data(), GlassMode::kQuantized, {}), specs, topt))
          .mean_rms_spot_mm;
  CHECK(loss.spot_mm == doctest::Approx(analysis).epsilon(1e-9));
  // And differs from the unweighted loss.
  Lens plain = lens;
  plain.specs.wavelength_weights.clear();
  const LensParameterization plain_param(plain, GlassSpace(*load_catalog("ohara")));
  DesignLoss<double> plain_loss;
  evaluate_design<double>(plain_param, x.data(), GlassMode::kQuantized, {}, sampling,
                          DesignLossOptions{}, nullptr, nullptr, &plain_loss);
  CHECK(std::abs(plain_loss.spot_mm - loss.spot_mm) > 1e-4 * loss.spot_mm);
}

}  // namespace test_spot_adjoint
