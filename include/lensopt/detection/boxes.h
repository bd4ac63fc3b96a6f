// Bounding boxes through the image formation: crops, the simulated resolution factor, and the
// lens's distortion (the paper's section "Lens Distortion in Object Detection").
//
// Coordinates. A box is (x0, y0, x1, y1) in continuous pixel coordinates of its image: x grows to
// the right, y downwards, pixel (i, j) covers [i, i + 1) x [j, j + 1), so pixel centres are at
// (i + 1/2, j + 1/2) as in render/render.h's SensorGeometry. COCO's [x, y, w, h] is
// (x0, y0, x1 - x0, y1 - y0). Area = (x1 - x0)(y1 - y0) pixels^2.
//
// Crop. A crop window (x0c, y0c, w, h) moves a box by (-x0c, -y0c) and clips it to [0, w] x
// [0, h]. The clipped box is dropped when it is too small to be an object (either side below
// `min_side_px`, 2 px by default) or when less than `min_visible_fraction` (1/4 by default) of
// its area lies inside the crop: a box mostly cut away would ask the detector to find an object
// from a sliver.
//
// Resolution factor (render/render.h's model). At factor s = 2 an image of W x H pixels is the
// upper-left quadrant of a virtual 2W x 2H sensor of the same diagonal: the scene's pixels are the
// image's pixels (pitch halved, the optical axis at the image's bottom-right corner), so a box
// keeps its pixel coordinates and the factor enters through the geometry of the distortion
// (BoxDistortion's `res_factor`; the PSFs cover twice as many pixels). `scale_box` is the map for
// a pipeline that instead enlarges the scene s times (coordinates times s).
//
// Distortion. The renderer's warp moves the scene point at undistorted radial height r (mm on the
// sensor, from the optical axis) to r' = ybar(r), the piecewise-linear map through the nodes
// (y_ref,h, ybar_h) of the imaging model (render/model.cpp), along the same azimuth:
//   p' = a + (p - a) r'(r) / r,   r = pitch |p - a|,  a = the axis in pixels.
// The paper corrects ground-truth boxes "by shifting the midpoint of each bounding box segment,
// then drawing a new bounding box around the shifted coordinates": the four edge midpoints
// (x_mid, y0), (x_mid, y1), (x0, y_mid), (x1, y_mid) are mapped by p -> p', and the new box is
// their bounding box. The inverse correction of predicted boxes does the same with p' -> p
// (r = ybar^-1(r')). Both keep boxes where a straight edge stays nearly straight (the midpoint is
// the extreme point of a barrel- or pincushion-bent edge on the side away from the axis).
#pragma once

#include <optional>
#include <vector>

#include "lensopt/render/render.h"

namespace lensopt {

struct Box {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // pixels (see the header)

  double width() const { return x1 - x0; }
  double height() const { return y1 - y0; }
  double area() const;  // 0 for an empty box
  bool empty() const { return !(x1 > x0 && y1 > y0); }
};

// Intersection over union; 0 when either box is empty.
double iou(const Box& a, const Box& b);
// Intersection area over the area of `b` (COCO's overlap with a crowd box b); 0 if b is empty.
double intersection_over_second(const Box& a, const Box& b);

struct CropRule {
  double min_side_px = 2.0;            // drop if the clipped box is narrower or lower
  double min_visible_fraction = 0.25;  // drop if less of the box's area lies in the crop
};

// The box in the crop's coordinates, clipped; nullopt when the rule drops it.
std::optional<Box> crop_box(const Box& box, double crop_x0, double crop_y0, double crop_width,
                            double crop_height, const CropRule& rule = {});

// A scene box at resolution factor s (coordinates times s), before any crop.
Box scale_box(const Box& box, double factor);

// The lens's distortion as a map of pixel positions of one image size (see the header).
class BoxDistortion {
 public:
  // Throws Error if the model's distortion is not invertible (render/model.cpp's rule).
  BoxDistortion(const ImagingModel& model, int width, int height, int res_factor);

  // Where the scene point at pixel position (x, y) appears in the distorted image.
  void distort(double x, double y, double& x_out, double& y_out) const;
  // Where a point of the distorted image came from (the inverse of distort).
  void undistort(double x, double y, double& x_out, double& y_out) const;

  // The paper's correction of a ground-truth box (edge midpoints mapped, box redrawn).
  Box distort_box(const Box& box) const;
  // The inverse correction of a predicted box.
  Box undistort_box(const Box& box) const;

  const SensorGeometry& geometry() const { return geometry_; }

 private:
  void map_point(double x, double y, bool forward, double& x_out, double& y_out) const;
  Box map_box(const Box& box, bool forward) const;

  SensorGeometry geometry_;
  std::vector<double> reference_y_mm_;  // y_ref,h
  std::vector<double> centroid_y_mm_;   // ybar_h
};

}  // namespace lensopt
