// Boxes through crops, the resolution factor and distortion (maths in detection/boxes.h).
#include "lensopt/detection/boxes.h"

#include <algorithm>
#include <cmath>

#include "lensopt/core/interpolate.h"

namespace lensopt {

double Box::area() const {
  return empty() ? 0.0 : (x1 - x0) * (y1 - y0);
}

namespace {

double intersection_area(const Box& a, const Box& b) {
  const double w = std::min(a.x1, b.x1) - std::max(a.x0, b.x0);
  const double h = std::min(a.y1, b.y1) - std::max(a.y0, b.y0);
  return w > 0 && h > 0 ? w * h : 0.0;
}

}  // namespace

double iou(const Box& a, const Box& b) {
  const double inter = intersection_area(a, b);
  const double uni = a.area() + b.area() - inter;
  return uni > 0 ? inter / uni : 0.0;
}

double intersection_over_second(const Box& a, const Box& b) {
  const double area = b.area();
  return area > 0 ? intersection_area(a, b) / area : 0.0;
}

std::optional<Box> crop_box(const Box& box, double crop_x0, double crop_y0, double crop_width,
                            double crop_height, const CropRule& rule) {
  const double full = box.area();
  if (full <= 0) return std::nullopt;
  Box c{std::clamp(box.x0 - crop_x0, 0.0, crop_width),
        std::clamp(box.y0 - crop_y0, 0.0, crop_height),
        std::clamp(box.x1 - crop_x0, 0.0, crop_width),
        std::clamp(box.y1 - crop_y0, 0.0, crop_height)};
  if (c.width() < rule.min_side_px || c.height() < rule.min_side_px) return std::nullopt;
  if (c.area() < rule.min_visible_fraction * full) return std::nullopt;
  return c;
}

Box scale_box(const Box& box, double factor) {
  return {box.x0 * factor, box.y0 * factor, box.x1 * factor, box.y1 * factor};
}

BoxDistortion::BoxDistortion(const ImagingModel& model, int width, int height, int res_factor)
    : geometry_(SensorGeometry::make(width, height, res_factor, model.sensor_diagonal_mm)),
      reference_y_mm_(model.reference_y_mm),
      centroid_y_mm_(model.centroid_y_mm) {
  undistorted_radius_mm(model, 0.0);  // throws if ybar_h does not increase
}

void BoxDistortion::map_point(double x, double y, bool forward, double& x_out,
                              double& y_out) const {
  const double dx = x - geometry_.axis_x, dy = y - geometry_.axis_y;
  const double r = geometry_.pitch_mm * std::sqrt(dx * dx + dy * dy);
  const std::vector<double>& from = forward ? reference_y_mm_ : centroid_y_mm_;
  const std::vector<double>& to = forward ? centroid_y_mm_ : reference_y_mm_;
  double scale;
  if (r > 1e-12) {
    scale = interpolate_linear(from, to, r, true) / r;
  } else {  // the radial scale of the first piece at the axis
    scale = from.size() > 1 ? (to[1] - to[0]) / (from[1] - from[0]) : 1.0;
  }
  x_out = geometry_.axis_x + dx * scale;
  y_out = geometry_.axis_y + dy * scale;
}

void BoxDistortion::distort(double x, double y, double& x_out, double& y_out) const {
  map_point(x, y, true, x_out, y_out);
}

void BoxDistortion::undistort(double x, double y, double& x_out, double& y_out) const {
  map_point(x, y, false, x_out, y_out);
}

Box BoxDistortion::map_box(const Box& box, bool forward) const {
  const double xm = 0.5 * (box.x0 + box.x1), ym = 0.5 * (box.y0 + box.y1);
  const double px[4] = {xm, xm, box.x0, box.x1};
  const double py[4] = {box.y0, box.y1, ym, ym};
  Box out{INFINITY, INFINITY, -INFINITY, -INFINITY};
  for (int k = 0; k < 4; ++k) {
    double x, y;
    map_point(px[k], py[k], forward, x, y);
    out.x0 = std::min(out.x0, x);
    out.y0 = std::min(out.y0, y);
    out.x1 = std::max(out.x1, x);
    out.y1 = std::max(out.y1, y);
  }
  return out;
}

Box BoxDistortion::distort_box(const Box& box) const {
  return map_box(box, true);
}
Box BoxDistortion::undistort_box(const Box& box) const {
  return map_box(box, false);
}

}  // namespace lensopt
