#include "lensopt/render/metrics.h"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/core/threads.h"
#include "render/metrics_views.h"

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

// The hot loop, compiled for AVX-512 and AVX2/FMA as well as the baseline (picked at run time).
// One output row of SSIM: `xs`, `ys` point to the wy rows under the window (each `width`
// doubles, one channel); vertical Gaussian sums of x, y, x^2, y^2, xy into v (5 x width
// scratch), horizontal sums into m (5 x out_w scratch), and the sum of SSIM over the row. In
// double: the variances are differences of nearly equal second moments. Both passes run over
// blocks of kBlock columns whose five sums stay in registers across the taps (one load of x and
// y per tap instead of five loads and stores of the sums), adding the taps in order: the same
// sums as one pass per tap over whole rows.
constexpr int kBlock = 8;
typedef double Block __attribute__((vector_size(kBlock * sizeof(double))));

// Unaligned loads and stores of a block (macros rather than functions: a function returning a
// vector type wider than the baseline's registers draws GCC's ABI warning).
#define LENSOPT_LOAD_BLOCK(dst, p) std::memcpy(&(dst), (p), sizeof(Block))
#define LENSOPT_STORE_BLOCK(p, src) std::memcpy((p), &(src), sizeof(Block))

__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default"))) double ssim_row(
    const double* const* xs, const double* const* ys, int width, const double* gy, int wy,
    const double* gx, int wx, double* v, double* m, int out_w) {
  constexpr double kC1 = 0.01 * 0.01;
  constexpr double kC2 = 0.03 * 0.03;
  double* v0 = v;
  double* v1 = v + width;
  double* v2 = v + 2 * width;
  double* v3 = v + 3 * width;
  double* v4 = v + 4 * width;
  int i0 = 0;
  for (; i0 + kBlock <= width; i0 += kBlock) {
    Block s0 = {}, s1 = {}, s2 = {}, s3 = {}, s4 = {};
    for (int k = 0; k < wy; ++k) {
      const double g = gy[k];
      Block a, b;
      LENSOPT_LOAD_BLOCK(a, xs[k] + i0);
      LENSOPT_LOAD_BLOCK(b, ys[k] + i0);
      const Block ga = g * a, gb = g * b;
      s0 += ga;
      s1 += gb;
      s2 += ga * a;
      s3 += gb * b;
      s4 += ga * b;
    }
    LENSOPT_STORE_BLOCK(v0 + i0, s0);
    LENSOPT_STORE_BLOCK(v1 + i0, s1);
    LENSOPT_STORE_BLOCK(v2 + i0, s2);
    LENSOPT_STORE_BLOCK(v3 + i0, s3);
    LENSOPT_STORE_BLOCK(v4 + i0, s4);
  }
  for (int i = i0; i < width; ++i) {  // the last columns
    double s0 = 0, s1 = 0, s2 = 0, s3 = 0, s4 = 0;
    for (int k = 0; k < wy; ++k) {
      const double a = xs[k][i], b = ys[k][i];
      const double ga = gy[k] * a, gb = gy[k] * b;
      s0 += ga;
      s1 += gb;
      s2 += ga * a;
      s3 += gb * b;
      s4 += ga * b;
    }
    v0[i] = s0;
    v1[i] = s1;
    v2[i] = s2;
    v3[i] = s3;
    v4[i] = s4;
  }
  for (int q = 0; q < 5; ++q) {
    double* __restrict dst = m + static_cast<std::size_t>(q) * out_w;
    const double* __restrict src = v + static_cast<std::size_t>(q) * width;
    int c0 = 0;
    for (; c0 + kBlock <= out_w; c0 += kBlock) {
      Block sum = {};
      for (int k = 0; k < wx; ++k) {
        Block x;
        LENSOPT_LOAD_BLOCK(x, src + c0 + k);
        sum += gx[k] * x;
      }
      LENSOPT_STORE_BLOCK(dst + c0, sum);
    }
    for (int col = c0; col < out_w; ++col) {
      double s = 0;
      for (int k = 0; k < wx; ++k) s += gx[k] * src[col + k];
      dst[col] = s;
    }
  }
  const double* mx = m;
  const double* my = mx + out_w;
  const double* mxx = my + out_w;
  const double* myy = mxx + out_w;
  const double* mxy = myy + out_w;
  // The terms (vectorized, into v's space, no longer needed), then their sum in column order.
  double* __restrict terms = v;
  for (int col = 0; col < out_w; ++col) {
    const double vx = mxx[col] - mx[col] * mx[col], vy = myy[col] - my[col] * my[col];
    const double cxy = mxy[col] - mx[col] * my[col];
    terms[col] = ((2 * mx[col] * my[col] + kC1) * (2 * cxy + kC2)) /
                 ((mx[col] * mx[col] + my[col] * my[col] + kC1) * (vx + vy + kC2));
  }
  double sum = 0;
  for (int col = 0; col < out_w; ++col) sum += terms[col];
  return sum;
}

int window_size(int extent) {
  const int size = std::min(11, extent);
  return size % 2 == 1 ? size : size - 1;
}

}  // namespace

double psnr_db(const ChannelView& x, const ChannelView& y, int width, int height, int channels,
               int threads) {
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  // Per-row sums, then the rows in order: the same value for any thread count.
  std::vector<double> row_sums(height, 0.0);
#pragma omp parallel for num_threads(thread_count(threads)) schedule(static)
  for (int row = 0; row < height; ++row) {
    double row_sum = 0;
    const float* xr = x.data + static_cast<std::size_t>(row) * x.row_stride;
    const float* yr = y.data + static_cast<std::size_t>(row) * y.row_stride;
    for (int col = 0; col < width; ++col) {
      for (int c = 0; c < channels; ++c) {
        const double d = static_cast<double>(xr[col * x.col_stride + c * x.channel_stride]) -
                         static_cast<double>(yr[col * y.col_stride + c * y.channel_stride]);
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

double psnr_db(const FloatImage& x, const FloatImage& y, int channels, int threads) {
  check_same_size(x, y, channels);
  return psnr_db(ChannelView::of(x), ChannelView::of(y), x.width, x.height, channels, threads);
}

double ssim(const FloatImage& x, const FloatImage& y, int channels, int threads) {
  check_same_size(x, y, channels);
  return ssim(ChannelView::of(x), ChannelView::of(y), x.width, x.height, channels, threads);
}

double ssim(const ChannelView& x, const ChannelView& y, int width, int height, int channels,
            int threads) {
  constexpr double kSigma = 1.5;
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
        const float* xr =
            x.data + static_cast<std::size_t>(row) * x.row_stride + c * x.channel_stride;
        const float* yr =
            y.data + static_cast<std::size_t>(row) * y.row_stride + c * y.channel_stride;
        for (int col = 0; col < width; ++col) {
          a[col] = xr[col * x.col_stride];
          b[col] = yr[col * y.col_stride];
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
