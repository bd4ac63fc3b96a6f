// The blocks of the overlap-add blur (render/overlap_add.h).
#include "render/overlap_add.h"

#include <algorithm>

namespace lensopt {

OverlapAddBuffers::OverlapAddBuffers(int ny_, int nx_)
    : nx(nx_),
      ny(ny_),
      plans(fft_plans(ny_, nx_)),
      real(static_cast<std::size_t>(ny_) * nx_),
      spectrum(static_cast<std::size_t>(ny_) * (nx_ / 2 + 1)) {}

void load_reflected_block(const FloatImage& image, int c, int x_first, int y_first, int cols,
                          int rows, OverlapAddBuffers& b) {
  load_reflected_block(image, 0, 0, image.width, image.height, c, x_first, y_first, cols, rows, b);
}

void load_reflected_block(const FloatImage& window, int origin_x, int origin_y, int full_width,
                          int full_height, int c, int x_first, int y_first, int cols, int rows,
                          OverlapAddBuffers& b) {
  const int nx = b.nx, ny = b.ny, channels = window.channels;
  b.reflect_x.resize(cols);
  for (int i = 0; i < cols; ++i)
    b.reflect_x[i] = (reflect_index(x_first + i, full_width) - origin_x) * channels;
  for (int j = 0; j < rows; ++j) {
    const int sy = reflect_index(y_first + j, full_height) - origin_y;
    const float* src =
        window.pixels.data() + static_cast<std::size_t>(sy) * window.width * channels + c;
    double* row = b.real.data + static_cast<std::size_t>(j) * nx;
    for (int i = 0; i < cols; ++i) row[i] = src[b.reflect_x[i]];
    std::fill(row + cols, row + nx, 0.0);
  }
  std::fill(b.real.data + static_cast<std::size_t>(rows) * nx,
            b.real.data + static_cast<std::size_t>(ny) * nx, 0.0);
  fftw_execute_dft_r2c(b.plans.forward, b.real.data, b.spectrum.data);
}

void convolve_loaded_block(const std::complex<double>* kernel_spectrum, OverlapAddBuffers& b) {
  // (a + ib)(c + id) = (ac - bd) + i(ad + bc), written out on the interleaved doubles: the
  // product std::complex computes, without its NaN recovery branch (no NaN reaches here), so
  // that the loop vectorizes.
  double* __restrict s = reinterpret_cast<double*>(b.spectrum.data);
  const double* __restrict k = reinterpret_cast<const double*>(kernel_spectrum);
  const std::size_t size = b.spectrum_size();
  for (std::size_t i = 0; i < size; ++i) {
    const double a = s[2 * i], bi = s[2 * i + 1], c = k[2 * i], d = k[2 * i + 1];
    s[2 * i] = a * c - bi * d;
    s[2 * i + 1] = a * d + bi * c;
  }
  fftw_execute_dft_c2r(b.plans.backward, b.spectrum.data, b.real.data);
}

}  // namespace lensopt
