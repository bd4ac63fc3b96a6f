// The design loss's constraint pass (optimize/design_loss.h, add_constraints): without extremes
// to report, only the rays that a first pass over the records marks (an entry past a bound, or
// within kHingeTie of the angle bound) are visited. The residuals and the loss terms must be
// those of visiting every ray (as an evaluation with extremes does), bit for bit, on double and
// on Jets, with the penalties active on some rays and not on others.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "bit_compare.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/optimize/optimizer.h"
#include "test_support.h"

namespace test_optimize_screen {

using namespace lensopt;

namespace {

using test::same_bits;

template <typename T>
void check_screened(const std::string& file, const DesignLossOptions& options) {
  CAPTURE(file);
  CAPTURE(options.max_ray_angle_deg);
  CAPTURE(options.paper_penalties);
  const Lens lens = read_lens(test::source_dir() / "lenses" / file);
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  TraceOptions sampling;
  sampling.rings = 8;
  sampling.fields = 5;
  sampling.threads = 2;
  std::vector<T> xt(param.size());
  for (int i = 0; i < param.size(); ++i) {
    if constexpr (std::is_same_v<T, double>)
      xt[i] = x[i];
    else
      xt[i] = T(x[i], i % static_cast<int>(T::DIMENSION));
  }
  // The residual count: the loss without residuals first (its field count), then both ways.
  DesignLoss<T> probe;
  evaluate_design<T>(param, xt.data(), GlassMode::kFixed, glasses, sampling, options, nullptr,
                     nullptr, &probe);
  const int fields = static_cast<int>(probe.field_rms_mm.size());
  const int rays = static_cast<int>(paper_pupil_samples(sampling.rings).size());
  const int count =
      design_residual_count(fields, constraint_field_count(fields, kConstraintFields),
                            static_cast<int>(lens.specs.wavelengths_nm.size()), rays,
                            static_cast<int>(lens.surfaces.size()), lens.element_count());
  std::vector<T> screened(count, K<T>(0.0)), visited(count, K<T>(0.0));
  DesignLoss<T> loss_screened, loss_visited;
  DesignExtremes extremes;
  evaluate_design<T>(param, xt.data(), GlassMode::kFixed, glasses, sampling, options, nullptr,
                     screened.data(), &loss_screened);
  evaluate_design<T>(param, xt.data(), GlassMode::kFixed, glasses, sampling, options, nullptr,
                     visited.data(), &loss_visited, &extremes);
  // Some rays are past a bound and some are not: the pass skips rays and visits others.
  REQUIRE(value_of(loss_visited.ray_path_mm) + value_of(loss_visited.ray_angle) > 0.0);
  int differing = 0, penalties = 0;
  for (int i = 0; i < count; ++i) differing += !same_bits(screened[i], visited[i]);
  for (int i = fields * static_cast<int>(lens.specs.wavelengths_nm.size()) * rays * 2; i < count;
       ++i)
    penalties += value_of(visited[i]) != 0.0;
  CHECK(penalties > 0);
  CHECK(differing == 0);
  CHECK(same_bits(loss_screened.total, loss_visited.total));
  CHECK(same_bits(loss_screened.ray_path_mm, loss_visited.ray_path_mm));
  CHECK(same_bits(loss_screened.ray_angle, loss_visited.ray_angle));
  CHECK(same_bits(loss_screened.spot_mm, loss_visited.spot_mm));
}

}  // namespace

TEST_CASE("design loss: screening the constraint rays gives the bits of visiting them all") {
  DesignLossOptions strict;  // the Cooke crosses its air-gap and angle bounds (test_optimize.cpp)
  DesignLossOptions tight;   // most rays near or past a 35 deg angle bound
  tight.max_ray_angle_deg = 35.0;
  tight.min_air_mm = 2.0;
  DesignLossOptions paper;
  paper.paper_penalties = true;
  for (const char* file : {"cooke.toml", "tessar.toml", "doublet-asphere.toml"}) {
    for (const DesignLossOptions* options : {&strict, &tight, &paper}) {
      // The default bounds hold on the Tessar and the doublet: only the tight ones there.
      if (std::string(file) != "cooke.toml" && options != &tight) continue;
      check_screened<double>(file, *options);
      check_screened<ceres::Jet<double, 12>>(file, *options);
    }
  }
}

}  // namespace test_optimize_screen
