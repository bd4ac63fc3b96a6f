// A drawing surface for plots, so each plot is drawn once and written as SVG or PNG.
//
// Coordinates are pixels of the output page, x to the right and y down (the SVG convention);
// a plot maps its data into a panel with plot::Axes (axes.h). Two backends:
//   SvgCanvas     the project's SvgDocument (vector output, .svg);
//   RasterCanvas  an OpenImageIO ImageBuf (.png; in the module liblensopt_oiio.so, loaded when
//                 the first one is made): lines, boxes and text through ImageBufAlgo,
//                 drawn at `supersample` times the page size and box-filtered down, which
//                 anti-aliases edges. Filled polygons are filled span by span with render_box.
// Colours are CSS hex strings "#rrggbb" (or "none"); text uses DejaVu Sans (fonts-dejavu-core).
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "lensopt/plot/svg.h"

namespace lensopt::plot {

enum class Anchor { kStart, kMiddle, kEnd };

struct TextStyle {
  double size_px = 12;
  Anchor anchor = Anchor::kStart;
  std::string colour = "#000000";
  bool vertical = false;  // rotated by -90 degrees about the anchor (reads bottom to top)
  bool bold = false;

  TextStyle(double size = 12, Anchor anchor_value = Anchor::kStart,
            std::string colour_value = "#000000", bool vertical_value = false,
            bool bold_value = false)
      : size_px(size),
        anchor(anchor_value),
        colour(std::move(colour_value)),
        vertical(vertical_value),
        bold(bold_value) {}
};

// An RGB image with values in [0, 1], rows top to bottom, 3 floats per pixel.
struct RgbImage {
  int width = 0;
  int height = 0;
  std::vector<float> pixels;

  RgbImage() = default;
  RgbImage(int w, int h) : width(w), height(h), pixels(static_cast<std::size_t>(w) * h * 3, 0.f) {}
  float* at(int x, int y) { return &pixels[(static_cast<std::size_t>(y) * width + x) * 3]; }
  const float* at(int x, int y) const {
    return &pixels[(static_cast<std::size_t>(y) * width + x) * 3];
  }
};

// An approximate width (px) of `text` in DejaVu Sans at `size_px`, for placing labels.
double text_width_px(const std::string& text, double size_px);

// The drawing calls check their input once for both backends: coordinates that are not finite
// are left out (a polyline is split there), and lines are clipped to a margin around the page,
// so no NaN reaches a file and no huge number reaches a pixel cast.
class Canvas {
 public:
  Canvas(double width, double height) : width_(width), height_(height) {}
  virtual ~Canvas() = default;
  Canvas(const Canvas&) = delete;
  Canvas& operator=(const Canvas&) = delete;

  double width() const { return width_; }
  double height() const { return height_; }

  void line(Point a, Point b, const Style& style);
  void polyline(const std::vector<Point>& points, const Style& style);
  // A closed polygon, filled with style.fill (unless "none") and stroked with style.stroke.
  void polygon(const std::vector<Point>& points, const Style& style);
  void circle(Point centre, double radius, const Style& style);
  void rect(Point corner, double width, double height, const Style& style);
  // Small filled dots of radius `radius` px (spot diagrams).
  void dots(const std::vector<Point>& centres, double radius, const std::string& colour,
            double opacity = 1.0);
  // Text with its baseline at `at` (anchored per style.anchor).
  void text(Point at, const std::string& content, const TextStyle& style);
  // An RGB image stretched over the rectangle; `pixelated` keeps its pixels sharp (no smoothing).
  void image(Point corner, double width, double height, const RgbImage& image, bool pixelated);

  // Lines and polylines drawn after this are clipped to the rectangle (x, y, width, height) until
  // clear_clip(), so a panel's rays stay in the panel.
  void set_clip(double x, double y, double width, double height);
  void clear_clip();

  // Writes the page to `path` atomically in the backend's format.
  virtual void save(const std::filesystem::path& path) const = 0;
  // Problems met while drawing that did not stop it (e.g. no font found: text left out).
  virtual std::vector<std::string> warnings() const { return {}; }

 protected:
  // The backends' drawing, called with finite coordinates near the page only.
  virtual void draw_polyline(const std::vector<Point>& points, const Style& style) = 0;
  virtual void draw_polygon(const std::vector<Point>& points, const Style& style) = 0;
  virtual void draw_circle(Point centre, double radius, const Style& style) = 0;
  virtual void draw_rect(Point corner, double width, double height, const Style& style) = 0;
  virtual void draw_dots(const std::vector<Point>& centres, double radius,
                         const std::string& colour, double opacity) = 0;
  virtual void draw_text(Point at, const std::string& content, const TextStyle& style) = 0;
  virtual void draw_image(Point corner, double width, double height, const RgbImage& image,
                          bool pixelated) = 0;

 private:
  bool near_page(Point p) const;
  double width_;
  double height_;
  bool clip_ = false;
  double clip_x0_ = 0, clip_y0_ = 0, clip_x1_ = 0, clip_y1_ = 0;
};

class SvgCanvas : public Canvas {
 public:
  SvgCanvas(double width, double height);
  void draw_polyline(const std::vector<Point>& points, const Style& style) override;
  void draw_polygon(const std::vector<Point>& points, const Style& style) override;
  void draw_circle(Point centre, double radius, const Style& style) override;
  void draw_rect(Point corner, double width, double height, const Style& style) override;
  void draw_dots(const std::vector<Point>& centres, double radius, const std::string& colour,
                 double opacity) override;
  void draw_text(Point at, const std::string& content, const TextStyle& style) override;
  void draw_image(Point corner, double width, double height, const RgbImage& image,
                  bool pixelated) override;
  void save(const std::filesystem::path& path) const override;

  std::string str() const { return doc_.str(); }

 private:
  SvgDocument doc_;
};

class RasterCanvas : public Canvas {
 public:
  // A white page of width x height px (rounded to whole pixels).
  RasterCanvas(double width, double height, int supersample = 2);
  ~RasterCanvas() override;
  void draw_polyline(const std::vector<Point>& points, const Style& style) override;
  void draw_polygon(const std::vector<Point>& points, const Style& style) override;
  void draw_circle(Point centre, double radius, const Style& style) override;
  void draw_rect(Point corner, double width, double height, const Style& style) override;
  void draw_dots(const std::vector<Point>& centres, double radius, const std::string& colour,
                 double opacity) override;
  void draw_text(Point at, const std::string& content, const TextStyle& style) override;
  void draw_image(Point corner, double width, double height, const RgbImage& image,
                  bool pixelated) override;
  void save(const std::filesystem::path& path) const override;
  std::vector<std::string> warnings() const override;

  // The page at its final size (supersampling resolved), RGB.
  RgbImage final_image() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

enum class OutputFormat { kSvg, kPng };

// The output format from a file's extension (.svg or .png, any case); throws Error otherwise.
OutputFormat output_format_for(const std::filesystem::path& path);

// A canvas of the format `path` asks for.
std::unique_ptr<Canvas> make_canvas(const std::filesystem::path& path, double width, double height);

// PNG bytes of an RGB image (8 bit), through libpng.
std::string encode_png(const RgbImage& image);

// "#rrggbb" -> r, g, b in [0, 1]; false for "none" or anything unparsable.
bool parse_colour(const std::string& css, float rgb[3]);

}  // namespace lensopt::plot
