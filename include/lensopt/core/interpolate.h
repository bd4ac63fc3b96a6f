// Piecewise-linear interpolation through nodes (x_k, y_k), x increasing, and its partial
// derivatives with respect to the nodes (for adjoints: the node values carry the derivatives).
//
// With k the piece holding x (x_k <= x < x_{k+1}) and t = (x - x_k) / (x_{k+1} - x_k):
//   y(x) = y_k + t (y_{k+1} - y_k).
// Outside [x_0, x_last] the value is clamped to the end value (extrapolate = false) or the first
// / last piece is extended (extrapolate = true). One node: y_0 everywhere.
// Partials (inside a piece): dy/dy_k = 1 - t, dy/dy_{k+1} = t,
//   dy/dx_k = (y_{k+1} - y_k) (t - 1) / (x_{k+1} - x_k),  dy/dx_{k+1} = -(y_{k+1} - y_k) t /
//   (x_{k+1} - x_k), dy/dx = (y_{k+1} - y_k) / (x_{k+1} - x_k).
// Clamped: dy/dy_end = 1, all else 0.
//
// Cubic convolution (Keys 1981, a = -1/2; "bicubic", OpenImageIO's "catmull-rom"): a sample at
// fraction t in [0, 1) past tap 0 weighs the taps at -1, 0, 1, 2 by
//   w_-1 = -t^3/2 + t^2 - t/2,  w_0 = 3t^3/2 - 5t^2/2 + 1,  w_1 = -3t^3/2 + 2t^2 + t/2,
//   w_2 = t^3/2 - t^2/2,
// and dw/dt = (-3t^2/2 + 2t - 1/2, 9t^2/2 - 5t, -9t^2/2 + 4t + 1/2, 3t^2/2 - t). The kernel is C1,
// so a sample's value is continuously differentiable in its position (also across taps).
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

namespace lensopt {

// The piece of x and its partial derivatives (see the header).
struct LinearPiece {
  int k = 0;                  // first node of the piece (k and k + 1 carry the partials)
  double value = 0;           // y(x)
  double d_y0 = 0, d_y1 = 0;  // d y / d y_k, d y / d y_{k+1}
  double d_x0 = 0, d_x1 = 0;  // d y / d x_k, d y / d x_{k+1}
  double d_x = 0;             // d y / d x
};

inline LinearPiece linear_piece(const std::vector<double>& xs, const std::vector<double>& ys,
                                double x, bool extrapolate) {
  LinearPiece p;
  const std::size_t n = xs.size();
  if (n == 1) {
    p.value = ys[0];
    p.d_y0 = 1;
    return p;
  }
  std::size_t k;
  if (x <= xs.front()) {
    if (!extrapolate) {
      p.value = ys.front();
      p.d_y0 = 1;
      return p;
    }
    k = 0;
  } else if (x >= xs.back()) {
    if (!extrapolate) {
      p.k = static_cast<int>(n - 2);
      p.value = ys.back();
      p.d_y1 = 1;
      return p;
    }
    k = n - 2;
  } else {
    k = static_cast<std::size_t>(std::upper_bound(xs.begin(), xs.end(), x) - xs.begin()) - 1;
  }
  const double dx = xs[k + 1] - xs[k];
  const double dy = ys[k + 1] - ys[k];
  const double t = (x - xs[k]) / dx;
  p.k = static_cast<int>(k);
  p.value = ys[k] + t * dy;
  p.d_y0 = 1 - t;
  p.d_y1 = t;
  p.d_x0 = dy * (t - 1) / dx;
  p.d_x1 = -dy * t / dx;
  p.d_x = dy / dx;
  return p;
}

// y(x) alone.
inline double interpolate_linear(const std::vector<double>& xs, const std::vector<double>& ys,
                                 double x, bool extrapolate) {
  return linear_piece(xs, ys, x, extrapolate).value;
}

// Keys cubic weights of the taps at -1, 0, 1, 2 for a fraction t.
inline void keys_weights(double t, double w[4]) {
  const double t2 = t * t, t3 = t2 * t;
  w[0] = -0.5 * t3 + t2 - 0.5 * t;
  w[1] = 1.5 * t3 - 2.5 * t2 + 1.0;
  w[2] = -1.5 * t3 + 2.0 * t2 + 0.5 * t;
  w[3] = 0.5 * t3 - 0.5 * t2;
}

// Their derivatives d w / d t.
inline void keys_weight_derivatives(double t, double dw[4]) {
  const double t2 = t * t;
  dw[0] = -1.5 * t2 + 2.0 * t - 0.5;
  dw[1] = 4.5 * t2 - 5.0 * t;
  dw[2] = -4.5 * t2 + 4.0 * t + 0.5;
  dw[3] = 1.5 * t2 - t;
}

}  // namespace lensopt
