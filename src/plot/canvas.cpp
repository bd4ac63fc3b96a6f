// The SVG canvas backend and helpers shared by both backends.
#include "lensopt/plot/canvas.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>

#include "core/png_io.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"

namespace lensopt::plot {

double text_width_px(const std::string& text, double size_px) {
  // DejaVu Sans advances: digits and most lower case about 0.6 em, narrow letters less.
  double em = 0;
  for (unsigned char c : text) {
    if ((c & 0xC0) == 0x80) continue;  // UTF-8 continuation byte
    if (c == ' ' || c == '.' || c == ',' || c == ':' || c == 'i' || c == 'l' || c == 'j' ||
        c == '|' || c == '(' || c == ')' || c == '\'' || c == 't' || c == 'f' || c == 'r')
      em += 0.36;
    else if (std::isupper(c) || c == 'm' || c == 'w')
      em += 0.75;
    else
      em += 0.62;
  }
  return em * size_px;
}

bool parse_colour(const std::string& css, float rgb[3]) {
  if (css.size() != 7 || css[0] != '#') return false;
  for (int c = 0; c < 3; ++c) {
    unsigned v = 0;
    for (int k = 0; k < 2; ++k) {
      const char h =
          static_cast<char>(std::tolower(static_cast<unsigned char>(css[1 + 2 * c + k])));
      v <<= 4;
      if (h >= '0' && h <= '9')
        v |= static_cast<unsigned>(h - '0');
      else if (h >= 'a' && h <= 'f')
        v |= static_cast<unsigned>(h - 'a' + 10);
      else
        return false;
    }
    rgb[c] = static_cast<float>(v) / 255.f;
  }
  return true;
}

OutputFormat output_format_for(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".svg") return OutputFormat::kSvg;
  if (ext == ".png") return OutputFormat::kPng;
  throw Error(SourceLocation{path.string(), 0, 0},
              fmt::format("cannot tell the plot format from the extension '{}': use .svg or .png",
                          ext.empty() ? std::string("(none)") : ext));
}

std::unique_ptr<Canvas> make_canvas(const std::filesystem::path& path, double width,
                                    double height) {
  if (output_format_for(path) == OutputFormat::kSvg)
    return std::make_unique<SvgCanvas>(width, height);
  return std::make_unique<RasterCanvas>(width, height);
}

std::string encode_png(const RgbImage& image) {
  std::vector<unsigned char> bytes;
  std::string error;
  if (!encode_png_bytes(image.width, image.height, 3, 8, image.pixels.data(), bytes, error))
    throw Error(fmt::format("cannot encode a PNG in memory: {}", error));
  return std::string(bytes.begin(), bytes.end());
}

// ---- input checks shared by the backends --------------------------------------------------------

namespace {

bool finite(Point p) {
  return std::isfinite(p.x) && std::isfinite(p.y);
}

// Liang-Barsky: clips segment a-b to the box; false if nothing is left. t0/t1 are the kept
// parameter range.
bool clip_segment(Point a, Point b, double x0, double y0, double x1, double y1, double& t0,
                  double& t1) {
  t0 = 0;
  t1 = 1;
  const double dx = b.x - a.x, dy = b.y - a.y;
  const double p[4] = {-dx, dx, -dy, dy};
  const double q[4] = {a.x - x0, x1 - a.x, a.y - y0, y1 - a.y};
  for (int i = 0; i < 4; ++i) {
    if (p[i] == 0) {
      if (q[i] < 0) return false;
      continue;
    }
    const double t = q[i] / p[i];
    if (p[i] < 0)
      t0 = std::max(t0, t);
    else
      t1 = std::min(t1, t);
    if (t0 > t1) return false;
  }
  return true;
}

}  // namespace

bool Canvas::near_page(Point p) const {
  return finite(p) && p.x > -width_ && p.x < 2 * width_ && p.y > -height_ && p.y < 2 * height_;
}

void Canvas::line(Point a, Point b, const Style& style) {
  polyline({a, b}, style);
}

void Canvas::set_clip(double x, double y, double width, double height) {
  clip_ = true;
  clip_x0_ = x;
  clip_y0_ = y;
  clip_x1_ = x + width;
  clip_y1_ = y + height;
}

void Canvas::clear_clip() {
  clip_ = false;
}

void Canvas::polyline(const std::vector<Point>& points, const Style& style) {
  // Clip every segment to the page and a margin of one page; split where a segment leaves it
  // or a point is not finite.
  double x0 = -width_, y0 = -height_, x1 = 2 * width_, y1 = 2 * height_;
  if (clip_) {
    x0 = std::max(x0, clip_x0_);
    y0 = std::max(y0, clip_y0_);
    x1 = std::min(x1, clip_x1_);
    y1 = std::min(y1, clip_y1_);
  }
  std::vector<Point> run;
  auto flush = [&] {
    if (run.size() >= 2) draw_polyline(run, style);
    run.clear();
  };
  for (std::size_t i = 0; i + 1 < points.size(); ++i) {
    const Point a = points[i], b = points[i + 1];
    double t0, t1;
    if (!finite(a) || !finite(b) || !clip_segment(a, b, x0, y0, x1, y1, t0, t1)) {
      flush();
      continue;
    }
    const Point pa{a.x + t0 * (b.x - a.x), a.y + t0 * (b.y - a.y)};
    const Point pb{a.x + t1 * (b.x - a.x), a.y + t1 * (b.y - a.y)};
    if (t0 > 0) flush();
    if (run.empty()) run.push_back(pa);
    run.push_back(pb);
    if (t1 < 1) flush();
  }
  flush();
}

void Canvas::polygon(const std::vector<Point>& points, const Style& style) {
  if (points.size() < 3) return;
  for (const Point& p : points)
    if (!near_page(p)) return;  // element outlines and boxes: all on the page or none
  draw_polygon(points, style);
}

void Canvas::circle(Point centre, double radius, const Style& style) {
  if (!near_page(centre) || !(radius >= 0) || radius > width_ + height_) return;
  draw_circle(centre, radius, style);
}

void Canvas::rect(Point corner, double width, double height, const Style& style) {
  if (!near_page(corner) || !near_page({corner.x + width, corner.y + height})) return;
  draw_rect(corner, width, height, style);
}

void Canvas::dots(const std::vector<Point>& centres, double radius, const std::string& colour,
                  double opacity) {
  if (!(radius > 0) || radius > 100) return;
  std::vector<Point> kept;
  kept.reserve(centres.size());
  for (const Point& p : centres)
    if (near_page(p)) kept.push_back(p);
  if (!kept.empty()) draw_dots(kept, radius, colour, opacity);
}

void Canvas::text(Point at, const std::string& content, const TextStyle& style) {
  if (!near_page(at) || !(style.size_px > 0) || style.size_px > 500) return;
  draw_text(at, content, style);
}

void Canvas::image(Point corner, double width, double height, const RgbImage& image,
                   bool pixelated) {
  if (!near_page(corner) || !near_page({corner.x + width, corner.y + height})) return;
  if (!(width > 0) || !(height > 0) || image.width <= 0 || image.height <= 0) return;
  draw_image(corner, width, height, image, pixelated);
}

// ---- SVG backend ------------------------------------------------------------------------------

SvgCanvas::SvgCanvas(double width, double height) : Canvas(width, height), doc_(width, height) {}

void SvgCanvas::draw_polyline(const std::vector<Point>& points, const Style& style) {
  if (points.size() == 2)
    doc_.line(points[0], points[1], style);
  else
    doc_.polyline(points, style);
}

void SvgCanvas::draw_polygon(const std::vector<Point>& points, const Style& style) {
  if (points.size() >= 3) doc_.polygon(points, style);
}

void SvgCanvas::draw_circle(Point centre, double radius, const Style& style) {
  doc_.circle(centre, radius, style);
}

void SvgCanvas::draw_rect(Point corner, double width, double height, const Style& style) {
  doc_.rect(corner, width, height, style);
}

void SvgCanvas::draw_dots(const std::vector<Point>& centres, double radius,
                          const std::string& colour, double opacity) {
  doc_.dots(centres, radius, colour, opacity);
}

void SvgCanvas::draw_text(Point at, const std::string& content, const TextStyle& style) {
  const char* anchor = style.anchor == Anchor::kStart    ? "start"
                       : style.anchor == Anchor::kMiddle ? "middle"
                                                         : "end";
  doc_.text(at, content, style.size_px, anchor, style.colour, style.vertical ? -90.0 : 0.0,
            style.bold);
}

void SvgCanvas::draw_image(Point corner, double width, double height, const RgbImage& image,
                           bool pixelated) {
  doc_.image_png(corner, width, height, encode_png(image), pixelated);
}

void SvgCanvas::save(const std::filesystem::path& path) const {
  write_file_atomic(path, doc_.str());
}

}  // namespace lensopt::plot
