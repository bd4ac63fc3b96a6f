// The inverse distortion map of the warp (render/render.h), shared by the Renderer
// (src/render/warp.cpp) and the joint optimization's differentiable rendering
// (src/joint/imaging.cpp, which adds its derivative). The output pixel (i, j) at radial height
// r' = pitch |c - a| (c = (i + 1/2, j + 1/2) its centre, a the optical axis, pixels) samples the
// undistorted image at
//   s = a + (c - a) rho(r') / r',   rho = interp((ybar_h, y_ref,h), r') (extended with the end
// pieces), the inverse of r' = r + D(r) y_ref,last; on the axis (r' < 1e-12 mm) the scale
// rho / r' is the first piece's slope (y_ref,1 - y_ref,0) / (ybar_1 - ybar_0). A sample outside
// [0, W] x [0, H] is black (the scene there was not captured). With a single node (a lens whose
// only field is on axis) the distortion is unknown and the map is the identity (rho = r'): one
// node would otherwise send every pixel to the axis and render a constant image.
#pragma once

#include <cmath>
#include <vector>

#include "lensopt/core/interpolate.h"
#include "lensopt/render/render.h"

namespace lensopt {

class InverseDistortion {
 public:
  // The nodes (ybar_h, y_ref,h), mm; ybar_h must increase (the callers check it, naming the
  // fields). Both vectors must outlive this object.
  InverseDistortion(const std::vector<double>& centroid_y_mm,
                    const std::vector<double>& reference_y_mm)
      : ybar_(centroid_y_mm),
        yref_(reference_y_mm),
        axis_scale_(centroid_y_mm.size() > 1 ? (reference_y_mm[1] - reference_y_mm[0]) /
                                                   (centroid_y_mm[1] - centroid_y_mm[0])
                                             : 1.0) {}

  // The sample position s (pixels, origin at the image's top-left corner) of output pixel
  // (i, j) of the image `geo`; false if it falls outside the image (black).
  bool source(const SensorGeometry& geo, int i, int j, double& sx, double& sy) const {
    const double dx = i + 0.5 - geo.axis_x, dy = j + 0.5 - geo.axis_y;
    const double r_out = geo.pitch_mm * std::sqrt(dx * dx + dy * dy);
    const double scale = ybar_.size() < 2 ? 1.0
                         : r_out > 1e-12  ? interpolate_linear(ybar_, yref_, r_out, true) / r_out
                                          : axis_scale_;
    sx = geo.axis_x + dx * scale;
    sy = geo.axis_y + dy * scale;
    return sx >= 0.0 && sx <= geo.width && sy >= 0.0 && sy <= geo.height;
  }

 private:
  const std::vector<double>& ybar_;
  const std::vector<double>& yref_;
  double axis_scale_;
};

}  // namespace lensopt
