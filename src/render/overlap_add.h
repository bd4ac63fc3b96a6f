// The blocks of the overlap-add blur (render/render.h states the model), shared by the Renderer
// (src/render/convolve.cpp) and the joint optimization's differentiable rendering
// (src/joint/imaging.cpp, which adds the adjoint):
//   B(p) = sum_q w_q(p) (K_q * S_ext)(p),   w_q(x, y) = w_x,q(x) w_y,q(y),
// S_ext the image extended by symmetric reflection at its borders. Per patch q and colour
// channel one block: S_ext over the window's extent [x0, x1) x [y0, y1) plus a pad r >= the
// kernel radius on each side, zero-padded to an FFT size nx x ny (products of 2, 3, 5, 7), then
//   Bq = c2r(r2c(block) . K^)   with K^ = r2c(K placed at the origin, wrapped) / (nx ny),
// a circular convolution that equals the linear one over the valid part [r, r + x1 - x0) of the
// block (the pad holds the kernel's reach), and w_q Bq over the window's extent is added into B.
#pragma once

#include <complex>
#include <cstddef>
#include <memory>
#include <mutex>
#include <vector>

#include "core/fft.h"
#include "lensopt/render/image.h"

namespace lensopt {

// One thread's FFT buffers of one nx x ny size: the real block and its spectrum (FFTW's
// fftw_complex has std::complex<double>'s layout).
struct OverlapAddBuffers {
  int nx = 0, ny = 0;
  FftPlans plans;
  RealBuffer real;
  ComplexBuffer spectrum;
  std::vector<int> reflect_x;                // scratch: reflected columns of the block being loaded
  std::vector<std::complex<double>> kernel;  // scratch: a kernel spectrum made for one block

  OverlapAddBuffers(int ny, int nx);
  std::size_t real_size() const { return static_cast<std::size_t>(ny) * nx; }
  std::size_t spectrum_size() const { return static_cast<std::size_t>(ny) * (nx / 2 + 1); }
  std::complex<double>* complex_spectrum() {
    return reinterpret_cast<std::complex<double>*>(spectrum.data);
  }
};

// The FFT buffers of a Renderer, kept between renders: a render takes one set per thread and
// gives it back, so a run of many images allocates (and faults in) its buffers once, not per
// image. Sets of another size than asked for are dropped (a run's images usually share one size).
class OverlapAddPool {
 public:
  std::unique_ptr<OverlapAddBuffers> acquire(int ny, int nx) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      while (!free_.empty()) {
        std::unique_ptr<OverlapAddBuffers> b = std::move(free_.back());
        free_.pop_back();
        if (b->ny == ny && b->nx == nx) return b;
      }
    }
    return std::make_unique<OverlapAddBuffers>(ny, nx);
  }
  void release(std::unique_ptr<OverlapAddBuffers> b) {
    std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(std::move(b));
  }

 private:
  std::mutex mutex_;
  std::vector<std::unique_ptr<OverlapAddBuffers>> free_;
};

// K^ of a (2r+1)^2 kernel (row-major, centre at (r, r)) into `out`: the r2c transform of the
// kernel placed at the origin, scaled by 1 / (nx ny) (the unnormalized inverse). Uses b.real and
// b.spectrum as scratch. V: double, or float (the Renderer's PixelKernel; exact in double).
template <typename V>
void kernel_spectrum(const V* kernel, int radius, OverlapAddBuffers& b,
                     std::vector<std::complex<double>>& out) {
  place_kernel(kernel, radius, b.ny, b.nx, b.real.data);
  fftw_execute_dft_r2c(b.plans.forward, b.real.data, b.spectrum.data);
  const double scale = 1.0 / (static_cast<double>(b.nx) * b.ny);
  const std::complex<double>* s = b.complex_spectrum();
  out.resize(b.spectrum_size());
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = s[i] * scale;
}

// Loads channel c of `image` over [x_first, x_first + cols) x [y_first, y_first + rows) (image
// coordinates, reflected at the borders) into b.real (zero beyond) and transforms it into
// b.spectrum.
void load_reflected_block(const FloatImage& image, int c, int x_first, int y_first, int cols,
                          int rows, OverlapAddBuffers& b);
// The same from a window of the image: `window` holds the pixels from (origin_x, origin_y) of a
// full_width x full_height image; coordinates and the reflection are the full image's, and every
// pixel read must lie in the window.
void load_reflected_block(const FloatImage& window, int origin_x, int origin_y, int full_width,
                          int full_height, int c, int x_first, int y_first, int cols, int rows,
                          OverlapAddBuffers& b);

// b.spectrum *= K^ element-wise, and the blurred block back into b.real (c2r).
void convolve_loaded_block(const std::complex<double>* kernel_spectrum, OverlapAddBuffers& b);

// Adds w_y(j) w_x(i) Bq(i, j) for (i, j) in [x0, x1) x [y0, y1) (image coordinates) into
// dst[(j - dst_y0) stride + (i - dst_x0) column_stride]; Bq(i, j) is b.real at row j - y0 + pad,
// column i - x0 + pad (the block loaded from (x0 - pad, y0 - pad)). Out: float (the Renderer's
// interleaved image, column_stride = its channels) or double (the joint's region,
// zero-initialized: the sum is then the product to the last bit).
template <typename Out>
void add_windowed_block(const OverlapAddBuffers& b, int pad, int x0, int x1, int y0, int y1,
                        const std::vector<double>& window_x, const std::vector<double>& window_y,
                        Out* dst, std::size_t stride, int dst_x0, int dst_y0,
                        std::size_t column_stride = 1) {
  const int width = x1 - x0;
  const double* wx = window_x.data() + x0;
  for (int j = y0; j < y1; ++j) {
    const double wy = window_y[j];
    const double* row = b.real.data + static_cast<std::size_t>(j - y0 + pad) * b.nx + pad;
    Out* out = dst + static_cast<std::size_t>(j - dst_y0) * stride +
               static_cast<std::size_t>(x0 - dst_x0) * column_stride;
    if (column_stride == 1) {
      for (int i = 0; i < width; ++i) out[i] += static_cast<Out>(wy * wx[i] * row[i]);
    } else {
      for (int i = 0; i < width; ++i)
        out[static_cast<std::size_t>(i) * column_stride] += static_cast<Out>(wy * wx[i] * row[i]);
    }
  }
}

}  // namespace lensopt
