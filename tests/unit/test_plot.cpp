// Plots: the layout's drawn geometry against the tracer, the charts' numbers against analyze and
// paraxial optics, and the SVG / PNG output.
#include <OpenImageIO/imageio.h>
#include <doctest/doctest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "lensopt/analysis/analyze.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/plot/canvas.h"
#include "lensopt/plot/layout.h"
#include "lensopt/plot/plot.h"
#include "lensopt/plot/psf_strip.h"
#include "lensopt/trace/kernel.h"
#include "test_support.h"

namespace test_plot {

using namespace lensopt;
using namespace lensopt::plot;

namespace {

const char* kBaselines[] = {"doublet", "cooke", "tessar"};

Lens baseline(const std::string& name) {
  return read_lens(test::source_dir() / "lenses" / (name + ".toml"));
}

// Plot contexts are the expensive part: build each baseline's once.
const PlotContext& context(const std::string& name) {
  static std::map<std::string, PlotContext> cache;
  auto it = cache.find(name);
  if (it == cache.end()) it = cache.emplace(name, make_plot_context(baseline(name))).first;
  return it->second;
}

double sag(double c, double y) {
  return c * y * y / (1.0 + std::sqrt(1.0 - c * c * y * y));
}

// z of a drawn curve at height y by the sag formula: the sphere up to the drawn semi-diameter,
// then the flat annulus up to the edge.
double drawn_z(const SurfaceDrawing& s, double y) {
  return s.vertex_z_mm + sag(s.curvature_per_mm, std::min(std::abs(y), s.drawn_semi_diameter_mm));
}

// z of a polyline (top to bottom, y non-increasing) at height y, by linear interpolation; on a
// vertical (annulus) segment, its z.
std::optional<double> polyline_z(const std::vector<Point>& pts, double y) {
  for (std::size_t i = 0; i + 1 < pts.size(); ++i) {
    const Point a = pts[i], b = pts[i + 1];
    if ((a.y >= y && y >= b.y) || (b.y >= y && y >= a.y)) {
      if (a.y == b.y) return std::min(a.x, b.x);
      return a.x + (y - a.y) / (b.y - a.y) * (b.x - a.x);
    }
  }
  return std::nullopt;
}

bool same_point(Point a, Point b) {
  return std::abs(a.x - b.x) < 1e-12 && std::abs(a.y - b.y) < 1e-12;
}

// The SVG text without its embedded base64 PNG data (whose letters may spell "nan" or "inf").
std::string without_embedded_data(const std::string& svg) {
  std::string out;
  const std::string tag = "base64,";
  std::size_t at = 0;
  for (;;) {
    const std::size_t b = svg.find(tag, at);
    if (b == std::string::npos) break;
    out.append(svg, at, b + tag.size() - at);
    at = svg.find('"', b);
    if (at == std::string::npos) return out;
  }
  out.append(svg, at, std::string::npos);
  return out;
}

// Tag balance of an XML text: every start tag closed in order, declarations and self-closing
// tags skipped, nothing outside the root. Returns "" when well formed, else what is wrong.
std::string xml_problem(const std::string& text) {
  std::vector<std::string> stack;
  std::size_t i = 0;
  int roots = 0;
  while ((i = text.find('<', i)) != std::string::npos) {
    const std::size_t end = text.find('>', i);
    if (end == std::string::npos) return "unterminated tag";
    const std::string tag = text.substr(i + 1, end - i - 1);
    i = end + 1;
    if (tag.empty()) return "empty tag";
    if (tag[0] == '?' || tag[0] == '!') continue;
    if (tag.find('<') != std::string::npos) return "'<' inside a tag";
    // Attribute quotes must pair up.
    if (std::count(tag.begin(), tag.end(), '"') % 2 != 0) return "odd quotes in <" + tag + ">";
    if (tag[0] == '/') {
      const std::string name = tag.substr(1);
      if (stack.empty() || stack.back() != name) return "unbalanced </" + name + ">";
      stack.pop_back();
      continue;
    }
    const std::string name = tag.substr(0, tag.find_first_of(" \n\t/"));
    if (stack.empty()) ++roots;
    if (tag.back() != '/') stack.push_back(name);
  }
  if (!stack.empty()) return "unclosed <" + stack.back() + ">";
  if (roots != 1) return "expected one root element";
  return "";
}

std::filesystem::path temp_dir() {
  const auto dir =
      std::filesystem::temp_directory_path() / ("lensopt_test_plot_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace

TEST_CASE("plot: layout surfaces follow their sag at their vertex positions") {
  for (const char* name : kBaselines) {
    CAPTURE(name);
    const PlotContext& ctx = context(name);
    const LayoutGeometry g = compute_layout(ctx);
    const TraceLens<double>& lens = ctx.sys.lens;
    REQUIRE(static_cast<int>(g.surfaces.size()) == lens.surface_count());
    double z = 0;
    for (int k = 0; k < lens.surface_count(); ++k) {
      const SurfaceDrawing& s = g.surfaces[k];
      CHECK(s.vertex_z_mm == doctest::Approx(z).epsilon(1e-12));
      CHECK(s.curvature_per_mm == lens.curvature_per_mm[k]);
      CHECK(s.drawn_semi_diameter_mm > 0);
      CHECK(s.edge_semi_diameter_mm >= s.drawn_semi_diameter_mm);
      REQUIRE(s.profile.size() >= 3);
      CHECK(s.profile.front().y == doctest::Approx(s.drawn_semi_diameter_mm));
      CHECK(s.profile.back().y == doctest::Approx(-s.drawn_semi_diameter_mm));
      for (const Point& p : s.profile)
        CHECK(p.x == doctest::Approx(z + sag(s.curvature_per_mm, p.y)).epsilon(1e-12));
      // The drawn curve is the profile plus, where the element is wider, a flat annulus.
      for (const Point& p : s.curve) {
        CHECK(std::abs(p.y) <= s.edge_semi_diameter_mm + 1e-12);
        CHECK(p.x == doctest::Approx(drawn_z(s, p.y)).epsilon(1e-12));
      }
      z += lens.thickness_mm[k];
    }
    CHECK(g.image_z_mm == doctest::Approx(z).epsilon(1e-12));
    CHECK(g.warnings.empty());
  }
}

TEST_CASE("plot: layout clear apertures hold the rays and consecutive surfaces never cross") {
  for (const char* name : kBaselines) {
    CAPTURE(name);
    const PlotContext& ctx = context(name);
    const LayoutGeometry g = compute_layout(ctx);
    const int k_count = static_cast<int>(g.surfaces.size());
    // Every drawn ray meets every surface inside its drawn aperture, on the surface.
    for (const RayDrawing& r : g.rays) {
      REQUIRE(r.complete);
      REQUIRE(static_cast<int>(r.points.size()) == k_count + 2);
      for (int k = 0; k < k_count; ++k) {
        const SurfaceDrawing& s = g.surfaces[k];
        const Point p = r.points[1 + k];
        if (s.is_stop) {
          CHECK(std::abs(p.y) <= g.stop_clear_mm);
        } else {
          CHECK(std::abs(p.y) <= s.clear_semi_diameter_mm);
        }
        CHECK(p.x == doctest::Approx(s.vertex_z_mm + sag(s.curvature_per_mm, p.y)).epsilon(1e-9));
      }
    }
    // Surfaces k and k+1 (the stop as its plane) never cross where both are drawn: exactly by
    // the sag formula, and as drawn polylines (chords of the sampled profiles).
    int checked = 0;
    for (int k = 0; k + 1 < k_count; ++k) {
      const SurfaceDrawing& a = g.surfaces[k];
      const SurfaceDrawing& b = g.surfaces[k + 1];
      const double reach = std::min(a.edge_semi_diameter_mm, b.edge_semi_diameter_mm);
      for (int i = 0; i <= 500; ++i) {
        const double y = reach * i / 500.0;
        CHECK(drawn_z(b, y) - drawn_z(a, y) >= -1e-9);
        const auto za = polyline_z(a.curve, y), zb = polyline_z(b.curve, y);
        REQUIRE(za.has_value());
        REQUIRE(zb.has_value());
        CHECK(*zb - *za >= -1e-3);
        ++checked;
      }
      CHECK(g.min_gap_mm[k] >= -1e-9);
    }
    CHECK(checked == 501 * (k_count - 1));
  }
}

TEST_CASE("plot: layout element edges meet and close each element") {
  for (const char* name : kBaselines) {
    CAPTURE(name);
    const PlotContext& ctx = context(name);
    const LayoutGeometry g = compute_layout(ctx);
    CHECK(static_cast<int>(g.elements.size()) ==
          std::count(ctx.sys.lens.is_glass.begin(), ctx.sys.lens.is_glass.end(), 1));
    for (const ElementDrawing& e : g.elements) {
      CAPTURE(e.front_surface);
      const SurfaceDrawing& front = g.surfaces[e.front_surface];
      const SurfaceDrawing& back = g.surfaces[e.back_surface];
      CHECK(e.back_surface == e.front_surface + 1);
      CHECK(front.in_element);
      CHECK(back.in_element);
      // Rims join the ends of the front and back curves, flat at +-E.
      CHECK(same_point(e.upper_rim[0], front.curve.front()));
      CHECK(same_point(e.upper_rim[1], back.curve.front()));
      CHECK(same_point(e.lower_rim[0], front.curve.back()));
      CHECK(same_point(e.lower_rim[1], back.curve.back()));
      CHECK(e.upper_rim[0].y == doctest::Approx(e.edge_semi_diameter_mm));
      CHECK(e.upper_rim[1].y == doctest::Approx(e.edge_semi_diameter_mm));
      CHECK(e.lower_rim[0].y == doctest::Approx(-e.edge_semi_diameter_mm));
      CHECK(e.lower_rim[1].y == doctest::Approx(-e.edge_semi_diameter_mm));
      // Edge thickness >= 0; E covers both clear apertures.
      CHECK(e.upper_rim[1].x >= e.upper_rim[0].x);
      CHECK(e.edge_semi_diameter_mm >= front.clear_semi_diameter_mm);
      CHECK(e.edge_semi_diameter_mm >= back.clear_semi_diameter_mm);
      // The outline runs front top -> front bottom -> back bottom -> back top; the closing
      // segment is the upper rim.
      REQUIRE(e.outline.size() == front.curve.size() + back.curve.size());
      CHECK(same_point(e.outline.front(), e.upper_rim[0]));
      CHECK(same_point(e.outline.back(), e.upper_rim[1]));
      CHECK(same_point(e.outline[front.curve.size() - 1], e.lower_rim[0]));
      CHECK(same_point(e.outline[front.curve.size()], e.lower_rim[1]));
    }
  }
}

TEST_CASE("plot: layout rays end on the image plane at the traced heights; the stop at its z") {
  for (const char* name : kBaselines) {
    CAPTURE(name);
    const PlotContext& ctx = context(name);
    const LayoutOptions options;
    const LayoutGeometry g = compute_layout(ctx, options);
    const TraceSystem<double>& sys = ctx.sys;
    REQUIRE(g.field_deg.size() == 3);
    CHECK(g.field_deg[0] == 0.0);
    CHECK(g.field_deg[1] == doctest::Approx(0.7 * ctx.lens.specs.half_field_deg));
    CHECK(g.field_deg[2] == doctest::Approx(ctx.lens.specs.half_field_deg));
    REQUIRE(g.rays.size() == 3u * options.rays_per_field);
    const int ref = sys.wavelength_count;
    for (const RayDrawing& r : g.rays) {
      // Trace the same ray independently: aimed pupil point of its field at 587.6 nm.
      const int h = static_cast<int>(
          std::lround(g.field_deg[r.field] / sys.fields_deg.back() * (sys.fields_deg.size() - 1)));
      REQUIRE(sys.fields_deg[h] == doctest::Approx(g.field_deg[r.field]));
      const PupilMap<double>& map = sys.pupil_map(h, ref);
      const double theta = sys.fields_deg[h] * kPi / 180.0;
      RayBundle<double> ray;
      ray.resize(1);
      ray.x[0] = 0;
      ray.y[0] = sys.epd_mm / 2 * (map.offset_y + map.scale_y * r.pupil_y);
      ray.z[0] = sys.entrance_pupil_z_mm;
      ray.l[0] = 0;
      ray.m[0] = std::sin(theta);
      ray.n[0] = std::cos(theta);
      trace_bundle(sys.lens, ref, sys.lens.surface_count(), true, ray,
                   static_cast<RayRecord<double>*>(nullptr));
      REQUIRE(ray.status[0] == kRayOk);
      CHECK(r.points.back().x == doctest::Approx(g.image_z_mm).epsilon(1e-12));
      CHECK(r.points.back().y == doctest::Approx(ray.y[0]).epsilon(1e-12));
      CHECK(std::abs(r.points.back().y) <= g.image_half_height_mm);
      // Rays start left of the first surface and run forward.
      CHECK(r.points.front().x == g.start_z_mm);
      for (std::size_t i = 0; i + 1 < r.points.size(); ++i)
        CHECK(r.points[i + 1].x >= r.points[i].x - 1e-9);
    }
    // The stop: at the stop surface's vertex, from the real stop radius outward; the on-axis
    // marginal rays pass exactly at its edge.
    double z_stop = 0;
    for (int k = 0; k < sys.lens.stop; ++k) z_stop += sys.lens.thickness_mm[k];
    CHECK(g.stop_surface == ctx.lens.stop_index());
    CHECK(g.stop_z_mm == doctest::Approx(z_stop).epsilon(1e-12));
    CHECK(g.stop_radius_mm == doctest::Approx(sys.stop_radius_mm).epsilon(1e-12));
    CHECK(g.stop_clear_mm >= g.stop_radius_mm);
    CHECK(g.stop_clear_mm < 1.05 * g.stop_radius_mm);  // the aiming residual is small
    CHECK(g.stop_outer_mm > g.stop_clear_mm);
    const RayDrawing& top = g.rays[options.rays_per_field - 1];  // field 0, pupil +1
    CHECK(top.pupil_y == 1.0);
    CHECK(top.points[1 + sys.lens.stop].x == doctest::Approx(z_stop).epsilon(1e-12));
    CHECK(top.points[1 + sys.lens.stop].y == doctest::Approx(sys.stop_radius_mm).epsilon(1e-9));
  }
}

TEST_CASE("plot: spot diagram RMS values are analyze's, the drawn points agree") {
  const Lens lens = baseline("tessar");
  const AnalysisReport report = analyze_lens(lens, AnalyzeOptions{});
  const SpotData spots = compute_spots(context("tessar"));
  REQUIRE(spots.fields.size() == 5);
  CHECK(spots.mean_rms_um == doctest::Approx(*report.mean_rms_spot_um).epsilon(1e-12));
  const int expected_fields[] = {0, 5, 10, 15, 20};
  for (std::size_t j = 0; j < spots.fields.size(); ++j) {
    const SpotField& f = spots.fields[j];
    CAPTURE(f.field_deg);
    CHECK(f.field == expected_fields[j]);
    CHECK(f.rms_um == doctest::Approx(*report.fields[f.field].rms_spot_um).epsilon(1e-12));
    CHECK(f.centroid_y_mm == doctest::Approx(report.fields[f.field].centroid_y_mm).epsilon(1e-12));
    // The drawn points (12 rings, mirrored) about the full-sampling centroid: x symmetric, their
    // RMS radius within 15% of the full sampling's.
    double sx = 0, sy = 0, s2 = 0;
    for (std::size_t i = 0; i < f.x_um.size(); ++i) {
      sx += f.x_um[i];
      sy += f.y_um[i];
      s2 += f.x_um[i] * f.x_um[i] + f.y_um[i] * f.y_um[i];
    }
    const double n = static_cast<double>(f.x_um.size());
    CHECK(n == 2.0 * 144 * spots.wavelengths_nm.size());
    CHECK(std::abs(sx / n) < 1e-9);
    CHECK(std::abs(sy / n) < 0.1 * f.rms_um);
    CHECK(std::sqrt(s2 / n) == doctest::Approx(f.rms_um).epsilon(0.15));
  }
}

TEST_CASE("plot: fans and field curves agree with symmetry and paraxial optics") {
  const PlotContext& ctx = context("tessar");
  const FanData fans = compute_fans(ctx);
  REQUIRE(!fans.fields.empty());
  // On axis the sagittal fan is the tangential one (rotational symmetry).
  const FanField& axis = fans.fields[0];
  REQUIRE(axis.tangential.size() == 3);
  for (std::size_t c = 0; c < axis.tangential.size(); ++c)
    for (std::size_t i = 0; i < axis.tangential[c].pupil.size(); ++i)
      CHECK(axis.sagittal[c].error_um[i] ==
            doctest::Approx(axis.tangential[c].error_um[i]).epsilon(1e-9).scale(1.0));
  // The chief ray of the reference wavelength has no error; off axis the pupil centre of the
  // channel wavelengths shows lateral colour only.
  for (const FanField& f : fans.fields)
    for (const FanCurve& c : f.sagittal) CHECK(std::abs(c.error_um[c.pupil.size() / 2]) < 1e-9);

  const FieldCurveData field = compute_field_curves(ctx);
  REQUIRE(field.focus.size() == 3);
  for (const FocusCurve& c : field.focus) {
    CAPTURE(c.wavelength_nm);
    // On axis tangential and sagittal foci coincide, at the paraxial image of that wavelength.
    CHECK(c.valid[0]);
    CHECK(c.tangential_mm[0] == doctest::Approx(c.sagittal_mm[0]).epsilon(1e-6).scale(1.0));
    const ParaxialData<double> par = paraxial_data(ctx.sys.lens, c.wavelength_nm);
    const double shift = par.bfl_mm - ctx.sys.lens.thickness_mm.back();
    CHECK(c.sagittal_mm[0] == doctest::Approx(shift).epsilon(1e-4).scale(1.0));
  }
  REQUIRE(field.distortion_percent.size() == ctx.report.fields.size());
  for (std::size_t h = 0; h < field.distortion_percent.size(); ++h)
    CHECK(field.distortion_percent[h] == ctx.report.fields[h].distortion_percent);
}

TEST_CASE("plot: PSF strip tiles come from the render module's PSFs") {
  const PlotContext& ctx = context("tessar");
  const PsfStrip strip = compute_psf_strip(ctx);
  REQUIRE(strip.tiles.size() == 5);
  for (const PsfTile& t : strip.tiles) {
    CHECK(t.image.width == strip.grid_size);
    CHECK(t.image.height == strip.grid_size);
    float peak = 0;
    for (float v : t.image.pixels) peak = std::max(peak, v);
    CHECK(peak == doctest::Approx(1.0f));
    CHECK(t.peak > 0);
  }
  // A sharp axial PSF: the brightest pixel sits in the central bin.
  const PsfTile& axis = strip.tiles[0];
  const int c = strip.grid_size / 2;
  const float* centre = axis.image.at(c, c);
  CHECK(std::max({centre[0], centre[1], centre[2]}) > 0.9f);
}

TEST_CASE("plot: every kind draws well-formed SVG") {
  const PlotContext& ctx = context("doublet");
  const PlotContext& other = context("tessar");
  for (const std::string& kind : plot_kind_names()) {
    for (bool compare : {false, true}) {
      CAPTURE(kind);
      CAPTURE(compare);
      PlotOptions options;
      options.kind = parse_plot_kind(kind);
      PlotSummary summary;
      const auto canvas = draw_plot(
          ctx, compare ? &other : nullptr, options,
          [](double w, double h) { return std::make_unique<SvgCanvas>(w, h); }, &summary);
      const std::string svg = dynamic_cast<SvgCanvas&>(*canvas).str();
      CHECK(xml_problem(svg) == "");
      CHECK(svg.find("<svg") != std::string::npos);
      const std::string text = without_embedded_data(svg);
      CHECK(text.find("nan") == std::string::npos);
      CHECK(text.find("inf\"") == std::string::npos);
      CHECK(summary.width_px > 0);
      CHECK(summary.height_px > 0);
      CHECK(summary.warnings.empty());
      if (kind == "spot" || kind == "report") CHECK(summary.spot_box_um > 0);
    }
  }
  CHECK(xml_problem("<svg><g></svg>") != "");
  CHECK(xml_problem("<svg><line/></svg>") == "");
}

TEST_CASE("plot: PNG output is written and readable with the expected size") {
  const auto dir = temp_dir();
  PlotOptions options;
  options.kind = PlotKind::kLayout;
  const auto path = dir / "layout.png";
  const PlotSummary summary = write_plot(baseline("cooke"), nullptr, options, path);
  CHECK(summary.format == OutputFormat::kPng);
  auto in = OIIO::ImageInput::open(path.string());
  REQUIRE(in);
  const OIIO::ImageSpec& spec = in->spec();
  CHECK(spec.width == static_cast<int>(std::lround(summary.width_px)));
  CHECK(spec.height == static_cast<int>(std::lround(summary.height_px)));
  CHECK(spec.nchannels == 3);
  std::vector<float> pixels(static_cast<std::size_t>(spec.width) * spec.height * 3);
  REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, pixels.data()));
  in->close();
  std::size_t dark = 0;
  for (std::size_t i = 0; i < pixels.size(); i += 3)
    if (pixels[i] + pixels[i + 1] + pixels[i + 2] < 1.5) ++dark;
  CHECK(dark > 1000);                   // something is drawn
  CHECK(dark < pixels.size() / 3 / 2);  // on a white page
  std::filesystem::remove_all(dir);
}

TEST_CASE("plot: raster canvas puts shapes and text where the SVG would") {
  RasterCanvas canvas(100, 80, 2);
  canvas.rect({10, 10}, 20, 10, Style{"none", 1.0, "#ff0000"});
  TextStyle vertical{14, Anchor::kMiddle, "#0000ff"};
  vertical.vertical = true;
  canvas.text({70, 40}, "label", vertical);
  const RgbImage img = canvas.final_image();
  REQUIRE(img.width == 100);
  REQUIRE(img.height == 80);
  const float* inside = img.at(20, 15);
  CHECK(inside[0] == doctest::Approx(1.0f));
  CHECK(inside[1] == doctest::Approx(0.0f));
  const float* outside = img.at(5, 5);
  CHECK(outside[1] == doctest::Approx(1.0f));
  // The vertical text's ink: left of its baseline x = 70, centred on y = 40.
  int x_lo = 100, x_hi = -1, y_lo = 80, y_hi = -1;
  for (int y = 0; y < 80; ++y)
    for (int x = 40; x < 100; ++x) {
      const float* p = img.at(x, y);
      if (p[2] > 0.5f && p[0] < 0.5f) {
        x_lo = std::min(x_lo, x);
        x_hi = std::max(x_hi, x);
        y_lo = std::min(y_lo, y);
        y_hi = std::max(y_hi, y);
      }
    }
  REQUIRE(x_hi >= 0);
  CHECK(x_hi <= 72);
  CHECK(x_lo >= 70 - 16);
  CHECK(std::abs(0.5 * (y_lo + y_hi) - 40) <= 3);
  CHECK(y_hi - y_lo > 20);  // runs along y
}

TEST_CASE("plot: bad kinds and extensions are clear errors") {
  CHECK_THROWS_WITH_AS(parse_plot_kind("spots"),
                       doctest::Contains("layout, spot, fan, field, psf, report"), Error);
  CHECK_THROWS_AS(output_format_for("out.jpg"), Error);
  CHECK(output_format_for("a/b.SVG") == OutputFormat::kSvg);
  CHECK(output_format_for("b.png") == OutputFormat::kPng);
  PlotOptions bad;
  bad.spot_box_um = -1;
  CHECK_THROWS_AS(bad.validate(), Error);
}

TEST_CASE("plot: a lens whose rays fail is drawn with warnings and without NaN") {
  Lens lens = baseline("tessar");
  lens.specs.half_field_deg = 42;  // far beyond the design: rays miss, aiming breaks down
  const PlotContext ctx = make_plot_context(lens);
  const LayoutGeometry g = compute_layout(ctx);
  CHECK(!g.warnings.empty());
  for (const RayDrawing& r : g.rays)
    for (const Point& p : r.points) CHECK((std::isfinite(p.x) && std::isfinite(p.y)));
  PlotOptions options;
  options.kind = PlotKind::kReport;
  PlotSummary summary;
  const auto canvas = draw_plot(
      ctx, nullptr, options, [](double w, double h) { return std::make_unique<SvgCanvas>(w, h); },
      &summary);
  const std::string svg = dynamic_cast<SvgCanvas&>(*canvas).str();
  CHECK(xml_problem(svg) == "");
  const std::string text = without_embedded_data(svg);
  CHECK(text.find("nan") == std::string::npos);
  CHECK(text.find("inf") == std::string::npos);
  CHECK(!summary.warnings.empty());
}

TEST_CASE("plot: canvases leave out non-finite points and clip lines") {
  SvgCanvas canvas(100, 100);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  canvas.polyline({{10, 10}, {20, 20}, {nan, 5}, {30, 30}, {40, 40}}, Style{});
  canvas.line({50, 50}, {1e30, 50}, Style{});
  canvas.dots({{nan, nan}, {5, 5}}, 1.0, "#000000");
  canvas.text({nan, 1}, "x", TextStyle{});
  const std::string svg = canvas.str();
  CHECK(svg.find("nan") == std::string::npos);
  CHECK(svg.find("e+") == std::string::npos);
  // Two runs survive the NaN; the long line is clipped to the page's margin (x <= 200).
  std::size_t lines = 0;
  for (std::size_t i = 0; (i = svg.find("<line", i)) != std::string::npos; ++i) ++lines;
  CHECK(lines == 3);
  CHECK(svg.find("x2=\"200.00\"") != std::string::npos);
  canvas.set_clip(0, 0, 60, 100);
  canvas.line({0, 70}, {100, 70}, Style{});
  CHECK(canvas.str().find("x2=\"60.00\"") != std::string::npos);
}

}  // namespace test_plot
