// The paper's Table 2: mean RMS spot of the baseline lenses at full sampling with ray aiming,
// from the paper's released YAML (../shared) and from the project's own TOML versions.
#include <doctest/doctest.h>

#include "lensopt/analysis/analyze.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "test_support.h"

namespace test_reference {

using namespace lensopt;

namespace {

struct Table2Row {
  const char* name;
  double spot_um;
};
constexpr Table2Row kTable2[] = {{"doublet", 80.1}, {"cooke", 30.6}, {"tessar", 14.8}};

double mean_spot_um(const Lens& lens, bool ray_aiming = true) {
  AnalyzeOptions options;
  options.trace.ray_aiming = ray_aiming;
  const AnalysisReport report = analyze_lens(lens, options);
  REQUIRE(report.mean_rms_spot_um.has_value());
  CHECK(report.ray_failures == 0);
  return *report.mean_rms_spot_um;
}

}  // namespace

TEST_CASE("reference: Table 2 spot sizes from the project's TOML lenses within 1%") {
  for (const Table2Row& row : kTable2) {
    const Lens lens = read_lens(test::source_dir() / "lenses" / (std::string(row.name) + ".toml"));
    const double spot = mean_spot_um(lens);
    MESSAGE(row.name, ": ", spot, " um (paper ", row.spot_um, ")");
    CHECK(std::abs(spot - row.spot_um) / row.spot_um < 0.01);
  }
}

TEST_CASE("reference: Table 2 spot sizes from the paper's YAML within 1%") {
  LENSOPT_REQUIRE_SHARED(shared);
  for (const Table2Row& row : kTable2) {
    const Lens lens = read_lens(shared / "data" / "reference-lenses" /
                                (std::string("baseline_") + row.name + ".yml"));
    const double spot = mean_spot_um(lens);
    MESSAGE(row.name, " (yml): ", spot, " um (paper ", row.spot_um, ")");
    CHECK(std::abs(spot - row.spot_um) / row.spot_um < 0.01);
  }
}

TEST_CASE("reference: without ray aiming the Tessar is clearly worse") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  const double aimed = mean_spot_um(lens, true);
  const double unaimed = mean_spot_um(lens, false);
  MESSAGE("tessar: aimed ", aimed, " um, unaimed ", unaimed, " um");
  CHECK(unaimed > 1.5 * aimed);
}

TEST_CASE("reference: analysis figures of the Tessar are physically sensible") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  const AnalysisReport r = analyze_lens(lens, AnalyzeOptions{});
  CHECK(r.efl_mm == doctest::Approx(lens.specs.focal_length_mm()).epsilon(1e-12));
  CHECK(r.epd_mm == doctest::Approx(r.efl_mm / 2.0).epsilon(1e-12));
  REQUIRE(r.fields.size() == 21);
  // On axis: no distortion, unit relative illumination.
  CHECK(r.fields[0].distortion_percent == doctest::Approx(0.0).epsilon(1e-9));
  REQUIRE(r.fields[0].relative_illumination);
  CHECK(*r.fields[0].relative_illumination == doctest::Approx(1.0).epsilon(1e-12));
  // Off axis: illumination falls, but no faster than cos^4 by much for a lens with no vignetting
  // (pupil aberration can make it fall slower or faster); it stays in (0, 1.2).
  for (const FieldReport& f : r.fields) {
    REQUIRE(f.relative_illumination);
    CHECK(*f.relative_illumination > 0.0);
    CHECK(*f.relative_illumination < 1.2);
  }
  // One aiming step (the paper's) cuts the pupil error by more than an order of magnitude.
  AnalyzeOptions unaimed_options;
  unaimed_options.trace.ray_aiming = false;
  const AnalysisReport unaimed = analyze_lens(lens, unaimed_options);
  MESSAGE("tessar: largest aiming error ", 100 * r.max_aiming_error, " % of the stop radius, ",
          100 * unaimed.max_aiming_error, " % without ray aiming");
  CHECK(r.max_aiming_error < 0.1 * unaimed.max_aiming_error);
}

}  // namespace test_reference
