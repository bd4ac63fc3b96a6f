// The raster canvas backend: OpenImageIO's ImageBufAlgo (in the module liblensopt_oiio.so, behind
// core/image_plugin.h's RasterSurface) draws at `supersample` times the page size into an RGBA
// buffer (colours premultiplied, composited "over"); save() box-filters it down to the page size,
// which anti-aliases every edge, and writes an RGB PNG through libpng.
//   lines      render_line for hairlines; wider strokes as filled quads
//   polygons   even-odd scanline spans, each span one render_box
//   text       render_text (DejaVu Sans); vertical text is rendered apart, turned with
//              rotate270 and composited with over()
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/image_plugin.h"
#include "core/png_io.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/plot/canvas.h"

namespace lensopt::plot {
namespace {

// The OpenImageIO module, loaded when the first raster canvas is made.
const ImagePlugin& oiio() {
  return image_plugin("drawing a PNG plot (lines and text through OpenImageIO)");
}

constexpr const char* kFontRegular = "DejaVuSans";
constexpr const char* kFontBold = "DejaVuSans-Bold";

// Premultiplied RGBA of a CSS colour with an opacity; false for "none".
bool premultiplied(const std::string& css, double opacity, float rgba[4]) {
  float rgb[3];
  if (!parse_colour(css, rgb)) return false;
  const float a = static_cast<float>(std::clamp(opacity, 0.0, 1.0));
  for (int c = 0; c < 3; ++c) rgba[c] = rgb[c] * a;
  rgba[3] = a;
  return true;
}

std::vector<double> parse_dash(const std::string& dash, double scale) {
  std::vector<double> out;
  std::istringstream in(dash);
  std::string item;
  while (in >> item) {
    for (char& c : item)
      if (c == ',') c = ' ';
    std::istringstream part(item);
    double v;
    while (part >> v)
      if (v > 0) out.push_back(v * scale);
  }
  if (out.size() % 2 == 1) {  // SVG repeats an odd list
    const std::size_t n = out.size();
    for (std::size_t i = 0; i < n; ++i) out.push_back(out[i]);
  }
  return out;
}

// Splits a polyline into the "on" pieces of a dash pattern (lengths in the polyline's units).
std::vector<std::vector<Point>> dashed_pieces(const std::vector<Point>& points,
                                              const std::vector<double>& pattern) {
  std::vector<std::vector<Point>> pieces;
  if (pattern.empty()) {
    pieces.push_back(points);
    return pieces;
  }
  std::size_t index = 0;
  double left = pattern[0];
  bool on = true;
  std::vector<Point> current{points.front()};
  for (std::size_t i = 0; i + 1 < points.size(); ++i) {
    Point a = points[i];
    const Point b = points[i + 1];
    double length = std::hypot(b.x - a.x, b.y - a.y);
    while (length > left) {
      const double f = left / length;
      const Point cut{a.x + f * (b.x - a.x), a.y + f * (b.y - a.y)};
      if (on) {
        current.push_back(cut);
        pieces.push_back(current);
      }
      current = {cut};
      on = !on;
      length -= left;
      a = cut;
      index = (index + 1) % pattern.size();
      left = pattern[index];
    }
    left -= length;
    if (on)
      current.push_back(b);
    else
      current = {b};
  }
  if (on && current.size() >= 2) pieces.push_back(current);
  return pieces;
}

// Fills a polygon (pixel coordinates of dst): pixels whose centres are inside (even-odd), one
// render_box per span.
void fill_polygon(RasterSurface& dst, const std::vector<Point>& pts, const float rgba[4]) {
  if (pts.size() < 3) return;
  double y_lo = pts[0].y, y_hi = pts[0].y;
  for (const Point& p : pts) {
    y_lo = std::min(y_lo, p.y);
    y_hi = std::max(y_hi, p.y);
  }
  const int H = dst.height();
  const int W = dst.width();
  const int row_begin = std::max(0, static_cast<int>(std::floor(y_lo - 0.5)));
  const int row_end = std::min(H - 1, static_cast<int>(std::ceil(y_hi + 0.5)));
  std::vector<double> xs;
  for (int j = row_begin; j <= row_end; ++j) {
    const double yc = j + 0.5;
    xs.clear();
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const Point& a = pts[i];
      const Point& b = pts[(i + 1) % pts.size()];
      if ((a.y <= yc && yc < b.y) || (b.y <= yc && yc < a.y))
        xs.push_back(a.x + (yc - a.y) * (b.x - a.x) / (b.y - a.y));
    }
    std::sort(xs.begin(), xs.end());
    for (std::size_t k = 0; k + 1 < xs.size(); k += 2) {
      const int x0 = std::max(0, static_cast<int>(std::ceil(xs[k] - 0.5)));
      const int x1 = std::min(W - 1, static_cast<int>(std::floor(xs[k + 1] - 0.5)));
      if (x1 >= x0) dst.box(x0, j, x1, j, rgba);
    }
  }
}

// One straight stroke of width w (pixels of dst): a hairline below 1.75 px, else a quad.
void stroke_segment(RasterSurface& dst, Point a, Point b, double w, const float rgba[4]) {
  if (w < 1.75) {
    dst.line(static_cast<int>(std::floor(a.x)), static_cast<int>(std::floor(a.y)),
             static_cast<int>(std::floor(b.x)), static_cast<int>(std::floor(b.y)), rgba);
    return;
  }
  const double len = std::hypot(b.x - a.x, b.y - a.y);
  if (len < 1e-9) return;
  const double nx = -(b.y - a.y) / len * w / 2, ny = (b.x - a.x) / len * w / 2;
  fill_polygon(
      dst, {{a.x + nx, a.y + ny}, {b.x + nx, b.y + ny}, {b.x - nx, b.y - ny}, {a.x - nx, a.y - ny}},
      rgba);
}

// Text in runs: OpenImageIO 2.4's UTF-8 decoder keeps only the last byte of a multi-byte
// character, so ASCII runs go through render_text and the few symbols the plots use are drawn.
struct TextPiece {
  std::string ascii;    // a run of ASCII characters, or
  char32_t symbol = 0;  // one non-ASCII character
};

std::vector<TextPiece> split_text(const std::string& utf8) {
  std::vector<TextPiece> out;
  for (std::size_t i = 0; i < utf8.size();) {
    const unsigned char c = static_cast<unsigned char>(utf8[i]);
    if (c < 0x80) {
      if (out.empty() || out.back().symbol != 0) out.emplace_back();
      out.back().ascii += static_cast<char>(c);
      ++i;
      continue;
    }
    const int len = c >= 0xF0 ? 4 : c >= 0xE0 ? 3 : c >= 0xC0 ? 2 : 1;
    char32_t cp = len == 1 ? c : c & (0x7F >> len);
    for (int k = 1; k < len && i + k < utf8.size(); ++k)
      cp = (cp << 6) | (static_cast<unsigned char>(utf8[i + k]) & 0x3F);
    TextPiece p;
    p.symbol = cp;
    out.push_back(p);
    i += len;
  }
  return out;
}

// Advance (px) of an ASCII run: measured with a sentinel so trailing spaces count.
double ascii_advance(const std::string& text, int size, const char* font) {
  if (text.empty()) return 0;
  int with[4], bar[4];
  if (!oiio().text_size(text + "|", size, font, with) || !oiio().text_size("|", size, font, bar))
    return 0;
  return with[1] - bar[1];
}

double symbol_advance(char32_t symbol, int size, const char* font) {
  switch (symbol) {
    case U'\u00b0':
      return 0.40 * size;  // degree
    case U'\u00b5':
      return ascii_advance("u", size, font);  // micro
    case U'\u00d7':
      return 0.62 * size;  // times
    case U'\u2013':
      return 0.50 * size;  // en dash
    default:
      return ascii_advance("?", size, font);
  }
}

double text_advance(const std::vector<TextPiece>& pieces, int size, const char* font) {
  double w = 0;
  for (const TextPiece& p : pieces)
    w += p.symbol ? symbol_advance(p.symbol, size, font) : ascii_advance(p.ascii, size, font);
  return w;
}

// Draws pieces left-aligned with the baseline at (x, y) into dst.
void draw_pieces(RasterSurface& dst, double x, double y, const std::vector<TextPiece>& pieces,
                 int size, const char* font, const float rgba[4]) {
  const double em = size;
  const double stroke = std::max(1.0, 0.085 * em);
  for (const TextPiece& p : pieces) {
    if (!p.symbol) {
      dst.text(static_cast<int>(std::lround(x)), static_cast<int>(std::lround(y)), p.ascii, size,
               font, rgba);
      x += ascii_advance(p.ascii, size, font);
      continue;
    }
    switch (p.symbol) {
      case U'\u00b0': {  // a small ring at cap height
        const Point c{x + 0.2 * em, y - 0.6 * em};
        const double r = 0.11 * em;
        for (int i = 0; i < 16; ++i) {
          const double a0 = 2 * kPi * i / 16, a1 = 2 * kPi * (i + 1) / 16;
          stroke_segment(dst, {c.x + r * std::cos(a0), c.y + r * std::sin(a0)},
                         {c.x + r * std::cos(a1), c.y + r * std::sin(a1)}, stroke * 0.9, rgba);
        }
        break;
      }
      case U'\u00b5': {  // "u" with a descender on its left stem
        dst.text(static_cast<int>(std::lround(x)), static_cast<int>(std::lround(y)), "u", size,
                 font, rgba);
        int u[4];
        const double left = x + (oiio().text_size("u", size, font, u) ? u[0] : 0.09 * em);
        fill_polygon(dst,
                     {{left, y - 0.2 * em},
                      {left + stroke * 1.05, y - 0.2 * em},
                      {left + stroke * 1.05, y + 0.21 * em},
                      {left, y + 0.21 * em}},
                     rgba);
        break;
      }
      case U'\u00d7': {
        const Point c{x + 0.31 * em, y - 0.33 * em};
        const double h = 0.19 * em;
        stroke_segment(dst, {c.x - h, c.y - h}, {c.x + h, c.y + h}, stroke, rgba);
        stroke_segment(dst, {c.x - h, c.y + h}, {c.x + h, c.y - h}, stroke, rgba);
        break;
      }
      case U'\u2013':
        stroke_segment(dst, {x + 0.02 * em, y - 0.3 * em}, {x + 0.48 * em, y - 0.3 * em}, stroke,
                       rgba);
        break;
      default:
        dst.text(static_cast<int>(std::lround(x)), static_cast<int>(std::lround(y)), "?", size,
                 font, rgba);
    }
    x += symbol_advance(p.symbol, size, font);
  }
}

}  // namespace

struct RasterCanvas::Impl {
  int ss = 2;
  int width_px = 0;
  int height_px = 0;
  std::unique_ptr<RasterSurface> surface;
  RasterSurface& buf() { return *surface; }
  bool font_ok = true;
  bool bold_ok = true;
  std::vector<std::string> warnings;

  double s(double v) const { return v * ss; }
  Point s(Point p) const { return {p.x * ss, p.y * ss}; }

  void stroke(const std::vector<Point>& page_points, const Style& style, bool closed) {
    float rgba[4];
    if (page_points.size() < 2 || !premultiplied(style.stroke, style.opacity, rgba)) return;
    std::vector<Point> pts;
    pts.reserve(page_points.size() + 1);
    for (const Point& p : page_points) pts.push_back(s(p));
    if (closed) pts.push_back(pts.front());
    const double w = std::max(1.0, s(style.stroke_width));
    for (const auto& piece : dashed_pieces(pts, parse_dash(style.dash, ss))) {
      for (std::size_t i = 0; i + 1 < piece.size(); ++i) {
        stroke_segment(buf(), piece[i], piece[i + 1], w, rgba);
        // Square joins keep wide polylines free of notches.
        if (w >= 3 && i > 0 && style.opacity >= 1.0) {
          const int r = static_cast<int>(w / 2 - 0.5);
          const int x = static_cast<int>(std::floor(piece[i].x));
          const int y = static_cast<int>(std::floor(piece[i].y));
          buf().box(x - r, y - r, x + r, y + r, rgba);
        }
      }
    }
  }

  void draw_text(Point at, const std::string& content, const TextStyle& style) {
    const bool want_bold = style.bold && bold_ok;
    const char* font = want_bold ? kFontBold : kFontRegular;
    if (!font_ok || content.empty()) return;
    float rgba[4];
    if (!premultiplied(style.colour, 1.0, rgba)) return;
    const int size = std::max(1, static_cast<int>(std::lround(s(style.size_px))));
    const Point p = s(at);
    const std::vector<TextPiece> pieces = split_text(content);
    const double advance = text_advance(pieces, size, font);
    const double shift = style.anchor == Anchor::kStart    ? 0.0
                         : style.anchor == Anchor::kMiddle ? advance / 2
                                                           : advance;
    if (!style.vertical) {
      draw_pieces(buf(), p.x - shift, p.y, pieces, size, font, rgba);
      return;
    }
    // Vertical: draw horizontally into a transparent buffer, turn it 90 degrees
    // counter-clockwise, composite it over the page.
    const int pad = 2;
    const int ascent = static_cast<int>(std::ceil(1.05 * size));
    const int descent = static_cast<int>(std::ceil(0.3 * size));
    const int tw = static_cast<int>(std::ceil(advance)) + 2 * pad;
    const int th = ascent + descent + 2 * pad;
    std::unique_ptr<RasterSurface> flat = oiio().make_surface(tw, th);
    const float clear[4] = {0.f, 0.f, 0.f, 0.f};
    flat->fill(clear);
    const int base_u = pad, base_v = pad + ascent;
    draw_pieces(*flat, base_u, base_v, pieces, size, font, rgba);
    // (u, v) of the flat buffer lands on (v, tw - 1 - u) of the turned one.
    const double u_anchor = base_u + shift;
    const int x0 = static_cast<int>(std::lround(p.x - base_v));
    const int y0 = static_cast<int>(std::lround(p.y - (tw - 1 - u_anchor)));
    buf().over_rotated270(*flat, x0, y0);
  }
};

RasterCanvas::RasterCanvas(double width, double height, int supersample)
    : Canvas(width, height), impl_(std::make_unique<Impl>()) {
  impl_->ss = std::max(1, supersample);
  impl_->width_px = std::max(1, static_cast<int>(std::lround(width)));
  impl_->height_px = std::max(1, static_cast<int>(std::lround(height)));
  impl_->surface = oiio().make_surface(impl_->width_px * impl_->ss, impl_->height_px * impl_->ss);
  const float white[4] = {1.f, 1.f, 1.f, 1.f};
  impl_->buf().fill(white);
  int box[4];
  if (!oiio().text_size("M", 12, kFontRegular, box)) {
    impl_->font_ok = false;
    impl_->warnings.emplace_back(
        "OpenImageIO found no DejaVu Sans font (install fonts-dejavu-core): PNG text left out");
  }
  if (impl_->font_ok && !oiio().text_size("M", 12, kFontBold, box)) impl_->bold_ok = false;
}

RasterCanvas::~RasterCanvas() = default;

void RasterCanvas::draw_polyline(const std::vector<Point>& points, const Style& style) {
  impl_->stroke(points, style, false);
}

void RasterCanvas::draw_polygon(const std::vector<Point>& points, const Style& style) {
  float rgba[4];
  if (points.size() >= 3 && premultiplied(style.fill, style.opacity, rgba)) {
    std::vector<Point> pts;
    pts.reserve(points.size());
    for (const Point& p : points) pts.push_back(impl_->s(p));
    fill_polygon(impl_->buf(), pts, rgba);
  }
  impl_->stroke(points, style, true);
}

void RasterCanvas::draw_circle(Point centre, double radius, const Style& style) {
  const int n = std::clamp(static_cast<int>(impl_->s(radius)), 24, 360);
  std::vector<Point> pts(n);
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * kPi * i / n;
    pts[i] = {centre.x + radius * std::cos(a), centre.y + radius * std::sin(a)};
  }
  polygon(pts, style);
}

void RasterCanvas::draw_rect(Point corner, double width, double height, const Style& style) {
  polygon({corner,
           {corner.x + width, corner.y},
           {corner.x + width, corner.y + height},
           {corner.x, corner.y + height}},
          style);
}

void RasterCanvas::draw_dots(const std::vector<Point>& centres, double radius,
                             const std::string& colour, double opacity) {
  float rgba[4];
  if (!premultiplied(colour, opacity, rgba)) return;
  const int d = std::max(1, static_cast<int>(std::lround(2.0 * impl_->s(radius))));
  for (const Point& c : centres) {
    const Point p = impl_->s(c);
    const int x = static_cast<int>(std::lround(p.x - 0.5 * d));
    const int y = static_cast<int>(std::lround(p.y - 0.5 * d));
    impl_->buf().box(x, y, x + d - 1, y + d - 1, rgba);
  }
}

void RasterCanvas::draw_text(Point at, const std::string& content, const TextStyle& style) {
  impl_->draw_text(at, content, style);
}

void RasterCanvas::draw_image(Point corner, double width, double height, const RgbImage& image,
                              bool pixelated) {
  if (image.width <= 0 || image.height <= 0) return;
  const int x0 = static_cast<int>(std::lround(impl_->s(corner.x)));
  const int y0 = static_cast<int>(std::lround(impl_->s(corner.y)));
  const int w = std::max(1, static_cast<int>(std::lround(impl_->s(width))));
  const int h = std::max(1, static_cast<int>(std::lround(impl_->s(height))));
  impl_->buf().paste_rgb(image.pixels.data(), image.width, image.height, x0, y0, w, h, pixelated);
}

RgbImage RasterCanvas::final_image() const {
  const int w = impl_->width_px, h = impl_->height_px;
  RgbImage out(w, h);
  out.pixels = impl_->surface->downsample_rgb(w, h);
  return out;
}

void RasterCanvas::save(const std::filesystem::path& path) const {
  const RgbImage page = final_image();
  write_file_atomic_with(path, [&](const std::filesystem::path& temp) {
    std::string error;
    if (!write_png(temp, page.width, page.height, 3, 8, page.pixels.data(), error))
      throw Error(SourceLocation{path.string(), 0, 0},
                  fmt::format("cannot write the PNG: {}", error));
  });
}

std::vector<std::string> RasterCanvas::warnings() const {
  return impl_->warnings;
}

}  // namespace lensopt::plot
