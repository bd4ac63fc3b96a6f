#include "lensopt/plot/svg.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace lensopt::plot {
namespace {

std::string style_attributes(const Style& s) {
  std::string out = fmt::format(R"(stroke="{}" stroke-width="{:.3g}" fill="{}")", s.stroke,
                                s.stroke_width, s.fill);
  if (s.opacity < 1.0) out += fmt::format(R"( opacity="{:.3g}")", s.opacity);
  if (!s.dash.empty()) out += fmt::format(R"( stroke-dasharray="{}")", s.dash);
  return out;
}

std::string points_attribute(const std::vector<Point>& points) {
  std::string out;
  for (const Point& p : points) out += fmt::format("{:.2f},{:.2f} ", p.x, p.y);
  return out;
}

// Standard base64 (RFC 4648) for embedding PNG data.
std::string base64(const std::string& bytes) {
  static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) |
                       (static_cast<unsigned char>(bytes[i + 1]) << 8) |
                       static_cast<unsigned char>(bytes[i + 2]);
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += table[(v >> 6) & 63];
    out += table[v & 63];
  }
  if (i < bytes.size()) {
    unsigned v = static_cast<unsigned char>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? table[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

}  // namespace

std::string xml_escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

SvgDocument::SvgDocument(double width, double height) : width_(width), height_(height) {}

void SvgDocument::line(Point a, Point b, const Style& style) {
  body_ += fmt::format(R"(<line x1="{:.2f}" y1="{:.2f}" x2="{:.2f}" y2="{:.2f}" {}/>)", a.x, a.y,
                       b.x, b.y, style_attributes(style));
  body_ += '\n';
}

void SvgDocument::polyline(const std::vector<Point>& points, const Style& style) {
  body_ += fmt::format(R"(<polyline points="{}" {}/>)", points_attribute(points),
                       style_attributes(style));
  body_ += '\n';
}

void SvgDocument::polygon(const std::vector<Point>& points, const Style& style) {
  body_ += fmt::format(R"(<polygon points="{}" {}/>)", points_attribute(points),
                       style_attributes(style));
  body_ += '\n';
}

void SvgDocument::circle(Point c, double radius, const Style& style) {
  body_ += fmt::format(R"(<circle cx="{:.2f}" cy="{:.2f}" r="{:.3g}" {}/>)", c.x, c.y, radius,
                       style_attributes(style));
  body_ += '\n';
}

void SvgDocument::rect(Point corner, double width, double height, const Style& style) {
  body_ += fmt::format(R"(<rect x="{:.2f}" y="{:.2f}" width="{:.2f}" height="{:.2f}" {}/>)",
                       corner.x, corner.y, width, height, style_attributes(style));
  body_ += '\n';
}

void SvgDocument::text(Point at, const std::string& content, double size_px,
                       const std::string& anchor, const std::string& colour, double rotate_deg,
                       bool bold) {
  std::string transform;
  if (rotate_deg != 0.0)
    transform =
        fmt::format(R"svg( transform="rotate({:.3g} {:.2f} {:.2f})")svg", rotate_deg, at.x, at.y);
  body_ += fmt::format(
      R"(<text x="{:.2f}" y="{:.2f}" font-family="DejaVu Sans, Helvetica, Arial, sans-serif" )"
      R"(font-size="{:.3g}" text-anchor="{}" fill="{}" xml:space="preserve"{}{}>{}</text>)",
      at.x, at.y, size_px, anchor, colour, bold ? R"( font-weight="bold")" : "", transform,
      xml_escape(content));
  body_ += '\n';
}

void SvgDocument::image_png(Point corner, double width, double height, const std::string& png_bytes,
                            bool pixelated) {
  body_ += fmt::format(R"(<image x="{:.2f}" y="{:.2f}" width="{:.2f}" height="{:.2f}" )"
                       R"(preserveAspectRatio="none"{} href="data:image/png;base64,{}"/>)",
                       corner.x, corner.y, width, height,
                       pixelated ? R"( style="image-rendering:pixelated")" : "", base64(png_bytes));
  body_ += '\n';
}

void SvgDocument::dots(const std::vector<Point>& centres, double radius, const std::string& colour,
                       double opacity) {
  if (centres.empty()) return;
  std::string d;
  d.reserve(centres.size() * 16);
  for (const Point& p : centres) d += fmt::format("M{:.1f} {:.1f}h0", p.x, p.y);
  body_ += fmt::format(R"(<path d="{}" stroke="{}" stroke-width="{:.3g}" stroke-linecap="round")",
                       d, colour, 2.0 * radius);
  if (opacity < 1.0) body_ += fmt::format(R"( stroke-opacity="{:.3g}")", opacity);
  body_ += " fill=\"none\"/>\n";
}

void SvgDocument::begin_group(const std::string& transform) {
  body_ += transform.empty() ? "<g>\n" : fmt::format(R"(<g transform="{}">)", transform) + "\n";
}

void SvgDocument::end_group() {
  body_ += "</g>\n";
}

std::string SvgDocument::str() const {
  return fmt::format(R"(<?xml version="1.0" encoding="UTF-8"?>)"
                     "\n"
                     R"(<svg xmlns="http://www.w3.org/2000/svg" width="{:.0f}" height="{:.0f}" )"
                     R"(viewBox="0 0 {:.0f} {:.0f}">)"
                     "\n"
                     R"(<rect width="100%" height="100%" fill="#ffffff"/>)"
                     "\n{}</svg>\n",
                     width_, height_, width_, height_, body_);
}

std::string sequential_colour(int i, int n) {
  // Anchor colours of a viridis-like ramp, linearly interpolated.
  static const std::array<std::array<double, 3>, 5> ramp = {
      {{68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}}};
  const double t = n <= 1 ? 0.0 : std::clamp(static_cast<double>(i) / (n - 1), 0.0, 1.0);
  const double pos = t * (ramp.size() - 1);
  const std::size_t k = std::min<std::size_t>(static_cast<std::size_t>(pos), ramp.size() - 2);
  const double f = pos - k;
  std::array<int, 3> rgb{};
  for (int c = 0; c < 3; ++c)
    rgb[c] = static_cast<int>(std::lround(ramp[k][c] * (1 - f) + ramp[k + 1][c] * f));
  return fmt::format("#{:02x}{:02x}{:02x}", rgb[0], rgb[1], rgb[2]);
}

std::string wavelength_colour(double nm) {
  // Piecewise-linear approximation of the visible spectrum (380..780 nm) to sRGB.
  double r = 0, g = 0, b = 0;
  if (nm < 440) {
    r = (440 - nm) / 60;
    b = 1;
  } else if (nm < 490) {
    g = (nm - 440) / 50;
    b = 1;
  } else if (nm < 510) {
    g = 1;
    b = (510 - nm) / 20;
  } else if (nm < 580) {
    r = (nm - 510) / 70;
    g = 1;
  } else if (nm < 645) {
    r = 1;
    g = (645 - nm) / 65;
  } else {
    r = 1;
  }
  auto to8 = [](double v) {
    return static_cast<int>(std::lround(255 * std::clamp(v, 0.0, 1.0) * 0.9));
  };
  return fmt::format("#{:02x}{:02x}{:02x}", to8(r), to8(g), to8(b));
}

}  // namespace lensopt::plot
