#include "lensopt/render/metrics.h"

#include <fmt/format.h>
#include <omp.h>

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

int thread_count(int threads) { return threads > 0 ? threads : omp_get_max_threads(); }

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
  constexpr double kC1 = 0.01 * 0.01;
  constexpr double kC2 = 0.03 * 0.03;
  const int width = x.width;
  const int height = x.height;
  const int wx = window_size(width);
  const int wy = window_size(height);
  const std::vector<double> gx = gaussian_window(wx, kSigma);
  const std::vector<double> gy = gaussian_window(wy, kSigma);
  const int out_w = width - wx + 1;  // positions where the window lies inside the image
  const int out_h = height - wy + 1;
  const int nthreads = thread_count(threads);
  double total = 0;
  // Horizontal pass of x, y, x^2, y^2, xy into five height x out_w maps; vertical pass per row.
  // In double: the variances are differences of nearly equal second moments.
  std::vector<double> h[5];
  for (auto& m : h) m.resize(static_cast<std::size_t>(height) * out_w);
  for (int c = 0; c < channels; ++c) {
#pragma omp parallel for num_threads(nthreads) schedule(static)
    for (int row = 0; row < height; ++row) {
      for (int col = 0; col < out_w; ++col) {
        double s[5] = {0, 0, 0, 0, 0};
        for (int k = 0; k < wx; ++k) {
          const double a = x.at(col + k, row, c);
          const double b = y.at(col + k, row, c);
          const double g = gx[k];
          s[0] += g * a;
          s[1] += g * b;
          s[2] += g * a * a;
          s[3] += g * b * b;
          s[4] += g * a * b;
        }
        const std::size_t i = static_cast<std::size_t>(row) * out_w + col;
        for (int m = 0; m < 5; ++m) h[m][i] = s[m];
      }
    }
    double channel_sum = 0;
#pragma omp parallel for num_threads(nthreads) reduction(+ : channel_sum) schedule(static)
    for (int row = 0; row < out_h; ++row) {
      for (int col = 0; col < out_w; ++col) {
        double s[5] = {0, 0, 0, 0, 0};
        for (int k = 0; k < wy; ++k) {
          const std::size_t i = static_cast<std::size_t>(row + k) * out_w + col;
          for (int m = 0; m < 5; ++m) s[m] += gy[k] * h[m][i];
        }
        const double mx = s[0], my = s[1];
        const double vx = s[2] - mx * mx, vy = s[3] - my * my, cxy = s[4] - mx * my;
        channel_sum += ((2 * mx * my + kC1) * (2 * cxy + kC2)) /
                       ((mx * mx + my * my + kC1) * (vx + vy + kC2));
      }
    }
    total += channel_sum / (static_cast<double>(out_w) * out_h);
  }
  return total / channels;
}

}  // namespace lensopt
