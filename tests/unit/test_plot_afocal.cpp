// The spot diagram of an afocal lens in angle (plot/afocal_plot.h): the drawn RMS is the
// analysis's, in microradians, and the image-plane kinds are refused by name.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <fstream>
#include <sstream>
#include <string>

#include "error_checks.h"
#include "lensopt/analysis/afocal.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/plot/afocal_plot.h"
#include "lensopt/plot/plot.h"
#include "test_support.h"

namespace lensopt::plot::test_plot_afocal {
namespace {

// A Keplerian telescope f1 = 100, f2 = 25 of two plano-convex singlets (OpticStudio model
// glass, n = 1.5168 at 587.5618 nm), spaced afocal (test_afocal.cpp states the closed form).
Lens keplerian() {
  const double n = 1.5168, t = 4.0;
  const std::string text = fmt::format(
      "[lens]\nname = \"keplerian\"\n"
      "[system]\nmode = \"as-written\"\nafocal = true\naperture = \"epd\"\naperture_value = 20\n"
      "primary_wavelength_nm = 587.5618\nfields = [0, 0.5, 1]\n"
      "[specs]\nwavelengths_nm = [486.1327, 587.5618, 656.2725]\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = 0\nstop = true\n"
      "[[surfaces]]\ncurvature_per_mm = {:.17g}\nthickness_mm = {}\n"
      "material = {{ nd = 1.5168, vd = 64.17, model = \"opticstudio\" }}\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = {:.17g}\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = {}\n"
      "material = {{ nd = 1.5168, vd = 64.17, model = \"opticstudio\" }}\n"
      "[[surfaces]]\ncurvature_per_mm = {:.17g}\nthickness_mm = 40\n",
      1.0 / ((n - 1.0) * 100.0), t, 125.0 - 2.0 * t / n, t, -1.0 / ((n - 1.0) * 25.0));
  return parse_lens_toml(text, "keplerian.toml");
}

TEST_CASE("plot afocal: the spot diagram is drawn in microradians with the analysis's RMS") {
  const Lens lens = keplerian();
  TraceOptions trace;
  trace.rings = 8;
  const SpotData spots = afocal_spot_data(lens, trace);
  CHECK(spots.unit == "\u00b5rad");
  AfocalOptions options;
  options.wavefront = false;
  const AfocalReport report = analyze_afocal_lens(lens, trace, options);
  REQUIRE(spots.fields.size() == 3);
  for (std::size_t h = 0; h < 3; ++h) {
    REQUIRE(report.fields[h].rms_angular_spot_mrad);
    CHECK(spots.fields[h].rms_um == doctest::Approx(1e3 * *report.fields[h].rms_angular_spot_mrad));
    CHECK(!spots.fields[h].x_um.empty());
    CHECK(spots.fields[h].position_label.find("out ") == 0);
  }
  PlotOptions plot;
  plot.kind = PlotKind::kSpot;
  plot.trace = trace;
  const auto path = test::temp_root() / "afocal_spot.svg";
  const PlotSummary summary = write_plot(lens, nullptr, plot, path);
  CHECK(summary.spot_box_um > 0);
  std::ifstream in(path);
  std::stringstream svg;
  svg << in.rdbuf();
  CHECK(svg.str().find("\u00b5rad") != std::string::npos);
  CHECK(svg.str().find("afocal image space") != std::string::npos);
  // An image-plane kind is refused, naming the kind and what to use.
  plot.kind = PlotKind::kLayout;
  const std::string e = test::error_of([&] { write_plot(lens, nullptr, plot, path); });
  CHECK(e.find("--kind layout") != std::string::npos);
  CHECK(e.find("afocal") != std::string::npos);
}

}  // namespace
}  // namespace lensopt::plot::test_plot_afocal
