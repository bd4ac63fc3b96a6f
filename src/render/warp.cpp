// Relative illumination and the distortion warp.
//
// Both depend on a pixel's radius only; their per-pixel maps (the factor, the warp's source
// offset) are made once per image size and cached. The warp samples by hand with the Keys cubic
// (a = -1/2, "bicubic"), the same kernel as OpenImageIO's "catmull-rom" filter:
// ImageBufAlgo::st_warp gives the same values (the unit test compares them) but takes 0.8 s per
// 1280 x 720 RGB image on one core, most of the 1 s budget of a whole render; this loop takes a
// few milliseconds.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "lensopt/core/interpolate.h"
#include "lensopt/core/threads.h"
#include "lensopt/render/distortion_warp.h"
#include "lensopt/render/render.h"
#include "render/huge_pages.h"

namespace lensopt {
namespace {

// One output row of the warp: pixel i samples the input at (i + 1/2 + offset_x, j + 1/2 +
// offset_y) bicubically (taps clamped to the image); NaN offsets give black. The channel count
// is a template constant where it is small (NC = 0: any, from `channels`).
template <int NC>
__attribute__((target_clones("arch=x86-64-v3", "default"))) void warp_row(const float* src,
                                                                          int width, int height,
                                                                          int channels,
                                                                          const float* offsets,
                                                                          int j, float* dst) {
  const int nc = NC > 0 ? NC : channels;
  for (int i = 0; i < width; ++i) {
    const float ox = offsets[2 * i], oy = offsets[2 * i + 1];
    float* d = dst + static_cast<std::size_t>(i) * nc;
    if (std::isnan(ox)) {
      for (int c = 0; c < nc; ++c) d[c] = 0.0f;
      continue;
    }
    const double u = i + static_cast<double>(ox), v = j + static_cast<double>(oy);
    const int x0 = static_cast<int>(std::floor(u)), y0 = static_cast<int>(std::floor(v));
    double wx[4], wy[4];
    keys_weights(u - x0, wx);
    keys_weights(v - y0, wy);
    int xs[4];
    for (int k = 0; k < 4; ++k) xs[k] = std::clamp(x0 - 1 + k, 0, width - 1) * nc;
    for (int c0 = 0; c0 < nc; c0 += 16) {  // channels in blocks of 16 (only for many channels)
      const int cn = std::min(16, nc - c0);
      double acc[NC > 0 ? NC : 16] = {};
      for (int m = 0; m < 4; ++m) {
        const int y = std::clamp(y0 - 1 + m, 0, height - 1);
        const float* row = src + static_cast<std::size_t>(y) * width * nc + c0;
        for (int k = 0; k < 4; ++k) {
          const double w = wy[m] * wx[k];
          const float* p = row + xs[k];
          for (int c = 0; c < cn; ++c) acc[c] += w * p[c];
        }
      }
      for (int c = 0; c < cn; ++c) d[c0 + c] = static_cast<float>(acc[c]);
    }
  }
}

}  // namespace

void Renderer::illumination_row(const SensorGeometry& geo, int j, float* factor) const {
  for (int i = 0; i < geo.width; ++i)
    factor[i] = static_cast<float>(relative_illumination_at(model_, geo.radius_mm(i, j)));
}

void Renderer::warp_row_offsets(const SensorGeometry& geo, int j, float* offsets) const {
  const InverseDistortion inverse(model_.centroid_y_mm, model_.reference_y_mm);
  constexpr float kOutside = std::numeric_limits<float>::quiet_NaN();
  for (int i = 0; i < geo.width; ++i) {
    float* o = offsets + static_cast<std::size_t>(i) * 2;
    double sx, sy;
    if (inverse.source(geo, i, j, sx, sy)) {
      // Stored as the sample position minus the pixel's corner (i, j), minus 1/2 (so the taps
      // are at floor(i + offset) - 1 ...): small numbers, exact in float to 1e-5 pixel.
      o[0] = static_cast<float>(sx - 0.5 - i);
      o[1] = static_cast<float>(sy - 0.5 - j);
    } else {
      o[0] = o[1] = kOutside;  // black: the scene there was not captured
    }
  }
}

std::shared_ptr<const std::vector<float>> Renderer::illumination_map(int width, int height) const {
  std::lock_guard<std::mutex> lock(mutex_);
  require_relative_illumination(model_);  // here, not inside the parallel loops
  if (auto found = illumination_maps_.find(width, height)) return found;
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  if (pixels * sizeof(float) > kMapBudgetBytes) return nullptr;
  const SensorGeometry geo =
      SensorGeometry::make(width, height, options_.res_factor, model_.sensor_diagonal_mm);
  auto map = std::make_shared<std::vector<float>>(pixels);
#pragma omp parallel for num_threads(thread_count(options_.threads)) schedule(static)
  for (int j = 0; j < height; ++j)
    illumination_row(geo, j, map->data() + static_cast<std::size_t>(j) * width);
  illumination_maps_.insert(width, height, map);
  return map;
}

std::shared_ptr<const std::vector<float>> Renderer::warp_map(int width, int height) const {
  std::lock_guard<std::mutex> lock(mutex_);
  // The inverse map (render/distortion_warp.h); undistorted_radius_mm throws (here, outside the
  // parallel loops) if it is not invertible.
  undistorted_radius_mm(model_, 0.0);
  if (auto found = warp_maps_.find(width, height)) return found;
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  if (pixels * 2 * sizeof(float) > kMapBudgetBytes) return nullptr;
  const SensorGeometry geo =
      SensorGeometry::make(width, height, options_.res_factor, model_.sensor_diagonal_mm);
  auto map = std::make_shared<std::vector<float>>(pixels * 2);
#pragma omp parallel for num_threads(thread_count(options_.threads)) schedule(static)
  for (int j = 0; j < height; ++j)
    warp_row_offsets(geo, j, map->data() + static_cast<std::size_t>(j) * width * 2);
  warp_maps_.insert(width, height, map);
  return map;
}

void Renderer::apply_relative_illumination(FloatImage& image, int threads) const {
  const std::shared_ptr<const std::vector<float>> map = illumination_map(image.width, image.height);
  const int colours = colour_channel_count(image.channels);
  const int width = image.width, channels = image.channels;
  const SensorGeometry geo = SensorGeometry::make(image.width, image.height, options_.res_factor,
                                                  model_.sensor_diagonal_mm);
#pragma omp parallel num_threads(thread_count(threads > 0 ? threads : options_.threads))
  {
    std::vector<float> row(map ? 0 : width);  // a row's factors when the map is not kept
#pragma omp for schedule(static)
    for (int j = 0; j < image.height; ++j) {
      const float* __restrict factor;
      if (map) {
        factor = map->data() + static_cast<std::size_t>(j) * width;
      } else {
        illumination_row(geo, j, row.data());
        factor = row.data();
      }
      float* __restrict out = image.pixels.data() + static_cast<std::size_t>(j) * width * channels;
      for (int i = 0; i < width; ++i) {
        const float ri = factor[i];
        for (int c = 0; c < colours; ++c) out[static_cast<std::size_t>(i) * channels + c] *= ri;
      }
    }
  }
}

FloatImage Renderer::apply_distortion(const FloatImage& image, int threads) const {
  FloatImage out;
  warp_into(image, out, thread_count(threads > 0 ? threads : options_.threads));
  return out;
}

void Renderer::warp_into(const FloatImage& image, FloatImage& out, int nthreads) const {
  const int width = image.width, height = image.height, channels = image.channels;
  const std::shared_ptr<const std::vector<float>> map = warp_map(width, height);
  const SensorGeometry geo =
      SensorGeometry::make(width, height, options_.res_factor, model_.sensor_diagonal_mm);
  out.width = width;
  out.height = height;
  out.channels = channels;
  // warp_row writes every value (black where the source is outside): memory of the right size
  // is reused as it is.
  const std::size_t values = static_cast<std::size_t>(width) * height * channels;
  if (out.pixels.size() != values) resize_with_huge_pages(out.pixels, values);
#pragma omp parallel num_threads(nthreads)
  {
    std::vector<float> row(map ? 0 : static_cast<std::size_t>(width) * 2);
#pragma omp for schedule(static)
    for (int j = 0; j < height; ++j) {
      const float* offsets;
      if (map) {
        offsets = map->data() + static_cast<std::size_t>(j) * width * 2;
      } else {
        warp_row_offsets(geo, j, row.data());
        offsets = row.data();
      }
      float* dst = out.pixels.data() + static_cast<std::size_t>(j) * width * channels;
      const float* src = image.pixels.data();
      switch (channels) {
        case 1:
          warp_row<1>(src, width, height, channels, offsets, j, dst);
          break;
        case 3:
          warp_row<3>(src, width, height, channels, offsets, j, dst);
          break;
        case 4:
          warp_row<4>(src, width, height, channels, offsets, j, dst);
          break;
        default:
          warp_row<0>(src, width, height, channels, offsets, j, dst);
          break;
      }
    }
  }
}

}  // namespace lensopt
