// Plots of lenses as written (issue 29): each of the lens's own fields once, titles with the
// number of fields analyze used, and fields labelled in the lens's field type (deg, object
// height mm, image height mm).
#include <doctest/doctest.h>

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "lensopt/formats/lens_file.h"
#include "lensopt/plot/canvas.h"
#include "lensopt/plot/layout.h"
#include "lensopt/plot/plot.h"
#include "lensopt/plot/psf_strip.h"
#include "test_support.h"

namespace test_plot_fields {

using namespace lensopt;
using namespace lensopt::plot;

namespace {

std::string report_svg(const PlotContext& ctx) {
  PlotOptions options;
  options.kind = PlotKind::kReport;
  const auto canvas = draw_plot(
      ctx, nullptr, options, [](double w, double h) { return std::make_unique<SvgCanvas>(w, h); });
  return dynamic_cast<SvgCanvas&>(*canvas).str();
}

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t i = 0; (i = text.find(what, i)) != std::string::npos; i += what.size()) ++n;
  return n;
}

}  // namespace

TEST_CASE("plot fields: the shipped double Gauss plots its own fields 0, 10, 14 deg once each") {
  const Lens lens = read_lens(test::source_dir() / "lenses/zmx/double_gauss_100.zmx");
  const PlotContext ctx = make_plot_context(lens);
  REQUIRE(ctx.sys.fields_deg == std::vector<double>{0.0, 10.0, 14.0});
  const std::vector<int> all{0, 1, 2};
  const SpotData spots = compute_spots(ctx);
  std::vector<int> spot_fields;
  for (const SpotField& f : spots.fields) spot_fields.push_back(f.field);
  CHECK(spot_fields == all);  // was 0, 0, 1, 1, 2
  CHECK(spots.analyzed_fields == 3);
  const FanData fans = compute_fans(ctx);
  REQUIRE(fans.fields.size() == 3);
  CHECK(fans.fields[1].field_deg == 10.0);
  CHECK(fans.fields[1].label == "10.0\u00b0");
  const PsfStrip strip = compute_psf_strip(ctx);
  CHECK(strip.tiles.size() == 3);
  CHECK(compute_layout(ctx).field_deg == std::vector<double>{0.0, 10.0, 14.0});

  const std::string svg = report_svg(ctx);
  CHECK(svg.find("(3 fields)") != std::string::npos);
  CHECK(svg.find("21 fields") == std::string::npos);
  // Each field once per chart: the spot boxes, the PSF tiles and the fan titles of 10 deg.
  CHECK(count(svg, "10.0\u00b0  (y ") == 1);
  CHECK(count(svg, "10.0\u00b0 tangential") == 1);
}

TEST_CASE("plot fields: the paper's lenses keep five spot fields out of their 21") {
  const Lens lens = read_lens(test::source_dir() / "lenses/tessar.toml");
  const PlotContext ctx = make_plot_context(lens);
  const SpotData spots = compute_spots(ctx);
  REQUIRE(spots.fields.size() == 5);
  CHECK(spots.analyzed_fields == 21);
  CHECK(spots.fields[4].label == "25.0\u00b0");
  CHECK(report_svg(ctx).find("(21 fields)") != std::string::npos);
}

TEST_CASE("plot fields: object- and image-height fields are labelled in mm, not degrees") {
  // The achromat as written, its fields given as object heights at a finite distance, then as
  // real image heights.
  Lens lens = read_lens(test::source_dir() / "lenses/zmx/achromat_ac254_100.zmx");
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.object_distance_mm = 1000.0;
  lens.specs.field_type = FieldType::kObjectHeight;
  lens.specs.fields = {{0.0, 1.0, {}}, {15.0, 1.0, {}}, {25.0, 1.0, {}}};
  {
    const PlotContext ctx = make_plot_context(lens);
    const SpotData spots = compute_spots(ctx);
    REQUIRE(spots.fields.size() == 3);
    CHECK(spots.fields[2].label == "object 25.00 mm");
    CHECK(compute_layout(ctx).field_labels.back() == "object 25.00 mm");
    const std::string svg = report_svg(ctx);
    CHECK(svg.find("object 15.00 mm  (y ") != std::string::npos);
    CHECK(svg.find("field object 25.00 mm") != std::string::npos);  // the layout's legend
    // No field is labelled as an angle (the header's half field is the chief-ray angle).
    CHECK(svg.find("25.0\u00b0") == std::string::npos);
  }
  lens.specs.object_distance_mm = std::numeric_limits<double>::infinity();
  lens.specs.field_type = FieldType::kRealImageHeight;
  lens.specs.fields = {{0.0, 1.0, {}}, {1.0, 1.0, {}}, {2.0, 1.0, {}}};
  const PlotContext ctx = make_plot_context(lens);
  const FanData fans = compute_fans(ctx);
  REQUIRE(fans.fields.size() == 3);
  CHECK(fans.fields[2].label == "image 2.00 mm");
  CHECK(report_svg(ctx).find("image 2.00 mm tangential") != std::string::npos);
}

}  // namespace test_plot_fields
