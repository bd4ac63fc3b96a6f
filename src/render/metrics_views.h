// PSNR and SSIM (render/metrics.h) over channel views: the Renderer computes them from its blur's
// planar accumulator (one plane per colour channel) without interleaving it first. An internal
// header of the render module.
#pragma once

#include <cstddef>

#include "lensopt/render/image.h"

namespace lensopt {

// Channel c of pixel (col, row) is data[row row_stride + col col_stride + c channel_stride].
struct ChannelView {
  const float* data = nullptr;
  std::size_t row_stride = 0, col_stride = 0, channel_stride = 0;

  // An interleaved image.
  static ChannelView of(const FloatImage& image) {
    return {image.pixels.data(), static_cast<std::size_t>(image.width) * image.channels,
            static_cast<std::size_t>(image.channels), 1};
  }
  // Planes of width x height floats, one after the other.
  static ChannelView planar(const float* planes, int width, int height) {
    return {planes, static_cast<std::size_t>(width), 1,
            static_cast<std::size_t>(width) * static_cast<std::size_t>(height)};
  }
};

// As psnr_db and ssim of two width x height images over `channels` channels (sizes not checked).
double psnr_db(const ChannelView& x, const ChannelView& y, int width, int height, int channels,
               int threads);
double ssim(const ChannelView& x, const ChannelView& y, int width, int height, int channels,
            int threads);

}  // namespace lensopt
