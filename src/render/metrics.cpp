#include "lensopt/render/metrics.h"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/core/threads.h"

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

// The hot loop, compiled for AVX2/FMA as well as the baseline (picked at run time), written with
// contiguous inner loops so it vectorizes. One output row of SSIM: `xs`, `ys` point to the wy
// rows under the window (each `width` doubles, one channel); vertical Gaussian sums of x, y, x^2,
// y^2, xy into v (5 x width scratch), horizontal sums into m (5 x out_w scratch), and the sum of
// SSIM over the row. In double: the variances are differences of nearly equal second moments.
// v0..v4 += g (a, b, a^2, b^2, a b), elementwise.
inline __attribute__((always_inline)) void add_moments(const double* __restrict a,
                                                       const double* __restrict b, double g, int n,
                                                       double* __restrict v0, double* __restrict v1,
                                                       double* __restrict v2, double* __restrict v3,
                                                       double* __restrict v4) {
  for (int i = 0; i < n; ++i) {
    const double ga = g * a[i], gb = g * b[i];
    v0[i] += ga;
    v1[i] += gb;
    v2[i] += ga * a[i];
    v3[i] += gb * b[i];
    v4[i] += ga * b[i];
  }
}

__attribute__((target_clones("arch=x86-64-v3", "default"))) double ssim_row(
    const double* const* xs, const double* const* ys, int width, const double* gy, int wy,
    const double* gx, int wx, double* v, double* m, int out_w) {
  constexpr double kC1 = 0.01 * 0.01;
  constexpr double kC2 = 0.03 * 0.03;
  for (int i = 0; i < 5 * width; ++i) v[i] = 0.0;
  for (int k = 0; k < wy; ++k)
    add_moments(xs[k], ys[k], gy[k], width, v, v + width, v + 2 * width, v + 3 * width,
                v + 4 * width);
  for (int i = 0; i < 5 * out_w; ++i) m[i] = 0.0;
  for (int q = 0; q < 5; ++q) {
    double* __restrict dst = m + static_cast<std::size_t>(q) * out_w;
    const double* __restrict src = v + static_cast<std::size_t>(q) * width;
    for (int k = 0; k < wx; ++k) {
      const double g = gx[k];
      for (int col = 0; col < out_w; ++col) dst[col] += g * src[col + k];
    }
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
  // Per-row sums, then the rows in order: the same value for any thread count.
  std::vector<double> row_sums(x.height, 0.0);
#pragma omp parallel for num_threads(thread_count(threads)) schedule(static)
  for (int row = 0; row < x.height; ++row) {
    double row_sum = 0;
    for (std::size_t p = static_cast<std::size_t>(row) * x.width;
         p < static_cast<std::size_t>(row + 1) * x.width; ++p) {
      for (int c = 0; c < channels; ++c) {
        const double d = static_cast<double>(x.pixels[p * x.channels + c]) -
                         static_cast<double>(y.pixels[p * y.channels + c]);
        row_sum += d * d;
      }
    }
    row_sums[row] = row_sum;
  }
  double sum = 0;
  for (const double r : row_sums) sum += r;
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
  // Per thread, a ring of the wy input rows under the window (channel c, as double); per output
  // row one new row enters the ring and ssim_row does the rest.
  double total = 0;
  for (int c = 0; c < channels; ++c) {
    // Per-row terms, summed in row order afterwards: the same value for any thread count.
    std::vector<double> row_terms(out_h, 0.0);
#pragma omp parallel num_threads(nthreads)
    {
      const int t = omp_get_thread_num(), nt = omp_get_num_threads();
      const int r0 = static_cast<int>(static_cast<long>(out_h) * t / nt);
      const int r1 = static_cast<int>(static_cast<long>(out_h) * (t + 1) / nt);
      std::vector<double> ring(static_cast<std::size_t>(wy) * 2 * width);
      std::vector<double> v(static_cast<std::size_t>(5) * width);
      std::vector<double> m(static_cast<std::size_t>(5) * out_w);
      std::vector<const double*> xs(wy), ys(wy);
      auto load = [&](int row) {  // image row `row` into ring slot row % wy
        double* a = ring.data() + static_cast<std::size_t>(row % wy) * 2 * width;
        double* b = a + width;
        const float* xr = x.pixels.data() + static_cast<std::size_t>(row) * width * x.channels + c;
        const float* yr = y.pixels.data() + static_cast<std::size_t>(row) * width * y.channels + c;
        for (int col = 0; col < width; ++col) {
          a[col] = xr[static_cast<std::size_t>(col) * x.channels];
          b[col] = yr[static_cast<std::size_t>(col) * y.channels];
        }
      };
      if (r0 < r1)
        for (int row = r0; row < r0 + wy - 1; ++row) load(row);
      for (int row = r0; row < r1; ++row) {
        load(row + wy - 1);
        for (int k = 0; k < wy; ++k) {
          xs[k] = ring.data() + static_cast<std::size_t>((row + k) % wy) * 2 * width;
          ys[k] = xs[k] + width;
        }
        row_terms[row] = ssim_row(xs.data(), ys.data(), width, gy.data(), wy, gx.data(), wx,
                                  v.data(), m.data(), out_w);
      }
    }
    double channel_sum = 0;
    for (const double r : row_terms) channel_sum += r;
    total += channel_sum / (static_cast<double>(out_w) * out_h);
  }
  return total / channels;
}

}  // namespace lensopt
