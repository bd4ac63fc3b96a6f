// Glass elements split by a dummy or stop surface (optimize/glass_elements.h): the .zmx reader
// puts a flat stop at the vertex of a curved stop surface, inside the glass of the element the
// stop surface closes (the Cooke triplet's flint). Before, each half was bounded on its own: the
// half 0 mm thick on axis made the lens-derived glass bound 0 for every element, and optimize
// returned a 11 um edge on the rear crown marked "pass". Now the element is bounded on its
// summed travel and edge, and the bounds come from whole elements.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "lensopt/analysis/analyze.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/optimize/design_loss.h"
#include "lensopt/optimize/glass_elements.h"
#include "lensopt/optimize/optimizer.h"
#include "test_support.h"

namespace test_optimize_split_elements {

using namespace lensopt;

namespace {

Lens cooke_50() {
  return read_lens(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx");
}

// The sag of a sphere of curvature c at height h (independent of lens/profile_sag.h).
double sphere_sag(double c, double h) {
  return c * h * h / (1.0 + std::sqrt(1.0 - c * c * h * h));
}

}  // namespace

TEST_CASE("optimize split elements: the Cooke's flint split by its curved stop is one element") {
  const Lens lens = cooke_50();
  // S1 S2 | S3 stop S4 | S5 S6: the stop (index 3) has F2 on both sides.
  REQUIRE(lens.surfaces.size() == 7);
  REQUIRE(lens.surfaces[3].is_stop);
  const std::vector<int> first = element_first_spaces(lens);
  CHECK(first == std::vector<int>{0, 1, 2, 2, 4, 5, 6});
  CHECK_FALSE(element_last_space(first, 2));
  CHECK(element_last_space(first, 3));
  // The start's derived bounds: from whole elements (before: min glass 0, from the flint's
  // second half, 0 mm on axis).
  const DesignLossOptions derived = lens_derived_bounds(lens, DesignLossOptions{});
  MESSAGE("cooke_triplet_50 derived glass bounds: ", derived.min_glass_mm, " .. ",
          derived.max_glass_mm, " mm");
  CHECK(derived.min_glass_mm > 0.2);
  // The report has one row pair for the flint, of its summed travel (>= its 1 mm centre).
  const ConstraintReport start = check_constraints(lens, derived, AnalyzeOptions{}.trace);
  bool flint = false;
  for (const ConstraintReport::Row& r : start.rows) {
    CHECK(r.name.find("glass 4-5") == std::string::npos);
    CHECK(r.name.find("glass 3-4") == std::string::npos);
    if (r.name.rfind("glass 3-5 (", 0) == 0 && r.name.size() > 4 &&
        r.name.compare(r.name.size() - 4, 4, " min") == 0) {
      flint = true;
      CHECK(r.value > 0.99);
      CHECK(r.pass);
    }
  }
  CHECK(flint);
}

TEST_CASE("optimize split elements: optimize holds every element's edge (regression)") {
  const Lens lens = cooke_50();
  OptimizeOptions o;
  o.glass_search = GlassSearch::kNone;
  o.verbose = false;
  o.loss = bounds_for(lens, o.loss, BoundsMode::kAuto);
  REQUIRE(o.loss.min_glass_mm > 0.2);
  const OptimizeResult r = optimize_lens(lens, o);
  MESSAGE("cooke_triplet_50: spot ", r.start_spot_um, " -> ", r.final_spot_um, " um");
  CHECK(r.final_constraints.all_pass());
  CHECK(r.final_spot_um < r.start_spot_um);
  // Every element's edge, computed here from the sphere sags at the report's heights, holds the
  // bound of its row, and the bound is not 0 (before: the rear crown's edge was 0.011 mm).
  int edges = 0;
  for (const ConstraintReport::Row& row : r.final_constraints.rows) {
    int a = 0, b = 0;
    double h = 0.0;
    if (std::sscanf(row.name.c_str(), "glass %d-%d edge at %lf mm", &a, &b, &h) != 3) continue;
    ++edges;
    const Lens& out = r.lens;
    double t = 0.0;
    for (int k = a - 1; k < b - 1; ++k) t += out.surfaces[k].thickness_mm;
    auto edge = [&](double at) {
      return t + sphere_sag(out.surfaces[b - 1].curvature_per_mm, at) -
             sphere_sag(out.surfaces[a - 1].curvature_per_mm, at);
    };
    // The row prints the height to 3 digits: the edge lies between its values at the ends of
    // the rounding interval.
    const double d = 0.5 * std::pow(10.0, std::floor(std::log10(h)) - 2);
    const double lo = std::min(edge(h - d), edge(h + d)), hi = std::max(edge(h - d), edge(h + d));
    INFO(row.name, ": ", row.value, " mm in [", lo, ", ", hi, "], bound ", row.bound);
    CHECK(row.value >= lo - 1e-12);
    CHECK(row.value <= hi + 1e-12);
    CHECK(row.bound > 0.2);
    CHECK(row.value >= row.bound);
    CHECK(row.pass);
  }
  CHECK(edges == 3);  // three elements, the flint once (glass 3-5)
}

TEST_CASE("optimize split elements: the adjoint gradient of the summed bound matches FD") {
  const Lens lens = cooke_50();
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions sampling;
  sampling.rings = 4;
  sampling.fields = 3;
  DesignLossOptions loss;
  // The flint's summed travel is 1.0 mm on axis: a 1.3 mm minimum makes its bound active (and
  // would be violated by each half alone whatever the other does).
  loss.min_glass_mm = 1.3;
  loss.max_glass_mm = 10.0;
  loss.min_image_clearance_mm = 1.0;
  const DesignValueGradient adj =
      design_loss_gradient(param, x, GlassMode::kContinuous, {}, sampling, loss);
  const DesignValueGradient jets =
      design_loss_gradient_jets(param, x, GlassMode::kContinuous, {}, sampling, loss);
  REQUIRE(adj.loss.ray_path_mm > 0.0);
  auto total = [&](const std::vector<double>& at) {
    DesignLoss<double> l;
    evaluate_design<double>(param, at.data(), GlassMode::kContinuous, {}, sampling, loss, nullptr,
                            nullptr, &l);
    return l.total;
  };
  for (int i = 0; i < param.size(); ++i) {
    std::vector<double> p = x, m = x;
    const double step = 1e-6;
    p[i] += step;
    m[i] -= step;
    const double fd = (total(p) - total(m)) / (2 * step);
    INFO("variable ", i, ": adjoint ", adj.gradient[i], " jets ", jets.gradient[i], " fd ", fd);
    CHECK(adj.gradient[i] == doctest::Approx(jets.gradient[i]).epsilon(1e-9).scale(1e-9));
    CHECK(jets.gradient[i] == doctest::Approx(fd).epsilon(1e-5).scale(1e-6));
  }
}

}  // namespace test_optimize_split_elements
