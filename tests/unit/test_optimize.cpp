// The optimizer's pieces: the lens <-> variables mapping, quantized glass variables with the
// straight-through gradient, the design loss's least-squares form against the paper's loss and
// against finite differences, and a short optimization that must not worsen the start.
#include <ceres/dynamic_autodiff_cost_function.h>
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <cmath>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/free_jacobian.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/paraxial/paraxial.h"
#include "test_support.h"

// <ceres/dynamic_autodiff_cost_function.h> brings glog's CHECK macros. Where doctest came first
// (the precompiled header), glog's replaced doctest's: a failed CHECK aborted the binary instead of
// being reported, and a passed one was not counted. doctest's, here and for the files after this
// one in its unity batch (CMakeLists.txt), as test_torch.h does for libtorch's.
#undef CHECK
#undef CHECK_EQ
#undef CHECK_NE
#undef CHECK_GT
#undef CHECK_LT
#undef CHECK_GE
#undef CHECK_LE
#define CHECK(...) DOCTEST_CHECK(__VA_ARGS__)
#define CHECK_EQ(...) DOCTEST_CHECK_EQ(__VA_ARGS__)
#define CHECK_NE(...) DOCTEST_CHECK_NE(__VA_ARGS__)
#define CHECK_GT(...) DOCTEST_CHECK_GT(__VA_ARGS__)
#define CHECK_LT(...) DOCTEST_CHECK_LT(__VA_ARGS__)
#define CHECK_GE(...) DOCTEST_CHECK_GE(__VA_ARGS__)
#define CHECK_LE(...) DOCTEST_CHECK_LE(__VA_ARGS__)

namespace test_optimize {

using namespace lensopt;

namespace {

Lens baseline(const char* name) {
  return read_lens(test::source_dir() / "lenses" / (std::string(name) + ".toml"));
}

LensParameterization parameterization(const Lens& lens) {
  return LensParameterization(lens, GlassSpace(*load_catalog("ohara")));
}

TraceOptions small_sampling() {
  TraceOptions t;
  t.rings = 6;
  t.fields = 5;
  return t;
}

}  // namespace

TEST_CASE("optimize: whitening makes the catalog's (nd, vd) zero-mean with unit covariance") {
  const GlassSpace space(*load_catalog("ohara"));
  REQUIRE(space.size() == 65);
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (int i = 0; i < space.size(); ++i) mean += space.glass_point(i);
  mean /= space.size();
  for (int i = 0; i < space.size(); ++i) {
    const Eigen::Vector2d d = space.glass_point(i) - mean;
    cov += d * d.transpose();
  }
  cov /= space.size();
  CHECK(mean.norm() < 1e-12);
  CHECK((cov - Eigen::Matrix2d::Identity()).norm() < 1e-12);
  // Unwhitening inverts whitening.
  double nd = 0, vd = 0;
  const Eigen::Vector2d g = space.whiten(1.7, 45.0);
  space.unwhiten(g[0], g[1], nd, vd);
  CHECK(nd == doctest::Approx(1.7).epsilon(1e-14));
  CHECK(vd == doctest::Approx(45.0).epsilon(1e-14));
}

TEST_CASE("optimize: lens -> variables -> lens reproduces the baselines") {
  for (const char* name : {"doublet", "cooke", "tessar"}) {
    const Lens lens = baseline(name);
    const LensParameterization param = parameterization(lens);
    const std::vector<double> x = param.from_lens(lens);
    const Lens back = param.to_lens(x.data(), GlassMode::kQuantized);
    // The forward map solves the last curvature for f exactly; the baselines are at f to ~1e-4.
    TraceOptions scale_only;
    scale_only.rings = 1;
    scale_only.fields = 1;
    scale_only.ray_aiming = false;
    const double scale = prepare_system(make_trace_lens(lens), lens.specs, scale_only).scale;
    const Lens expected = scaled(lens, scale);
    for (std::size_t k = 0; k + 1 < lens.surfaces.size(); ++k) {
      INFO(name, " surface ", k + 1);
      CHECK(back.surfaces[k].curvature_per_mm ==
            doctest::Approx(expected.surfaces[k].curvature_per_mm).epsilon(1e-12));
      CHECK(back.surfaces[k].thickness_mm ==
            doctest::Approx(expected.surfaces[k].thickness_mm).epsilon(1e-12));
      CHECK(back.surfaces[k].material.label() == lens.surfaces[k].material.label());
    }
    CHECK(back.surfaces.back().curvature_per_mm ==
          doctest::Approx(expected.surfaces.back().curvature_per_mm).epsilon(1e-3));
    CHECK(back.surfaces.back().thickness_mm ==
          doctest::Approx(expected.surfaces.back().thickness_mm).epsilon(1e-3));
    // And its focal length is the spec's exactly.
    const ParaxialData<double> p = paraxial_data(make_trace_lens(back), kWavelengthD_nm);
    CHECK(p.efl_mm == doctest::Approx(lens.specs.focal_length_mm()).epsilon(1e-13));
  }
}

TEST_CASE("optimize: quantized glass variables use the catalog glass, gradient straight through") {
  const Lens lens = baseline("cooke");
  const LensParameterization param = parameterization(lens);
  std::vector<double> x = param.from_lens(lens);
  int g = -1;
  for (int i = 0; i < param.size(); ++i)
    if (param.variables()[i].kind == LensVariable::Kind::kGlass0) {
      g = i;
      break;
    }
  REQUIRE(g >= 0);
  // Move the glass variable a little: the quantized forward pass keeps the catalog glass.
  x[g] += 0.05;
  using J = ceres::Jet<double, 1>;
  std::vector<J> xj(x.begin(), x.end());
  xj[g] = J(x[g], 0);
  const TraceLens<J> quantized = param.to_trace_lens(xj.data(), GlassMode::kQuantized);
  const int surface = param.variables()[g].surface;
  const std::vector<int> nearest = param.nearest_glasses(x.data());
  CHECK(quantized.nd[surface].a ==
        doctest::Approx(param.glass_space().nd(nearest[0])).epsilon(1e-14));
  // Straight-through: the derivative is that of the continuous map.
  const TraceLens<J> continuous = param.to_trace_lens(xj.data(), GlassMode::kContinuous);
  CHECK(quantized.nd[surface].v[0] == doctest::Approx(continuous.nd[surface].v[0]).epsilon(1e-14));
  CHECK(std::abs(quantized.nd[surface].v[0]) > 0.0);
  // Glass-variable loss: the squared whitened distance to the nearest catalog glass.
  const Eigen::Vector2d p = param.glass_space().glass_point(nearest[0]);
  const double expected = std::pow(x[g] - p[0], 2) + std::pow(x[g + 1] - p[1], 2);
  std::vector<int> glass_pairs;
  double loss = 0;
  for (int i = 0; i < param.size(); ++i) {
    if (param.variables()[i].kind != LensVariable::Kind::kGlass0) continue;
    const Eigen::Vector2d q = param.glass_space().glass_point(
        param.glass_space().nearest(Eigen::Vector2d(x[i], x[i + 1])));
    loss += std::pow(x[i] - q[0], 2) + std::pow(x[i + 1] - q[1], 2);
  }
  CHECK(param.glass_variable_loss(x.data()) == doctest::Approx(loss).epsilon(1e-14));
  CHECK(loss >= expected);
}

TEST_CASE("optimize: the reweighted least squares equals the paper's spot loss and its gradient") {
  const Lens lens = baseline("tessar");
  const LensParameterization param = parameterization(lens);
  const std::vector<double> x = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  const TraceOptions sampling = small_sampling();
  DesignLossOptions options;
  options.weight_ray_path = 0;  // spot terms only
  options.weight_ray_angle = 0;
  options.weight_glass = 0;
  DesignLoss<double> loss;
  evaluate_design<double>(param, x.data(), GlassMode::kFixed, glasses, sampling, options, nullptr,
                          nullptr, &loss);
  const int fields = static_cast<int>(loss.field_rms_mm.size());
  std::vector<double> weights(fields);
  for (int h = 0; h < fields; ++h) weights[h] = 1.0 / (fields * loss.field_rms_mm[h]);
  const int rays = static_cast<int>(paper_pupil_samples(sampling.rings).size());
  const int count =
      design_residual_count(fields, constraint_field_count(fields, kConstraintFields),
                            static_cast<int>(lens.specs.wavelengths_nm.size()), rays,
                            static_cast<int>(lens.surfaces.size()), lens.element_count());
  // Value: sum r^2 = l_S at the reweighting point.
  std::vector<double> r(count);
  evaluate_design<double>(param, x.data(), GlassMode::kFixed, glasses, sampling, options, &weights,
                          r.data(), nullptr);
  double sum = 0;
  for (double v : r) sum += v * v;
  CHECK(sum == doctest::Approx(loss.spot_mm).epsilon(1e-12));
  // Gradient: d(sum r^2)/dx = 2 d(l_S)/dx there (Jets on both sides).
  using J = ceres::Jet<double, 24>;
  REQUIRE(param.size() <= 24);
  std::vector<J> xj(param.size());
  for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
  std::vector<J> rj(count);
  DesignLoss<J> lj;
  evaluate_design<J>(param, xj.data(), GlassMode::kFixed, glasses, sampling, options, &weights,
                     rj.data(), &lj);
  J sum_j = J(0.0);
  for (const J& v : rj) sum_j += v * v;
  for (int i = 0; i < param.size(); ++i) {
    if (param.variables()[i].group == "glasses") continue;
    INFO("variable ", param.variables()[i].name);
    CHECK(sum_j.v[i] == doctest::Approx(2 * lj.spot_mm.v[i]).epsilon(1e-9));
  }
}

TEST_CASE("optimize: design-loss Jacobian matches finite differences") {
  const Lens lens = baseline("cooke");
  const LensParameterization param = parameterization(lens);
  std::vector<double> x = param.from_lens(lens);
  // The paper's loss is piecewise linear in the ray path: the Cooke's second element is exactly
  // 1.0000001 mm thick and its third exactly 3.0 mm, on the 1 and 3 mm bounds, kinks no finite
  // difference can straddle. Move them off the kinks; the air-gap and angle penalties stay
  // active (the Cooke violates those bounds).
  for (int i = 0; i < param.size(); ++i) {
    if (param.variables()[i].name == "s3") x[i] += 0.003;
    if (param.variables()[i].name == "s6") x[i] -= 0.003;
  }
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  const TraceOptions sampling = small_sampling();
  const DesignLossOptions options;
  auto total = [&](const std::vector<double>& xs) {
    DesignLoss<double> l;
    evaluate_design<double>(param, xs.data(), GlassMode::kContinuous, glasses, sampling, options,
                            nullptr, nullptr, &l);
    return l.total;
  };
  using J = ceres::Jet<double, 24>;
  std::vector<J> xj(param.size());
  for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
  DesignLoss<J> lj;
  evaluate_design<J>(param, xj.data(), GlassMode::kContinuous, glasses, sampling, options, nullptr,
                     nullptr, &lj);
  CHECK(lj.total.a == doctest::Approx(total(x)).epsilon(1e-13));
  DesignLoss<double> at_x;
  evaluate_design<double>(param, x.data(), GlassMode::kContinuous, glasses, sampling, options,
                          nullptr, nullptr, &at_x);
  CHECK(at_x.ray_path_mm > 0.0);  // the penalties are really exercised
  CHECK(at_x.ray_angle > 0.0);
  for (int i = 0; i < param.size(); ++i) {
    const double h = 1e-6;
    std::vector<double> plus = x, minus = x;
    plus[i] += h;
    minus[i] -= h;
    const double fd = (total(plus) - total(minus)) / (2 * h);
    INFO("variable ", param.variables()[i].name, " jet ", lj.total.v[i], " fd ", fd);
    CHECK(std::abs(lj.total.v[i] - fd) <= 1e-5 * std::max(std::abs(fd), 1e-3));
  }
}

TEST_CASE(
    "optimize: a short run from the Doublet never worsens its spot and keeps catalog glasses") {
  const Lens lens = baseline("doublet");
  OptimizeOptions options;
  options.sampling = small_sampling();
  options.glass_search = GlassSearch::kNone;
  options.max_iterations = 8;
  options.max_rounds = 1;
  options.verbose = false;
  const OptimizeResult result = optimize_lens(lens, options);
  MESSAGE("doublet: ", result.start_spot_um, " -> ", result.final_spot_um, " um in ",
          result.loss_evaluations, " evaluations");
  CHECK(result.final_spot_um <= result.start_spot_um);
  for (const Surface& s : result.lens.surfaces) {
    if (s.material.is_air()) continue;
    CHECK(s.material.kind == Material::Kind::kCatalog);
    CHECK(load_catalog("ohara")->find(s.material.glass_name) != nullptr);
  }
  CHECK(result.final_constraints.all_pass());
  CHECK(std::isfinite(result.final_spot_um));
}

TEST_CASE("optimize: bad options are rejected with the option named") {
  OptimizeOptions options;
  options.loss.max_ray_angle_deg = 95;
  CHECK_THROWS_WITH_AS(options.validate(), doctest::Contains("max_ray_angle_deg"), Error);
  options = OptimizeOptions{};
  options.loss.min_glass_mm = 4;
  CHECK_THROWS_WITH_AS(options.validate(), doctest::Contains("min_glass_mm"), Error);
  const Lens lens = baseline("tessar");
  const LensParameterization param = parameterization(lens);
  CHECK_THROWS_WITH_AS(param.select({"c99"}), doctest::Contains("unknown variable 'c99'"), Error);
  CHECK(param.select({"curvatures"}).size() == 6);
}

TEST_CASE(
    "optimize: with the paper's penalties the least squares equals lambda l_RP + lambda l_RA") {
  const Lens lens = baseline("cooke");  // violates its ray-path and ray-angle bounds
  const LensParameterization param = parameterization(lens);
  const std::vector<double> x = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  const TraceOptions sampling = small_sampling();
  DesignLossOptions options;
  options.paper_penalties = true;
  options.weight_spot = 0;
  options.weight_glass = 0;
  DesignLoss<double> loss;
  evaluate_design<double>(param, x.data(), GlassMode::kFixed, glasses, sampling, options, nullptr,
                          nullptr, &loss);
  REQUIRE(loss.ray_path_mm > 0.0);
  REQUIRE(loss.ray_angle > 0.0);
  const int fields = static_cast<int>(loss.field_rms_mm.size());
  const int count =
      design_residual_count(fields, constraint_field_count(fields, kConstraintFields),
                            static_cast<int>(lens.specs.wavelengths_nm.size()),
                            static_cast<int>(paper_pupil_samples(sampling.rings).size()),
                            static_cast<int>(lens.surfaces.size()), lens.element_count());
  std::vector<double> r(count);
  evaluate_design<double>(param, x.data(), GlassMode::kFixed, glasses, sampling, options, nullptr,
                          r.data(), nullptr);
  double sum = 0;
  for (double v : r) sum += v * v;
  const double paper =
      options.weight_ray_path * loss.ray_path_mm + options.weight_ray_angle * loss.ray_angle;
  MESSAGE("cooke: sum of squares ", sum, ", 100 l_RP + 100 l_RA ", paper);
  // Equal but for the hinge's rounding within 1e-4 of each bound (at most 5e-5 per active ray).
  CHECK(sum == doctest::Approx(paper).epsilon(0.02));
  CHECK(sum <= paper);
}

namespace {

// The design residuals of x (fixed glasses) as a Ceres functor, as the optimizer builds them.
struct DesignResiduals {
  const LensParameterization* param;
  std::vector<int> glasses;
  TraceOptions sampling;
  DesignLossOptions options;
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    return evaluate_design<T>(*param, parameters[0], GlassMode::kFixed, glasses, sampling, options,
                              nullptr, residuals, nullptr);
  }
};

// A small nonlinear functor of 7 variables with 5 residuals.
struct Toy {
  template <typename T>
  bool operator()(T const* const* p, T* r) const {
    using std::sin;
    using std::sqrt;
    const T* x = p[0];
    r[0] = x[0] * x[1] + sin(x[2]);
    r[1] = sqrt(K<T>(1.0) + x[3] * x[3]) - x[4] / (K<T>(2.0) + x[5] * x[5]);
    r[2] = x[6] * x[6] * x[0] - x[2];
    r[3] = x[1] * x[3] * x[5];
    r[4] = x[4] + x[6] - K<T>(3.0) * x[0];
    return true;
  }
};

// Jacobian (row-major) and residuals of a cost function at x.
void evaluate_cost(const ceres::CostFunction& cost, const std::vector<double>& x,
                   std::vector<double>& r, std::vector<double>& jacobian) {
  r.assign(cost.num_residuals(), 0.0);
  jacobian.assign(static_cast<std::size_t>(cost.num_residuals()) * x.size(), -1.0);
  const double* p = x.data();
  double* j = jacobian.data();
  REQUIRE(cost.Evaluate(&p, r.data(), &j));
}

}  // namespace

TEST_CASE("optimize: the free-variable Jacobian equals dynamic autodiff's columns bit for bit") {
  // The glasses held, as in the optimizer's default phases: FreeJacobianCost seeds Jets only on
  // the free variables; its residuals and free columns must equal those of Ceres' dynamic autodiff
  // cost function (one Jet direction per variable) exactly, and its frozen columns be zero.
  const Lens lens = baseline("cooke");
  const LensParameterization param = parameterization(lens);
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions sampling;
  sampling.rings = 2;
  sampling.fields = 3;
  const int n = param.size();
  const int rays = static_cast<int>(paper_pupil_samples(sampling.rings).size());
  const int count =
      design_residual_count(3, constraint_field_count(3, kConstraintFields),
                            static_cast<int>(lens.specs.wavelengths_nm.size()), rays,
                            static_cast<int>(lens.surfaces.size()), lens.element_count());
  std::vector<int> frozen;
  for (int i = 0; i < n; ++i)
    if (param.variables()[i].group == "glasses") frozen.push_back(i);
  REQUIRE(!frozen.empty());
  REQUIRE(static_cast<int>(frozen.size()) < n);
  auto functor = [&] {
    return new DesignResiduals{&param, param.nearest_glasses(x.data()), sampling, {}};
  };
  std::unique_ptr<ceres::CostFunction> reference;
  {
    auto* cost = new ceres::DynamicAutoDiffCostFunction<DesignResiduals, 24>(functor());
    cost->AddParameterBlock(n);
    cost->SetNumResiduals(count);
    reference.reset(cost);
  }
  std::unique_ptr<ceres::CostFunction> free(make_free_jacobian_cost(functor(), n, count, frozen));
  std::vector<double> r_ref, j_ref, r_free, j_free;
  evaluate_cost(*reference, x, r_ref, j_ref);
  evaluate_cost(*free, x, r_free, j_free);
  int nonzero = 0;
  for (int row = 0; row < count; ++row) {
    REQUIRE(r_free[row] == r_ref[row]);
    for (int i = 0; i < n; ++i) {
      const double a = j_free[static_cast<std::size_t>(row) * n + i];
      const double b = j_ref[static_cast<std::size_t>(row) * n + i];
      const bool is_frozen = std::find(frozen.begin(), frozen.end(), i) != frozen.end();
      if (is_frozen) {
        REQUIRE(a == 0.0);
      } else {
        INFO("row ", row, ", variable ", param.variables()[i].name);
        REQUIRE(a == b);
        nonzero += a != 0.0;
      }
    }
  }
  CHECK(nonzero > count);  // the free columns carry derivatives
  // Residuals alone (no Jacobian requested): the double evaluation, as Ceres' (its double
  // kernel may round differently from the Jets' values, so compare like with like).
  std::vector<double> r_only(count), r_only_ref(count);
  const double* p = x.data();
  REQUIRE(free->Evaluate(&p, r_only.data(), nullptr));
  REQUIRE(reference->Evaluate(&p, r_only_ref.data(), nullptr));
  for (int row = 0; row < count; ++row) CHECK(r_only[row] == r_only_ref[row]);
}

TEST_CASE("optimize: the free-variable Jacobian in several Jet passes, all variables frozen") {
  const std::vector<double> x = {0.3, -1.2, 0.7, 2.0, -0.4, 0.9, 1.5};
  auto* reference_cost = new ceres::DynamicAutoDiffCostFunction<Toy, 4>(new Toy);
  reference_cost->AddParameterBlock(7);
  reference_cost->SetNumResiduals(5);
  std::unique_ptr<ceres::CostFunction> reference(reference_cost);
  std::vector<double> r_ref, j_ref;
  evaluate_cost(*reference, x, r_ref, j_ref);
  // 6 free variables at width 4: two passes (the factory would pick 8; the class is used
  // directly to force the passes).
  const std::vector<int> free = {6, 0, 1, 2, 4, 5};
  FreeJacobianCost<Toy, 4> two_passes(new Toy, 7, 5, free);
  std::vector<double> r, jac;
  evaluate_cost(two_passes, x, r, jac);
  for (int row = 0; row < 5; ++row) {
    CHECK(r[row] == r_ref[row]);
    for (int i = 0; i < 7; ++i) {
      INFO("row ", row, ", variable ", i);
      CHECK(jac[row * 7 + i] == (i == 3 ? 0.0 : j_ref[row * 7 + i]));
    }
  }
  CHECK(j_ref[1 * 7 + 3] != 0.0);  // the frozen column is not zero by accident
  // Everything frozen: residuals, a zero Jacobian.
  std::unique_ptr<ceres::CostFunction> none(
      make_free_jacobian_cost(new Toy, 7, 5, {0, 1, 2, 3, 4, 5, 6}));
  evaluate_cost(*none, x, r, jac);
  for (int row = 0; row < 5; ++row) CHECK(r[row] == r_ref[row]);
  for (double v : jac) CHECK(v == 0.0);
}

TEST_CASE("optimize: a lens traced as written keeps its own focal length, at a finite object too") {
  // A 100 mm achromat (as written: EFL ~100 mm) at a 300 mm object, object-height fields, with
  // the paper's sensor and field defaults (16 mm, 25 deg) left in its specs: the optimizer held
  // d / (2 tan 25 deg) = 17.156 mm and returned a 17 mm lens.
  Lens lens = read_lens(test::source_dir() / "lenses" / "zmx" / "achromat_ac254_100.zmx");
  lens.specs.object_distance_mm = 300.0;
  lens.specs.field_type = FieldType::kObjectHeight;
  lens.specs.fields = {{0.0, 1.0, {}}, {6.0, 1.0, {}}, {12.0, 1.0, {}}};
  lens.specs.sensor_diagonal_mm = 16.0;
  lens.specs.half_field_deg = 25.0;
  REQUIRE(lens.specs.mode == SpecMode::kAsWritten);
  const TraceLens<double> start_trace = make_trace_lens(lens);
  const double efl_start = paraxial_data(start_trace, start_trace.reference_nm()).efl_mm;
  CHECK(design_focal_length_mm(lens) == efl_start);
  CHECK(efl_start > 99.0);
  OptimizeOptions options;
  options.sampling = small_sampling();
  options.glass_search = GlassSearch::kNone;
  options.max_iterations = 15;
  options.max_rounds = 1;
  options.verbose = false;
  options.loss = bounds_for(lens, options.loss, BoundsMode::kAuto);
  const OptimizeResult result = optimize_lens(lens, options);
  const TraceLens<double> final_trace = make_trace_lens(result.lens);
  const double efl_final = paraxial_data(final_trace, final_trace.reference_nm()).efl_mm;
  MESSAGE("achromat at 300 mm: EFL ", efl_start, " -> ", efl_final, " mm; spot ",
          result.start_spot_um, " -> ", result.final_spot_um, " um");
  CHECK(std::abs(efl_final - efl_start) <= 1e-6 * efl_start);
  CHECK(result.final_spot_um <= result.start_spot_um);
}

}  // namespace test_optimize
