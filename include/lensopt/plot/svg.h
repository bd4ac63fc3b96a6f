// A small SVG writer: the project's plots are written by the project itself (no plotting
// dependency). Coordinates are SVG user units (pixels, y down); a Figure maps data coordinates
// into a panel.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace lensopt::plot {

// Stroke and fill style. Colours are CSS strings ("#1f77b4", "none").
struct Style {
  std::string stroke = "#000000";
  double stroke_width = 1.0;
  std::string fill = "none";
  double opacity = 1.0;
  std::string dash;  // SVG dash array ("4 3"), empty for solid

  Style(std::string stroke_colour = "#000000", double width = 1.0, std::string fill_colour = "none",
        double opacity_value = 1.0, std::string dash_array = "")
      : stroke(std::move(stroke_colour)),
        stroke_width(width),
        fill(std::move(fill_colour)),
        opacity(opacity_value),
        dash(std::move(dash_array)) {}
};

struct Point {
  double x = 0;
  double y = 0;
};

// An SVG document built element by element.
class SvgDocument {
 public:
  SvgDocument(double width, double height);

  void line(Point a, Point b, const Style& style);
  void polyline(const std::vector<Point>& points, const Style& style);
  void polygon(const std::vector<Point>& points, const Style& style);
  void circle(Point centre, double radius, const Style& style);
  void rect(Point corner, double width, double height, const Style& style);
  // Text anchored "start", "middle" or "end"; size in px; rotation in degrees about the anchor.
  void text(Point at, const std::string& content, double size_px = 12,
            const std::string& anchor = "start", const std::string& colour = "#000000",
            double rotate_deg = 0, bool bold = false);
  // An embedded raster image (PNG bytes), e.g. a PSF strip; `pixelated` keeps its pixels sharp
  // when scaled up.
  void image_png(Point corner, double width, double height, const std::string& png_bytes,
                 bool pixelated = false);
  // Many small round dots of one colour as one compact path (zero-length segments with round
  // caps): a spot diagram of thousands of rays stays a small file.
  void dots(const std::vector<Point>& centres, double radius, const std::string& colour,
            double opacity = 1.0);
  // Starts / ends a <g> group with an optional transform.
  void begin_group(const std::string& transform = "");
  void end_group();

  double width() const { return width_; }
  double height() const { return height_; }
  std::string str() const;

 private:
  double width_;
  double height_;
  std::string body_;
};

// Escapes &, <, >, " for SVG text and attributes.
std::string xml_escape(const std::string& text);

// A colour for index i of n, from a perceptually ordered palette (viridis-like).
std::string sequential_colour(int i, int n);
// A colour for a wavelength in nm (visible spectrum approximation).
std::string wavelength_colour(double wavelength_nm);

}  // namespace lensopt::plot
