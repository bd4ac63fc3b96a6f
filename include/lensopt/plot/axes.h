// Panels of a plot page: a pixel rectangle, a linear map from data to pixels, ticks at "nice"
// numbers (1, 2, 5 x 10^k), frames, labels and legends, drawn on any Canvas.
//   px = frame.x + (x - x_lo) / (x_hi - x_lo) * frame.width
//   py = frame.y + (y_hi - y) / (y_hi - y_lo) * frame.height   (data y up, pixels y down)
#pragma once

#include <string>
#include <vector>

#include "lensopt/plot/canvas.h"

namespace lensopt::plot {

struct Rect {
  double x = 0;
  double y = 0;
  double width = 0;
  double height = 0;
  double right() const { return x + width; }
  double bottom() const { return y + height; }
  Point centre() const { return {x + width / 2, y + height / 2}; }
  // The rectangle shrunk by the given margins (px).
  Rect inset(double left, double top, double right_margin, double bottom_margin) const {
    return {x + left, y + top, width - left - right_margin, height - top - bottom_margin};
  }
};

// The smallest of 1, 2, 5 x 10^k that is >= v (v > 0).
double nice_ceil(double v);
// The same on a finer ladder: 1, 1.5, 2, 2.5, 3, 4, 5, 6, 8 x 10^k (plot extents).
double fine_ceil(double v);
// A tick step of 1, 2, 5 x 10^k giving about `target` intervals over [lo, hi].
double nice_step(double lo, double hi, int target);
// Tick values: multiples of nice_step within [lo, hi] (with a small tolerance).
std::vector<double> nice_ticks(double lo, double hi, int target);
// A tick label with as many decimals as the step needs ("0.05", "10", "-2.5").
std::string format_tick(double value, double step);

struct AxesLabels {
  std::string title;
  std::string x_label;
  std::string y_label;
  int x_ticks = 5;  // about this many intervals; 0: no ticks
  int y_ticks = 5;
  bool grid = true;
  bool y_tick_labels = true;  // false: ticks only (a panel sharing its left neighbour's scale)
  bool zero_x = false;        // a darker line at x = 0
  bool zero_y = false;        // a darker line at y = 0
  double font_px = 11;
};

class Axes {
 public:
  Axes(Rect frame, double x_lo, double x_hi, double y_lo, double y_hi);
  // Axes with equal scale in x and y (mm per px the same), the data range centred in the frame.
  static Axes equal_aspect(Rect frame, double x_lo, double x_hi, double y_lo, double y_hi);

  Point to_px(double x, double y) const;
  Point to_px(Point data) const { return to_px(data.x, data.y); }
  double px_per_x() const { return frame_.width / (x_hi_ - x_lo_); }
  double px_per_y() const { return frame_.height / (y_hi_ - y_lo_); }
  const Rect& frame() const { return frame_; }
  double x_lo() const { return x_lo_; }
  double x_hi() const { return x_hi_; }
  double y_lo() const { return y_lo_; }
  double y_hi() const { return y_hi_; }

  // Grid and zero lines (draw before the data).
  void draw_grid(Canvas& canvas, const AxesLabels& labels) const;
  // Frame, ticks, tick labels, axis labels and title (draw after the data).
  void draw_frame(Canvas& canvas, const AxesLabels& labels) const;

 private:
  Rect frame_;
  double x_lo_, x_hi_, y_lo_, y_hi_;
};

// A scale bar from `left` (its left end, px) `length_px` long with end ticks, labelled on its
// right ("5 mm", "50 um").
void draw_scale_bar(Canvas& canvas, Point left, double length_px, const std::string& label,
                    double font_px);

struct LegendEntry {
  std::string label;
  std::string colour;
  std::string dash;     // empty: solid line sample
  bool marker = false;  // a filled square instead of a line sample

  LegendEntry(std::string label_text, std::string colour_value, std::string dash_array = "",
              bool is_marker = false)
      : label(std::move(label_text)),
        colour(std::move(colour_value)),
        dash(std::move(dash_array)),
        marker(is_marker) {}
};

// A legend box with its top-left corner at `at`; returns its size (width, height) in px.
// A horizontal legend wraps into rows to stay within `max_width` (<= 0: one row).
Point draw_legend(Canvas& canvas, Point at, const std::vector<LegendEntry>& entries,
                  double font_px = 11, bool horizontal = false, double max_width = 0);
// The size a legend would take.
Point legend_size(const std::vector<LegendEntry>& entries, double font_px, bool horizontal,
                  double max_width = 0);

}  // namespace lensopt::plot
