// The optimizer's sampling of a lens without rotational symmetry (issue 32): a lens with a
// decentred element has different spots at (0, +10 deg), (0, -10 deg) and (10 deg, 0), and the
// design loss must trace each field as written (its azimuth, TraceSystem::field_azimuth_deg), as
// analyze does, not as the mirror of +y. Its merit at the start equals analyze's weighted mean of
// the per-field RMS spots; the per-field targets number the fields as analyze lists them.
#include <doctest/doctest.h>

#include <cmath>

#include "lensopt/analysis/analyze.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/optimize/design_loss.h"
#include "lensopt/optimize/design_sampling.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/optimize/variables.h"
#include "test_support.h"

namespace test_optimize_placed_fields {

using namespace lensopt;

namespace {

FieldPoint field_at(double x, double y, double weight) {
  FieldPoint f;
  f.x = x;
  f.value = y;
  f.weight = weight;
  return f;
}

// The Cooke triplet (lenses/zmx/cooke_triplet_50.zmx, as written) with its middle element
// decentred by `dy` mm in y (both faces, each restoring the frame after it), at the fields
// (0, 0), (0, +10), (0, -10) and (10, 0) deg with weights 1, 2, 3, 4 and wavelength weights.
// (The design loss also traced the decenters of such a lens times its focal length: the
// parameterization scaled the structure's placements as normalized lengths.)
Lens decentred_cooke(double dy) {
  Lens lens = read_lens(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx");
  REQUIRE(lens.specs.mode == SpecMode::kAsWritten);
  // The middle element: from its first glass surface to the first surface followed by air (the
  // .zmx's stop on its back face is a flat stop inserted inside it, which stays in place).
  int glass = 0, first = -1;
  for (int k = 0; k < static_cast<int>(lens.surfaces.size()); ++k)
    if (!lens.surfaces[k].material.is_air() && ++glass == 2 && first < 0) first = k;
  REQUIRE(first > 0);
  int k = first;
  for (; k < static_cast<int>(lens.surfaces.size()); ++k) {
    if (!lens.surfaces[k].is_stop && dy != 0.0) {
      lens.surfaces[k].placement.decenter_y_mm = dy;
      lens.surfaces[k].restore_frame = true;
    }
    if (lens.surfaces[k].material.is_air()) break;
  }
  REQUIRE(k > first + 1);
  lens.specs.fields = {field_at(0.0, 0.0, 1.0), field_at(0.0, 10.0, 2.0), field_at(0.0, -10.0, 3.0),
                       field_at(10.0, 0.0, 4.0)};
  lens.specs.wavelength_weights.assign(lens.specs.wavelengths_nm.size(), 1.0);
  lens.specs.wavelength_weights.front() = 0.5;
  return lens;
}

struct MeritCheck {
  double design_um = 0;   // l_S of the design loss at the start (um)
  double analyze_um = 0;  // analyze's weighted mean RMS spot (um)
  std::vector<double> field_um;
};

MeritCheck start_merit(const Lens& lens, int rings) {
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions sampling;
  sampling.rings = rings;
  sampling.fields = 5;
  DesignLoss<double> loss;
  REQUIRE(evaluate_design<double>(param, x.data(), GlassMode::kContinuous, {}, sampling,
                                  DesignLossOptions{}, nullptr, nullptr, &loss));
  AnalyzeOptions options;
  options.trace.rings = rings;
  const AnalysisReport report = analyze_lens(lens, options);
  MeritCheck out;
  out.design_um = loss.spot_mm * 1000.0;
  REQUIRE(report.mean_rms_spot_um);
  out.analyze_um = *report.mean_rms_spot_um;
  // The same mean from the per-field rows and the written weights.
  double sum = 0.0, weights = 0.0;
  for (const FieldReport& f : report.fields) {
    REQUIRE(f.rms_spot_um);
    out.field_um.push_back(*f.rms_spot_um);
    sum += f.weight * *f.rms_spot_um;
    weights += f.weight;
  }
  CHECK(std::abs(sum / weights - out.analyze_um) <= 1e-12 * out.analyze_um);
  REQUIRE(loss.field_rms_mm.size() == report.fields.size());
  for (std::size_t h = 0; h < report.fields.size(); ++h) {
    INFO("field ", h + 1, ": design ", loss.field_rms_mm[h] * 1000.0, " um, analyze ",
         out.field_um[h], " um");
    CHECK(std::abs(loss.field_rms_mm[h] * 1000.0 - out.field_um[h]) <= 1e-9 * out.field_um[h]);
  }
  return out;
}

}  // namespace

TEST_CASE(
    "optimize placed fields: the design loss traces +y, -y and x fields of a decentred "
    "lens as analyze does") {
  const Lens lens = decentred_cooke(0.2);
  REQUIRE(lens.breaks_symmetry());
  const MeritCheck m = start_merit(lens, 8);
  MESSAGE("decentred Cooke: design l_S ", m.design_um, " um, analyze ", m.analyze_um,
          " um; fields ", m.field_um[0], ", ", m.field_um[1], ", ", m.field_um[2], ", ",
          m.field_um[3], " um");
  // The decenter makes the three 10 deg fields differ (else the check below proves nothing).
  REQUIRE(m.field_um.size() == 4);
  CHECK(std::abs(m.field_um[1] - m.field_um[2]) > 1e-3 * m.field_um[1]);
  CHECK(std::abs(m.field_um[1] - m.field_um[3]) > 1e-3 * m.field_um[1]);
  CHECK(std::abs(m.design_um - m.analyze_um) <= 1e-9 * m.analyze_um);
  // The sampling names each field as written.
  const std::string text = describe_design_sampling(lens, TraceOptions{});
  INFO(text);
  CHECK(text.find("(0, -10)") != std::string::npos);
  CHECK(text.find("(10, 0)") != std::string::npos);
}

TEST_CASE("optimize placed fields: a rotationally symmetric lens keeps its sampling") {
  // Without the decenter the field on -y is the +y field (weights added; lens_setup) and the x
  // field is traced as the +y field turned (the same rays): three spot fields, and the design
  // loss agrees with analyze, as before.
  const Lens lens = decentred_cooke(0.0);
  REQUIRE_FALSE(lens.breaks_symmetry());
  const DesignSampling d = design_sampling(lens, TraceOptions{});
  CHECK(d.spot_fields == 3);  // 0, 10 deg on y (+y and -y as one) and 10 deg on x
  // The x field keeps its azimuth (it traces the same rays on a symmetric lens).
  CHECK(d.setup.field_azimuth_deg.size() == d.setup.field_values.size());
  const MeritCheck m = start_merit(lens, 8);
  CHECK(std::abs(m.design_um - m.analyze_um) <= 1e-9 * m.analyze_um);
}

TEST_CASE("optimize placed fields: per-field targets number the fields as analyze lists them") {
  const Lens lens = decentred_cooke(0.2);
  const AnalysisReport report = analyze_lens(lens, AnalyzeOptions{});
  REQUIRE(report.fields.size() == 4);
  const std::vector<DesignTarget> ok = {
      parse_target("rms_spot_um<=100,field=4", SourceLocation{"--target"})};
  CHECK_NOTHROW(check_target_fields(lens, ok));
  const std::vector<DesignTarget> beyond = {
      parse_target("rms_spot_um<=100,field=5", SourceLocation{"--target"})};
  CHECK_THROWS_WITH(check_target_fields(lens, beyond), doctest::Contains("the lens has 4 fields"));
  // A symmetric lens lists the fields on +y and -y as one, the x field as its own.
  const Lens symmetric = decentred_cooke(0.0);
  CHECK(analyze_lens(symmetric, AnalyzeOptions{}).fields.size() == 3);
  CHECK_NOTHROW(check_target_fields(
      symmetric, {parse_target("rms_spot_um<=100,field=3", SourceLocation{"--target"})}));
  CHECK_THROWS_WITH(check_target_fields(symmetric, {parse_target("rms_spot_um<=100,field=4",
                                                                 SourceLocation{"--target"})}),
                    doctest::Contains("the lens has 3 fields"));
}

}  // namespace test_optimize_placed_fields
