#include "lensopt/plot/axes.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace lensopt::plot {

double nice_ceil(double v) {
  if (!(v > 0) || !std::isfinite(v)) return 1.0;
  const double p = std::pow(10.0, std::floor(std::log10(v)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= v * (1 - 1e-9)) return m * p;
  return 10 * p;
}

double fine_ceil(double v) {
  if (!(v > 0) || !std::isfinite(v)) return 1.0;
  const double p = std::pow(10.0, std::floor(std::log10(v)));
  for (double m : {1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0})
    if (m * p >= v * (1 - 1e-9)) return m * p;
  return 10 * p;
}

double nice_step(double lo, double hi, int target) {
  const double span = std::abs(hi - lo);
  if (!(span > 0) || target <= 0) return 1.0;
  const double raw = span / target;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / p;
  const double m = f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10;
  return m * p;
}

std::vector<double> nice_ticks(double lo, double hi, int target) {
  std::vector<double> out;
  if (target <= 0 || !(hi > lo)) return out;
  const double step = nice_step(lo, hi, target);
  const double eps = 1e-6 * step;
  for (double k = std::ceil((lo - eps) / step); k * step <= hi + eps; k += 1) {
    const double v = k * step;
    out.push_back(std::abs(v) < eps ? 0.0 : v);
    if (out.size() > 100) break;
  }
  return out;
}

std::string format_tick(double value, double step) {
  int decimals = 0;
  if (step > 0 && step < 1) decimals = static_cast<int>(std::ceil(-std::log10(step) - 1e-9));
  decimals = std::clamp(decimals, 0, 6);
  if (std::abs(value) < 1e-6 * std::abs(step)) value = 0.0;  // no "-0"
  return fmt::format("{:.{}f}", value, decimals);
}

Axes::Axes(Rect frame, double x_lo, double x_hi, double y_lo, double y_hi)
    : frame_(frame), x_lo_(x_lo), x_hi_(x_hi), y_lo_(y_lo), y_hi_(y_hi) {
  if (!(x_hi_ > x_lo_)) x_hi_ = x_lo_ + 1;
  if (!(y_hi_ > y_lo_)) y_hi_ = y_lo_ + 1;
}

Axes Axes::equal_aspect(Rect frame, double x_lo, double x_hi, double y_lo, double y_hi) {
  const double sx = frame.width / std::max(1e-12, x_hi - x_lo);
  const double sy = frame.height / std::max(1e-12, y_hi - y_lo);
  const double s = std::min(sx, sy);
  const double xc = (x_lo + x_hi) / 2, yc = (y_lo + y_hi) / 2;
  const double hw = frame.width / s / 2, hh = frame.height / s / 2;
  return Axes(frame, xc - hw, xc + hw, yc - hh, yc + hh);
}

Point Axes::to_px(double x, double y) const {
  return {frame_.x + (x - x_lo_) / (x_hi_ - x_lo_) * frame_.width,
          frame_.y + (y_hi_ - y) / (y_hi_ - y_lo_) * frame_.height};
}

void Axes::draw_grid(Canvas& canvas, const AxesLabels& labels) const {
  const Style grid{"#e3e3e3", 0.8};
  const Style zero{"#9a9a9a", 1.0};
  if (labels.grid) {
    for (double x : nice_ticks(x_lo_, x_hi_, labels.x_ticks))
      canvas.line(to_px(x, y_lo_), to_px(x, y_hi_), grid);
    for (double y : nice_ticks(y_lo_, y_hi_, labels.y_ticks))
      canvas.line(to_px(x_lo_, y), to_px(x_hi_, y), grid);
  }
  if (labels.zero_x && x_lo_ < 0 && x_hi_ > 0) canvas.line(to_px(0, y_lo_), to_px(0, y_hi_), zero);
  if (labels.zero_y && y_lo_ < 0 && y_hi_ > 0) canvas.line(to_px(x_lo_, 0), to_px(x_hi_, 0), zero);
}

void Axes::draw_frame(Canvas& canvas, const AxesLabels& labels) const {
  const Style frame_style{"#333333", 1.0};
  canvas.rect({frame_.x, frame_.y}, frame_.width, frame_.height, frame_style);
  const double f = labels.font_px;
  TextStyle tick_text{f * 0.95, Anchor::kMiddle, "#333333"};
  const double tick_len = 4;
  double widest_y_label = 0;
  if (labels.x_ticks > 0) {
    const double step = nice_step(x_lo_, x_hi_, labels.x_ticks);
    for (double x : nice_ticks(x_lo_, x_hi_, labels.x_ticks)) {
      const Point p = to_px(x, y_lo_);
      canvas.line(p, {p.x, p.y - tick_len}, frame_style);
      canvas.text({p.x, p.y + f + 3}, format_tick(x, step), tick_text);
    }
  }
  if (labels.y_ticks > 0) {
    const double step = nice_step(y_lo_, y_hi_, labels.y_ticks);
    TextStyle t = tick_text;
    t.anchor = Anchor::kEnd;
    for (double y : nice_ticks(y_lo_, y_hi_, labels.y_ticks)) {
      const Point p = to_px(x_lo_, y);
      canvas.line(p, {p.x + tick_len, p.y}, frame_style);
      if (!labels.y_tick_labels) continue;
      const std::string s = format_tick(y, step);
      widest_y_label = std::max(widest_y_label, text_width_px(s, t.size_px));
      canvas.text({p.x - 4, p.y + f * 0.35}, s, t);
    }
  }
  if (!labels.x_label.empty()) {
    canvas.text({frame_.x + frame_.width / 2, frame_.bottom() + 2 * f + 8}, labels.x_label,
                TextStyle{f, Anchor::kMiddle, "#222222"});
  }
  if (!labels.y_label.empty()) {
    TextStyle t{f, Anchor::kMiddle, "#222222"};
    t.vertical = true;
    canvas.text({frame_.x - widest_y_label - 10, frame_.y + frame_.height / 2}, labels.y_label, t);
  }
  if (!labels.title.empty()) {
    TextStyle t{f * 1.1, Anchor::kMiddle, "#111111"};
    t.bold = true;
    canvas.text({frame_.x + frame_.width / 2, frame_.y - 7}, labels.title, t);
  }
}

void draw_scale_bar(Canvas& canvas, Point left, double length_px, const std::string& label,
                    double font_px) {
  const Style bar{"#222222", 1.6};
  canvas.line(left, {left.x + length_px, left.y}, bar);
  canvas.line({left.x, left.y - 4}, {left.x, left.y + 4}, bar);
  canvas.line({left.x + length_px, left.y - 4}, {left.x + length_px, left.y + 4}, bar);
  canvas.text({left.x + length_px + 6, left.y + font_px * 0.35}, label,
              TextStyle{font_px, Anchor::kStart, "#222222"});
}

namespace {

constexpr double kSample = 22, kGap = 6, kPad = 6, kSpacing = 14;

// Top-left corners of the entries (relative to the legend's corner) and the legend's size.
// Horizontal legends wrap to a new row before `max_width` (<= 0: no limit).
Point legend_positions(const std::vector<LegendEntry>& entries, double font_px, bool horizontal,
                       double max_width, std::vector<Point>* at) {
  const double row = font_px + 6;
  double x = kPad, y = kPad, w = 0;
  for (const LegendEntry& e : entries) {
    const double ew = kSample + kGap + text_width_px(e.label, font_px);
    if (horizontal && max_width > 0 && x > kPad && x + ew + kPad > max_width) {
      x = kPad;
      y += row;
    }
    if (at) at->push_back({x, y});
    w = std::max(w, x + ew);
    if (horizontal)
      x += ew + kSpacing;
    else
      y += row;
  }
  const double h = entries.empty() ? 0 : (horizontal ? y + row : y);
  return {w + kPad, h + kPad};
}

}  // namespace

Point legend_size(const std::vector<LegendEntry>& entries, double font_px, bool horizontal,
                  double max_width) {
  return legend_positions(entries, font_px, horizontal, max_width, nullptr);
}

Point draw_legend(Canvas& canvas, Point at, const std::vector<LegendEntry>& entries, double font_px,
                  bool horizontal, double max_width) {
  const double row = font_px + 6;
  std::vector<Point> where;
  const Point size = legend_positions(entries, font_px, horizontal, max_width, &where);
  canvas.rect(at, size.x, size.y, Style{"#c8c8c8", 0.8, "#ffffff"});
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const LegendEntry& e = entries[i];
    const double x = at.x + where[i].x;
    const double mid = at.y + where[i].y + row / 2;
    if (e.marker) {
      canvas.rect({x + kSample / 2 - 4, mid - 4}, 8, 8, Style{e.colour, 1.0, e.colour});
    } else {
      Style st{e.colour, 2.0};
      st.dash = e.dash;
      canvas.line({x, mid}, {x + kSample, mid}, st);
    }
    canvas.text({x + kSample + kGap, mid + font_px * 0.35}, e.label,
                TextStyle{font_px, Anchor::kStart, "#222222"});
  }
  return size;
}

}  // namespace lensopt::plot
