// Relative illumination and the distortion warp.
//
// The warp samples by hand with the Keys cubic (a = -1/2, "bicubic"), the same kernel as
// OpenImageIO's "catmull-rom" filter: ImageBufAlgo::st_warp gives the same values (the unit test
// compares them) but takes 0.8 s per 1280 x 720 RGB image on one core, most of the 1 s budget of
// a whole render; this loop takes a few milliseconds.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "lensopt/render/render.h"

namespace lensopt {
namespace {

int thread_count(int threads) { return threads > 0 ? threads : omp_get_max_threads(); }

// Keys cubic convolution weights (a = -1/2) of the taps at -1, 0, 1, 2 for a fraction t.
inline void keys_weights(double t, double w[4]) {
  const double t2 = t * t, t3 = t2 * t;
  w[0] = -0.5 * t3 + t2 - 0.5 * t;
  w[1] = 1.5 * t3 - 2.5 * t2 + 1.0;
  w[2] = -1.5 * t3 + 2.0 * t2 + 0.5 * t;
  w[3] = 0.5 * t3 - 0.5 * t2;
}

}  // namespace

void Renderer::apply_relative_illumination(FloatImage& image, int threads) const {
  const SensorGeometry geo = SensorGeometry::make(image.width, image.height, options_.res_factor,
                                                  model_.sensor_diagonal_mm);
  const int colours = colour_channel_count(image.channels);
#pragma omp parallel for num_threads(thread_count(threads > 0 ? threads : options_.threads)) \
    schedule(static)
  for (int j = 0; j < image.height; ++j) {
    for (int i = 0; i < image.width; ++i) {
      const float ri = static_cast<float>(relative_illumination_at(model_, geo.radius_mm(i, j)));
      for (int c = 0; c < colours; ++c) image.at(i, j, c) *= ri;
    }
  }
}

FloatImage Renderer::apply_distortion(const FloatImage& image, int threads) const {
  const int width = image.width, height = image.height, channels = image.channels;
  const SensorGeometry geo =
      SensorGeometry::make(width, height, options_.res_factor, model_.sensor_diagonal_mm);
  // The inverse map r(r') through (ybar_h, y_ref,h); undistorted_radius_mm throws (here, outside
  // the parallel loop) if it is not invertible.
  const std::vector<double>& ybar = model_.centroid_y_mm;
  const std::vector<double>& yref = model_.reference_y_mm;
  const int nodes = static_cast<int>(ybar.size());
  undistorted_radius_mm(model_, 0.0);
  auto inverse = [&](double r_out) {
    if (nodes == 1) return r_out;
    const int k = std::clamp(
        static_cast<int>(std::upper_bound(ybar.begin(), ybar.end(), r_out) - ybar.begin()) - 1, 0,
        nodes - 2);
    return yref[k] + (r_out - ybar[k]) * (yref[k + 1] - yref[k]) / (ybar[k + 1] - ybar[k]);
  };
  // Radial scale r / r' near the axis (the first piece of the inverse map).
  const double axis_scale = nodes > 1 ? (yref[1] - yref[0]) / (ybar[1] - ybar[0]) : 1.0;
  FloatImage out(width, height, channels, 0.0f);
  const float* src = image.pixels.data();
  float* dst_pixels = out.pixels.data();
  // One output pixel, with the channel count as a template constant where it is small.
  auto sample = [&](auto channel_count, int i, int j) {
    constexpr int kFixed = decltype(channel_count)::value;
    const int nc = kFixed > 0 ? kFixed : channels;
    const double dx = i + 0.5 - geo.axis_x, dy = j + 0.5 - geo.axis_y;
    const double r_out = geo.pitch_mm * std::sqrt(dx * dx + dy * dy);
    const double scale = r_out > 1e-12 ? inverse(r_out) / r_out : axis_scale;
    const double sx = geo.axis_x + dx * scale, sy = geo.axis_y + dy * scale;
    if (!(sx >= 0.0 && sx <= width && sy >= 0.0 && sy <= height)) return;  // black
    // Bicubic: pixel centres at k + 1/2, taps clamped to the image.
    const double u = sx - 0.5, v = sy - 0.5;
    const int x0 = static_cast<int>(std::floor(u)), y0 = static_cast<int>(std::floor(v));
    double wx[4], wy[4];
    keys_weights(u - x0, wx);
    keys_weights(v - y0, wy);
    int xs[4];
    for (int k = 0; k < 4; ++k) xs[k] = std::clamp(x0 - 1 + k, 0, width - 1) * nc;
    double acc[kFixed > 0 ? kFixed : 16] = {};
    for (int c0 = 0; c0 < nc; c0 += 16) {  // channels in blocks of 16 (only for many channels)
      const int cn = std::min(16, nc - c0);
      for (int c = 0; c < cn; ++c) acc[c] = 0.0;
      for (int m = 0; m < 4; ++m) {
        const int y = std::clamp(y0 - 1 + m, 0, height - 1);
        const float* row = src + static_cast<std::size_t>(y) * width * nc + c0;
        for (int k = 0; k < 4; ++k) {
          const double w = wy[m] * wx[k];
          const float* p = row + xs[k];
          for (int c = 0; c < cn; ++c) acc[c] += w * p[c];
        }
      }
      float* d = dst_pixels + (static_cast<std::size_t>(j) * width + i) * nc + c0;
      for (int c = 0; c < cn; ++c) d[c] = static_cast<float>(acc[c]);
    }
  };
#pragma omp parallel for num_threads(thread_count(threads > 0 ? threads : options_.threads)) \
    schedule(static)
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      switch (channels) {
        case 1: sample(std::integral_constant<int, 1>(), i, j); break;
        case 3: sample(std::integral_constant<int, 3>(), i, j); break;
        case 4: sample(std::integral_constant<int, 4>(), i, j); break;
        default: sample(std::integral_constant<int, 0>(), i, j); break;
      }
    }
  }
  return out;
}

}  // namespace lensopt
