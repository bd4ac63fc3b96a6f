#include "lensopt/render/metrics.h"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "lensopt/core/error.h"

namespace lensopt {
namespace {

void check_same_size(const FloatImage& x, const FloatImage& y, int channels) {
  if (x.width != y.width || x.height != y.height || channels > x.channels ||
      channels > y.channels || channels < 1 || x.empty()) {
    throw Error(fmt::format("cannot compare a {}x{}x{} image with a {}x{}x{} one over {} channels",
                            x.width, x.height, x.channels, y.width, y.height, y.channels,
                            channels));
  }
}

int thread_count(int threads) {
  return threads > 0 ? threads : omp_get_max_threads();
}

// Normalized Gaussian weights of an odd window of `size` taps.
std::vector<double> gaussian_window(int size, double sigma) {
  std::vector<double> w(size);
  const int half = size / 2;
  double sum = 0;
  for (int i = 0; i < size; ++i) sum += std::exp(-0.5 * (i - half) * (i - half) / (sigma * sigma));
  for (int i = 0; i < size; ++i)
    w[i] = std::exp(-0.5 * (i - half) * (i - half) / (sigma * sigma)) / sum;
  return w;
}

// The hot loops, compiled for AVX2/FMA as well as the baseline (picked at run time), written
// with contiguous inner loops so they vectorize.
// Horizontal pass of one row: planes (5 x width scratch) <- x, y, x^2, y^2, xy; slot (5 x out_w)
// <- their Gaussian-weighted sums over `taps` columns.
__attribute__((target_clones("arch=x86-64-v3", "default"))) void ssim_horizontal(
    const float* xr, int x_stride, const float* yr, int y_stride, int width, const double* g,
    int taps, double* planes, double* slot, int out_w) {
  for (int col = 0; col < width; ++col) {
    const double a = xr[static_cast<std::size_t>(col) * x_stride];
    const double b = yr[static_cast<std::size_t>(col) * y_stride];
    planes[col] = a;
    planes[width + col] = b;
    planes[2 * width + col] = a * a;
    planes[3 * width + col] = b * b;
    planes[4 * width + col] = a * b;
  }
  for (int q = 0; q < 5; ++q) {
    double* dst = slot + static_cast<std::size_t>(q) * out_w;
    const double* src = planes + static_cast<std::size_t>(q) * width;
    for (int col = 0; col < out_w; ++col) dst[col] = 0.0;
    for (int k = 0; k < taps; ++k) {
      const double w = g[k];
      for (int col = 0; col < out_w; ++col) dst[col] += w * src[col + k];
    }
  }
}

// Vertical pass of output row `row` over the ring of horizontal sums, and the sum of SSIM over
// the row. m is 5 x out_w scratch.
__attribute__((target_clones("arch=x86-64-v3", "default"))) double ssim_row(const double* ring,
                                                                            int row, int taps,
                                                                            const double* g,
                                                                            int out_w, double* m) {
  constexpr double kC1 = 0.01 * 0.01;
  constexpr double kC2 = 0.03 * 0.03;
  const int n = 5 * out_w;
  for (int i = 0; i < n; ++i) m[i] = 0.0;
  for (int k = 0; k < taps; ++k) {
    const double* slot = ring + static_cast<std::size_t>((row + k) % taps) * n;
    const double w = g[k];
    for (int i = 0; i < n; ++i) m[i] += w * slot[i];
  }
  const double* mx = m;
  const double* my = mx + out_w;
  const double* mxx = my + out_w;
  const double* myy = mxx + out_w;
  const double* mxy = myy + out_w;
  double sum = 0;
  for (int col = 0; col < out_w; ++col) {
    const double vx = mxx[col] - mx[col] * mx[col], vy = myy[col] - my[col] * my[col];
    const double cxy = mxy[col] - mx[col] * my[col];
    sum += ((2 * mx[col] * my[col] + kC1) * (2 * cxy + kC2)) /
           ((mx[col] * mx[col] + my[col] * my[col] + kC1) * (vx + vy + kC2));
  }
  return sum;
}

int window_size(int extent) {
  const int size = std::min(11, extent);
  return size % 2 == 1 ? size : size - 1;
}

}  // namespace

double psnr_db(const FloatImage& x, const FloatImage& y, int channels, int threads) {
  check_same_size(x, y, channels);
  const std::size_t pixels = static_cast<std::size_t>(x.width) * x.height;
  double sum = 0;
#pragma omp parallel for reduction(+ : sum) num_threads(thread_count(threads)) schedule(static)
  for (std::ptrdiff_t p = 0; p < static_cast<std::ptrdiff_t>(pixels); ++p) {
    for (int c = 0; c < channels; ++c) {
      const double d = static_cast<double>(x.pixels[p * x.channels + c]) -
                       static_cast<double>(y.pixels[p * y.channels + c]);
      sum += d * d;
    }
  }
  const double mse = sum / (static_cast<double>(pixels) * channels);
  if (mse <= 0.0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(1.0 / mse);
}

double ssim(const FloatImage& x, const FloatImage& y, int channels, int threads) {
  check_same_size(x, y, channels);
  constexpr double kSigma = 1.5;
  const int width = x.width;
  const int height = x.height;
  const int wx = window_size(width);
  const int wy = window_size(height);
  const std::vector<double> gx = gaussian_window(wx, kSigma);
  const std::vector<double> gy = gaussian_window(wy, kSigma);
  const int out_w = width - wx + 1;  // positions where the window lies inside the image
  const int out_h = height - wy + 1;
  const int nthreads = std::min(thread_count(threads), out_h);
  // Per output row, the horizontal pass of x, y, x^2, y^2, xy over the wy rows under the window,
  // kept in a ring of wy rows (per thread), then the vertical pass. In double: the variances are
  // differences of nearly equal second moments.
  double total = 0;
  for (int c = 0; c < channels; ++c) {
    double channel_sum = 0;
#pragma omp parallel num_threads(nthreads) reduction(+ : channel_sum)
    {
      const int t = omp_get_thread_num(), nt = omp_get_num_threads();
      const int r0 = static_cast<int>(static_cast<long>(out_h) * t / nt);
      const int r1 = static_cast<int>(static_cast<long>(out_h) * (t + 1) / nt);
      std::vector<double> ring(static_cast<std::size_t>(wy) * 5 * out_w);
      std::vector<double> planes(static_cast<std::size_t>(5) * width);
      std::vector<double> m(static_cast<std::size_t>(5) * out_w);
      auto horizontal = [&](int row) {
        const std::size_t offset = static_cast<std::size_t>(row) * width;
        ssim_horizontal(x.pixels.data() + offset * x.channels + c, x.channels,
                        y.pixels.data() + offset * y.channels + c, y.channels, width, gx.data(), wx,
                        planes.data(), ring.data() + static_cast<std::size_t>(row % wy) * 5 * out_w,
                        out_w);
      };
      if (r0 < r1)
        for (int row = r0; row < r0 + wy - 1; ++row) horizontal(row);
      for (int row = r0; row < r1; ++row) {
        horizontal(row + wy - 1);
        channel_sum += ssim_row(ring.data(), row, wy, gy.data(), out_w, m.data());
      }
    }
    total += channel_sum / (static_cast<double>(out_w) * out_h);
  }
  return total / channels;
}

}  // namespace lensopt
