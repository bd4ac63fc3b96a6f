// FFTW helpers shared by the renderer's overlap-add convolution, the joint optimization's
// differentiable rendering and the wave-optics PSF: FFT sizes, aligned buffers, cached plans,
// symmetric reflection. An internal header of the core library (src/, not installed), so that
// FFTW's types stay out of the public headers.
//
// FFTW rather than a hand-written FFT: patch buffers have arbitrary sizes (we pick products of
// 2, 3, 5, 7), FFTW is fast for all of them, and its plans, made once per size, may be executed
// concurrently from many threads on different arrays (fftw_execute_dft_r2c / _c2r). Transforms
// are unnormalized: c2r(r2c(a)) = (ny nx) a.
#pragma once

#include <fftw3.h>

#include <cstddef>
#include <cstring>
#include <new>

namespace lensopt {

// The smallest n >= m whose prime factors are 2, 3, 5 and 7.
int fft_size(int m);

// fftw_malloc'ed arrays (the alignment FFTW's plans expect).
struct RealBuffer {
  double* data = nullptr;
  explicit RealBuffer(std::size_t n) : data(fftw_alloc_real(n)) {
    if (!data) throw std::bad_alloc();
  }
  ~RealBuffer() { fftw_free(data); }
  RealBuffer(const RealBuffer&) = delete;
  RealBuffer& operator=(const RealBuffer&) = delete;
};
struct ComplexBuffer {
  fftw_complex* data = nullptr;
  explicit ComplexBuffer(std::size_t n) : data(fftw_alloc_complex(n)) {
    if (!data) throw std::bad_alloc();
  }
  ~ComplexBuffer() { fftw_free(data); }
  ComplexBuffer(const ComplexBuffer&) = delete;
  ComplexBuffer& operator=(const ComplexBuffer&) = delete;
};

// Forward (r2c) and backward (c2r) plans of one ny x nx size, made once per process (the
// planner, which is not thread-safe, runs under a lock; FFTW_ESTIMATE).
struct FftPlans {
  fftw_plan forward = nullptr;
  fftw_plan backward = nullptr;
};
FftPlans fft_plans(int ny, int nx);

// The in-place complex forward m x m plan (wave optics' pupil FFT), made once per size under the
// same planner lock as fft_plans; executing it on other arrays of the same alignment
// (fftw_execute_dft) is thread-safe.
fftw_plan complex_fft_plan(int m);

// Symmetric reflection of index i into [0, n): ..., 1, 0 | 0, 1, ..., n-1 | n-1, ...
inline int reflect_index(int i, int n) {
  const int period = 2 * n;
  int m = i % period;
  if (m < 0) m += period;
  return m < n ? m : period - 1 - m;
}

// Places a (2r+1)^2 kernel (row-major, centre at (r, r)) centred at the origin, wrapped, into
// a zeroed ny x nx buffer: circular convolution with it is the kernel's convolution.
template <typename V>
void place_kernel(const V* kernel, int radius, int ny, int nx, double* buffer) {
  std::memset(buffer, 0, sizeof(double) * static_cast<std::size_t>(ny) * nx);
  const int size = 2 * radius + 1;
  for (int dy = -radius; dy <= radius; ++dy) {
    const int row = (dy + ny) % ny;
    for (int dx = -radius; dx <= radius; ++dx) {
      buffer[static_cast<std::size_t>(row) * nx + (dx + nx) % nx] =
          kernel[static_cast<std::size_t>(dy + radius) * size + (dx + radius)];
    }
  }
}

}  // namespace lensopt
