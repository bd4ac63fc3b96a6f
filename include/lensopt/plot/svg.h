// A small SVG writer: the project's plots are written by the project itself (no plotting
// dependency). Coordinates are SVG user units (pixels, y down); a Figure maps data coordinates
// into a panel.
#pragma once

#include <string>
#include <vector>

namespace lensopt::plot {

// Stroke and fill style. Colours are CSS strings ("#1f77b4", "none").
struct Style {
  std::string stroke = "#000000";
  double stroke_width = 1.0;
  std::string fill = "none";
  double opacity = 1.0;
  std::string dash;  // SVG dash array ("4 3"), empty for solid
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
            double rotate_deg = 0);
  // An embedded raster image (PNG bytes), e.g. a PSF strip.
  void image_png(Point corner, double width, double height, const std::string& png_bytes);
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
