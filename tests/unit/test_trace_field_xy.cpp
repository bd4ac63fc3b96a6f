// Fields off the y axis (issue 32): a field (x, y) is traced in its own frame, the lens frame
// turned about z so that the field lies on +y. A rotationally symmetric lens traces it as the
// field on +y (the same spot and distortion, the image turned back); a lens with 3D placements
// turns its rays into the lens frame and back in the kernel (RayBundle::frame_cos), which the
// checks below pin down with systems related by a quarter turn; TOML and .zmx carry x and y.
#include <doctest/doctest.h>

#include <cmath>
#include <string>

#include "lensopt/analysis/analyze.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/plot/plot_data.h"
#include "test_support.h"

namespace test_trace_field_xy {

using namespace lensopt;
using namespace lensopt::plot;

namespace {

Lens cooke_as_written() {
  Lens lens = read_lens(test::source_dir() / "lenses/zmx/cooke_triplet_50.zmx");
  REQUIRE(lens.specs.mode == SpecMode::kAsWritten);
  return lens;
}

FieldPoint field_at(double x, double y) {
  FieldPoint f;
  f.x = x;
  f.value = y;
  return f;
}

AnalysisReport analyze_fields(Lens lens, std::vector<FieldPoint> fields) {
  lens.specs.fields = std::move(fields);
  AnalyzeOptions options;
  options.trace.rings = 12;
  return analyze_lens(lens, options);
}

double rel(double a, double b) {
  return std::abs(a - b) / std::max(1e-300, std::abs(b));
}

}  // namespace

TEST_CASE("field xy: a rotationally symmetric lens images an x field as the y field, turned") {
  const Lens lens = cooke_as_written();
  const AnalysisReport y = analyze_fields(lens, {field_at(0.0, 14.0)});
  const AnalysisReport x = analyze_fields(lens, {field_at(14.0, 0.0)});
  // (-9, 12): 15 deg off axis exactly, at an azimuth of -36.87 deg.
  const AnalysisReport d = analyze_fields(lens, {field_at(-9.0, 12.0)});
  const AnalysisReport y15 = analyze_fields(lens, {field_at(0.0, 15.0)});
  REQUIRE(y.fields.size() == 1);
  REQUIRE(x.fields.size() == 1);
  // Traced in the field's frame: the same rays, the same bits.
  CHECK(*x.fields[0].rms_spot_um == *y.fields[0].rms_spot_um);
  CHECK(x.fields[0].distortion_percent == y.fields[0].distortion_percent);
  CHECK(*d.fields[0].rms_spot_um == *y15.fields[0].rms_spot_um);
  CHECK(d.fields[0].distortion_percent == y15.fields[0].distortion_percent);
  CHECK(y.fields[0].azimuth_deg == 0.0);
  CHECK(x.fields[0].azimuth_deg == doctest::Approx(90.0).epsilon(1e-15));
  // The image turned back: on +x for the x field, along (-0.6, 0.8) for the other.
  const double c = y.fields[0].image_centroid_y_mm;
  CHECK(c > 1.0);
  CHECK(y.fields[0].image_centroid_x_mm == 0.0);
  CHECK(std::abs(x.fields[0].image_centroid_x_mm - c) < 1e-12 * c);
  CHECK(std::abs(x.fields[0].image_centroid_y_mm) < 1e-12 * c);
  const double c15 = y15.fields[0].image_centroid_y_mm;
  CHECK(std::abs(d.fields[0].image_centroid_x_mm + 0.6 * c15) < 1e-12 * c15);
  CHECK(std::abs(d.fields[0].image_centroid_y_mm - 0.8 * c15) < 1e-12 * c15);
  CHECK(x.fields[0].field_x == doctest::Approx(14.0).epsilon(1e-15));
  CHECK(std::abs(x.fields[0].field_y) < 1e-14);
  // The JSON report carries both coordinates only when a field is off the y axis.
  CHECK(format_report_json(x).find("\"image_centroid_x_mm\"") != std::string::npos);
  CHECK(format_report_json(x).find("\"field_x\"") != std::string::npos);
  CHECK(format_report_json(y).find("\"field_x\"") == std::string::npos);
}

TEST_CASE("field xy: the spot diagram of an x field is the y field's, turned, labelled by x, y") {
  Lens lens = cooke_as_written();
  lens.specs.fields = {field_at(0.0, 14.0)};
  TraceOptions trace;
  trace.rings = 12;
  const SpotData y = compute_spots(make_plot_context(lens, trace));
  lens.specs.fields = {field_at(14.0, 0.0)};
  const SpotData x = compute_spots(make_plot_context(lens, trace));
  REQUIRE(y.fields.size() == 1);
  REQUIRE(x.fields.size() == 1);
  REQUIRE(x.fields[0].x_um.size() == y.fields[0].x_um.size());
  REQUIRE(!x.fields[0].x_um.empty());
  // A quarter turn: (u, v) -> (v, -u).
  for (std::size_t i = 0; i < x.fields[0].x_um.size(); ++i) {
    CHECK(std::abs(x.fields[0].x_um[i] - y.fields[0].y_um[i]) < 1e-9);
    CHECK(std::abs(x.fields[0].y_um[i] + y.fields[0].x_um[i]) < 1e-9);
  }
  CHECK(std::abs(x.fields[0].centroid_x_mm - y.fields[0].centroid_y_mm) < 1e-12);
  CHECK(x.fields[0].label == "(14.0\u00b0, 0.0\u00b0)");
  CHECK(y.fields[0].label == "14.0\u00b0");
}

TEST_CASE("field xy: the kernel's field frame on a lens with placements") {
  // A spin of a rotationally symmetric surface about its own axis changes nothing physically but
  // makes the lens 'placed' (the general kernel path, full pupil): a field on x then goes through
  // the kernel's turn into the lens frame and back, and must image as the y field of the centred
  // lens, turned.
  const Lens lens = cooke_as_written();
  const int stop = lens.stop_index();
  Lens spun = lens;
  spun.surfaces[stop + 1].placement.tilt_z_deg = 37.0;
  spun.surfaces[stop + 1].restore_frame = true;
  REQUIRE(spun.breaks_symmetry());
  const AnalysisReport ref = analyze_fields(lens, {field_at(0.0, 14.0)});
  const AnalysisReport x = analyze_fields(spun, {field_at(14.0, 0.0)});
  REQUIRE(x.full_pupil);
  CHECK(rel(*x.fields[0].rms_spot_um, *ref.fields[0].rms_spot_um) < 1e-9);
  const double c = ref.fields[0].image_centroid_y_mm;
  CHECK(std::abs(x.fields[0].image_centroid_x_mm - c) < 1e-10 * c);
  CHECK(std::abs(x.fields[0].image_centroid_y_mm) < 1e-10 * c);
  CHECK(std::abs(x.fields[0].distortion_percent - ref.fields[0].distortion_percent) < 1e-9);

  // A real decenter: the last element decentred along x and a field on +x is the quarter turn of
  // the element decentred along y and the field on +y (field frame (u, v) -> lens (v, -u)).
  Lens ax = lens, by = lens;
  ax.surfaces[stop + 1].placement.decenter_x_mm = 0.05;
  by.surfaces[stop + 1].placement.decenter_y_mm = 0.05;
  const AnalysisReport a = analyze_fields(ax, {field_at(14.0, 0.0)});
  const AnalysisReport b = analyze_fields(by, {field_at(0.0, 14.0)});
  // ... and differs from the same decenter seen by a field on +y (a true 3D effect).
  const AnalysisReport a_on_y = analyze_fields(ax, {field_at(0.0, 14.0)});
  CHECK(rel(*a.fields[0].rms_spot_um, *b.fields[0].rms_spot_um) < 1e-9);
  CHECK(std::abs(a.fields[0].centroid_x_mm - b.fields[0].centroid_x_mm) < 1e-10);
  CHECK(std::abs(a.fields[0].centroid_y_mm - b.fields[0].centroid_y_mm) < 1e-10);
  CHECK(std::abs(a.fields[0].image_centroid_x_mm - b.fields[0].centroid_y_mm) < 1e-10);
  CHECK(std::abs(a.fields[0].image_centroid_y_mm + b.fields[0].centroid_x_mm) < 1e-10);
  CHECK(std::abs(b.fields[0].centroid_x_mm) < 1e-12);      // decenter in the field's meridian
  CHECK(std::abs(a_on_y.fields[0].centroid_x_mm) > 1e-4);  // decenter across it
}

TEST_CASE("field xy: TOML fields_x and .zmx XFLN round trip, vignetting factors turned back") {
  Lens lens = cooke_as_written();
  FieldPoint off = field_at(3.0, 4.0);
  off.vignetting.vdx = 0.1;
  off.vignetting.vdy = -0.05;
  off.vignetting.vcy = 0.2;
  off.vignetting.van_deg = 5.0;
  FieldPoint on_x = field_at(-7.0, 0.0);
  on_x.vignetting.vcx = 0.3;
  on_x.vignetting.vdx = 0.02;
  lens.specs.fields = {field_at(0.0, 0.0), off, on_x};
  const Lens toml = parse_lens_toml(format_lens_toml(lens), "xy.toml");
  REQUIRE(toml.specs.fields.size() == 3);
  for (std::size_t i = 0; i < 3; ++i) {
    CHECK(toml.specs.fields[i].x == lens.specs.fields[i].x);
    CHECK(toml.specs.fields[i].value == lens.specs.fields[i].value);
    CHECK(toml.specs.fields[i].vignetting.vdx == lens.specs.fields[i].vignetting.vdx);
    CHECK(toml.specs.fields[i].vignetting.van_deg == lens.specs.fields[i].vignetting.van_deg);
  }
  const std::string zmx = format_zmx(lens);
  CHECK(zmx.find("XFLN 0 3 -7") != std::string::npos);
  CHECK(zmx.find("YFLN 0 4 0") != std::string::npos);
  const Lens back = parse_zmx(zmx, "xy.zmx").lens;
  REQUIRE(back.specs.fields.size() == 3);
  for (std::size_t i = 0; i < 3; ++i) {
    const FieldPoint& f = back.specs.fields[i];
    const FieldPoint& g = lens.specs.fields[i];
    CAPTURE(i);
    CHECK(f.x == g.x);
    CHECK(f.value == g.value);
    CHECK(std::abs(f.vignetting.vdx - g.vignetting.vdx) < 1e-14);
    CHECK(std::abs(f.vignetting.vdy - g.vignetting.vdy) < 1e-14);
    CHECK(f.vignetting.vcx == g.vignetting.vcx);
    CHECK(f.vignetting.vcy == g.vignetting.vcy);
    CHECK(std::abs(f.vignetting.van_deg - g.vignetting.van_deg) < 1e-12);
  }
  // A field off the axis beyond 89 deg is refused, naming the key.
  const std::string text = format_lens_toml(lens);
  const std::size_t key = text.find("fields_x");
  REQUIRE(key != std::string::npos);
  const std::size_t at = text.find("[0.0, 3.0, -7.0]", key);
  REQUIRE(at != std::string::npos);
  std::string bad = text;
  bad.replace(at, 4, "[89.0");
  CHECK_THROWS_WITH_AS(parse_lens_toml(bad, "bad.toml"), doctest::Contains("below 89"), Error);
}

}  // namespace test_trace_field_xy
