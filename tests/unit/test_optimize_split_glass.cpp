// One glass per physical element (optimize/variables.h): a glass element split by a dummy or
// stop surface (optimize/glass_elements.h; the .zmx reader's flat stop at the vertex of the
// Cooke triplet's curved stop face, inside its F2 flint) has one glass variable pair, which both
// spaces take. Before, each half had its own pair (g3 and g4 on lenses/zmx/cooke_triplet_50.zmx),
// so a glass search could put two glasses on either side of the stop and make it refract.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/optimize/design_loss.h"
#include "lensopt/optimize/glass_elements.h"
#include "lensopt/optimize/optimizer.h"
#include "test_support.h"

namespace test_optimize_split_glass {

using namespace lensopt;

namespace {

Lens cooke_50() {
  return read_lens(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx");
}

int index_of(const LensParameterization& param, const std::string& name) {
  for (int i = 0; i < param.size(); ++i)
    if (param.variables()[i].name == name) return i;
  return -1;
}

// True when both spaces of the split flint (spaces 2 and 3, either side of the stop) hold the
// same glass.
bool flint_halves_identical(const Lens& lens) {
  const Material& a = lens.surfaces[2].material;
  const Material& b = lens.surfaces[3].material;
  return same_glass(a, b) && a.label() == b.label();
}

// The same with the stop in the middle of the flint (0.5 mm of glass on either side), so both
// halves refract rays over a real length.
Lens cooke_50_stop_mid_flint() {
  Lens lens = cooke_50();
  lens.surfaces[2].thickness_mm = 0.5;
  lens.surfaces[3].thickness_mm = 0.49997;
  return lens;
}

}  // namespace

TEST_CASE("split glass: one glass variable pair per element, both spaces take it") {
  const Lens lens = cooke_50();
  // S1 S2 | S3 stop S4 | S5 S6: the stop (index 3) has F2 on both sides.
  REQUIRE(lens.surfaces.size() == 7);
  REQUIRE(lens.surfaces[3].is_stop);
  REQUIRE(element_first_spaces(lens) == std::vector<int>{0, 1, 2, 2, 4, 5, 6});
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  std::vector<std::string> glass_names;
  for (const LensVariable& v : param.variables())
    if (v.group == "glasses") glass_names.push_back(v.name);
  // Three elements, three pairs: no g4 (before: g1, g3, g4, g6).
  CHECK(glass_names == std::vector<std::string>{"g1.0", "g1.1", "g3.0", "g3.1", "g6.0", "g6.1"});
  CHECK_THROWS_AS(param.select({"g4"}), Error);
  std::vector<double> x = param.from_lens(lens);
  CHECK(param.nearest_glasses(x.data()).size() == 3);

  // Move the flint's pair far from its start: both halves follow, in every glass mode.
  const int g0 = index_of(param, "g3.0");
  REQUIRE(g0 >= 0);
  x[g0] += 0.7;
  x[g0 + 1] -= 0.4;
  for (const GlassMode mode : {GlassMode::kContinuous, GlassMode::kQuantized, GlassMode::kFixed}) {
    const std::vector<int> fixed = param.nearest_glasses(x.data());
    const TraceLens<double> tl = param.to_trace_lens(x.data(), mode, fixed);
    INFO("mode ", static_cast<int>(mode), ": nd ", tl.nd[2], " / ", tl.nd[3], ", vd ", tl.vd[2],
         " / ", tl.vd[3]);
    CHECK(tl.nd[2] == tl.nd[3]);
    CHECK(tl.vd[2] == tl.vd[3]);
    CHECK(tl.is_glass[2] == tl.is_glass[3]);
    if (!tl.catalog_offset.empty()) CHECK(tl.catalog_offset[2] == tl.catalog_offset[3]);
    // The flint moved (the pair is live), the crowns did not.
    const TraceLens<double> start =
        param.to_trace_lens(param.from_lens(lens).data(), mode, param.nearest_glasses(x.data()));
    if (mode == GlassMode::kContinuous) CHECK(std::abs(tl.nd[2] - start.nd[2]) > 1e-3);
    const Lens out = param.to_lens(x.data(), mode, fixed);
    CHECK(flint_halves_identical(out));
  }
}

TEST_CASE("split glass: the shared glass variable's exact gradient matches central FD") {
  for (const bool mid : {false, true}) {
    const Lens lens = mid ? cooke_50_stop_mid_flint() : cooke_50();
    const std::string name = mid ? "cooke_triplet_50, stop mid-flint," : "cooke_triplet_50";
    const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
    std::vector<double> x = param.from_lens(lens);
    const int g0 = index_of(param, "g3.0");
    REQUIRE(g0 >= 0);
    // Off the catalog points, so the glass-variable term has a gradient too.
    x[g0] += 0.05;
    x[g0 + 1] -= 0.03;
    TraceOptions sampling;
    sampling.rings = 4;
    sampling.fields = 3;
    // Bounds far from active (the total is smooth: spot, glass and profile terms).
    DesignLossOptions loss;
    loss.min_air_mm = 0.0;
    loss.min_glass_mm = 0.0;
    loss.max_glass_mm = 100.0;
    loss.min_image_clearance_mm = 0.0;
    loss.max_ray_angle_deg = 89.0;
    const DesignValueGradient adj =
        design_loss_gradient(param, x, GlassMode::kContinuous, {}, sampling, loss);
    const DesignValueGradient jets =
        design_loss_gradient_jets(param, x, GlassMode::kContinuous, {}, sampling, loss);
    REQUIRE(adj.finite);
    auto total = [&](const std::vector<double>& at) {
      DesignLoss<double> l;
      evaluate_design<double>(param, at.data(), GlassMode::kContinuous, {}, sampling, loss, nullptr,
                              nullptr, &l);
      return l.total;
    };
    auto fd = [&](int i) {
      auto central = [&](double h) {
        std::vector<double> p = x, m = x;
        p[i] += h;
        m[i] -= h;
        return (total(p) - total(m)) / (2 * h);
      };
      return (4 * central(5e-6) - central(1e-5)) / 3;  // one Richardson step
    };
    for (const int i : {g0, g0 + 1}) {
      const double d = fd(i);
      MESSAGE(name, " ", param.variables()[i].name, " (both halves of the flint): adjoint ",
              adj.gradient[i], ", jets ", jets.gradient[i], ", central FD ", d,
              "; relative differences ", std::abs(adj.gradient[i] - d) / std::abs(d), ", ",
              std::abs(jets.gradient[i] - d) / std::abs(d));
      CHECK(std::abs(d) > 1e-6);
      CHECK(std::abs(adj.gradient[i] - d) <= 1e-6 * std::abs(d));
      CHECK(std::abs(jets.gradient[i] - d) <= 1e-6 * std::abs(d));
    }
    // The variable drives the index after the stop as well as before it.
    std::vector<double> moved = x;
    moved[g0] += 1e-3;
    const TraceLens<double> a = param.to_trace_lens(x.data(), GlassMode::kContinuous);
    const TraceLens<double> b = param.to_trace_lens(moved.data(), GlassMode::kContinuous);
    CHECK(b.nd[3] != a.nd[3]);
    CHECK(b.nd[3] == b.nd[2]);
  }
}

TEST_CASE("split glass: a glass search keeps both halves of the flint one glass") {
  for (const bool mid : {false, true}) {
    const Lens lens = mid ? cooke_50_stop_mid_flint() : cooke_50();
    OptimizeOptions o;
    o.glass_search = mid ? GlassSearch::kNeighbours : GlassSearch::kSnap;
    o.verbose = false;
    o.loss = bounds_for(lens, o.loss, BoundsMode::kAuto);
    const OptimizeResult r = optimize_lens(lens, o);
    std::string glasses;
    for (const Surface& s : r.lens.surfaces)
      if (!s.material.is_air()) glasses += s.material.label() + " ";
    const std::string name = mid ? "cooke_triplet_50, stop mid-flint, --glass-search neighbours"
                                 : "cooke_triplet_50, --glass-search snap";
    MESSAGE(name, ": spot ", r.start_spot_um, " -> ", r.final_spot_um, " um; glasses per space ",
            glasses);
    CHECK(flint_halves_identical(r.lens));
    CHECK(r.final_constraints.all_pass());
    CHECK(r.final_spot_um < r.start_spot_um);
  }
}

TEST_CASE("split glass: OptimizeResult.glasses names a split element's glass once") {
  // The Cooke triplet's flint is split by the stop at its curved face's vertex: 4 glass spaces,
  // 3 elements, 3 glasses (it listed the flint twice).
  const Lens lens = cooke_50();
  OptimizeOptions o;
  o.verbose = false;
  o.max_iterations = 2;
  o.max_rounds = 1;
  o.soft_start = false;
  o.loss = bounds_for(lens, o.loss, BoundsMode::kAuto);
  const OptimizeResult r = optimize_lens(lens, o);
  const std::vector<int> first = element_first_spaces(r.lens);
  std::vector<std::string> expected;
  int glass_spaces = 0;
  for (std::size_t k = 0; k < r.lens.surfaces.size(); ++k) {
    if (r.lens.surfaces[k].material.is_air()) continue;
    ++glass_spaces;
    if (first[k] == static_cast<int>(k)) expected.push_back(r.lens.surfaces[k].material.label());
  }
  CHECK(glass_spaces == 4);
  CHECK(expected.size() == 3);
  CHECK(r.glasses == expected);
  CHECK(summarize(r).glasses == expected);
}

}  // namespace test_optimize_split_glass
