// The spatially varying overlap-add convolution, by FFT (render/fft.h), and the Renderer.
#include <fftw3.h>
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstring>

#include "core/fft.h"
#include "lensopt/core/error.h"
#include "lensopt/render/metrics.h"
#include "lensopt/render/render.h"

namespace lensopt {
namespace {

int thread_count(int threads) {
  return threads > 0 ? threads : omp_get_max_threads();
}

}  // namespace

// Everything a render of one image size needs beyond the PSF grid: windows, patch extents, FFT
// size and plans, and the kernels' spectra (scaled by 1 / (ny nx) for the unnormalized inverse).
struct Renderer::GridEntry {
  std::shared_ptr<const PsfGrid> grid;
  int pad = 0;
  std::vector<std::vector<double>> window_x, window_y;  // [patch][pixel]
  std::vector<int> lo_x, hi_x, lo_y, hi_y;              // window extents in the image
  int nx = 0, ny = 0;
  FftPlans plans;
  std::vector<std::vector<std::complex<double>>> spectra;  // [patch * 3 + channel]
  std::vector<int> reflect_x, reflect_y;                   // [pixel + pad]

  std::size_t spectrum_size() const { return static_cast<std::size_t>(ny) * (nx / 2 + 1); }
};

Renderer::Renderer(ImagingModel model, RenderOptions options)
    : model_(std::move(model)), options_(options) {
  options_.validate();
}

Renderer::~Renderer() = default;

std::shared_ptr<Renderer::GridEntry> Renderer::entry(int width, int height) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (auto found = grids_.find(width, height)) return found;

  auto e = std::make_shared<GridEntry>();
  auto grid = std::make_shared<PsfGrid>(make_psf_grid(model_, width, height, options_.res_factor));
  e->grid = grid;
  e->pad = grid->max_radius;
  std::vector<double> sum_x, sum_y;
  e->window_x = overlap_windows(grid->bounds_x, width, 0, &sum_x);
  e->window_y = overlap_windows(grid->bounds_y, height, 0, &sum_y);
  const int widest_x = overlap_window_extents(e->window_x, e->lo_x, e->hi_x);
  const int widest_y = overlap_window_extents(e->window_y, e->lo_y, e->hi_y);
  e->nx = fft_size(widest_x + 2 * e->pad);
  e->ny = fft_size(widest_y + 2 * e->pad);
  e->plans = fft_plans(e->ny, e->nx);
  for (int i = -e->pad; i < width + e->pad; ++i) e->reflect_x.push_back(reflect_index(i, width));
  for (int j = -e->pad; j < height + e->pad; ++j) e->reflect_y.push_back(reflect_index(j, height));

  // Kernel spectra, once per image size.
  const int tasks = PsfGrid::kPatches * PsfGrid::kPatches * kColourChannels;
  e->spectra.resize(tasks);
  const double scale = 1.0 / (static_cast<double>(e->nx) * e->ny);
#pragma omp parallel num_threads(thread_count(options_.threads))
  {
    RealBuffer real(static_cast<std::size_t>(e->ny) * e->nx);
    ComplexBuffer spectrum(e->spectrum_size());
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < tasks; ++t) {
      const PixelKernel& k = grid->kernels[t / kColourChannels][t % kColourChannels];
      place_kernel(k.values.data(), k.radius, e->ny, e->nx, real.data);
      fftw_execute_dft_r2c(e->plans.forward, real.data, spectrum.data);
      auto& out = e->spectra[t];
      out.resize(e->spectrum_size());
      for (std::size_t i = 0; i < out.size(); ++i)
        out[i] = std::complex<double>(spectrum.data[i][0], spectrum.data[i][1]) * scale;
    }
  }
  grids_.insert(width, height, e);
  return e;
}

std::shared_ptr<const PsfGrid> Renderer::psf_grid(int width, int height) const {
  return entry(width, height)->grid;
}

FloatImage Renderer::blur(const FloatImage& input, int threads) const {
  const std::shared_ptr<GridEntry> e = entry(input.width, input.height);
  const PsfGrid& grid = *e->grid;
  const int width = input.width, height = input.height;
  const int colours = colour_channel_count(input.channels);
  const int nthreads = thread_count(threads > 0 ? threads : options_.threads);
  const std::size_t plane = static_cast<std::size_t>(width) * height;
  constexpr int n = PsfGrid::kPatches;
  const int tasks = n * n * colours;
  const std::size_t spectrum_size = e->spectrum_size();
  const int nx = e->nx, ny = e->ny;

  // One accumulator (colours planes) per thread, summed at the end.
  std::vector<std::vector<float>> accumulators(nthreads);
#pragma omp parallel num_threads(nthreads)
  {
    std::vector<float>& acc = accumulators[omp_get_thread_num()];
    acc.assign(plane * colours, 0.0f);
    RealBuffer real(static_cast<std::size_t>(ny) * nx);
    ComplexBuffer spectrum(spectrum_size);
    std::vector<std::complex<double>> grey_spectrum;
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < tasks; ++t) {
      const int q = t / colours, c = t % colours;
      const int px = q % n, py = q / n;
      const int lo_x = e->lo_x[px], lo_y = e->lo_y[py];
      const int wx = e->hi_x[px] - lo_x, wy = e->hi_y[py] - lo_y;
      const std::vector<double>& win_x = e->window_x[px];
      const std::vector<double>& win_y = e->window_y[py];
      // The patch's input: its window's extent plus the PSF reach on each side, from the
      // reflected image.
      const int pad = e->pad;
      // (zero padding up to the FFT size, where the block does not reach)
      const int rows = wy + 2 * pad, cols = wx + 2 * pad;
      for (int j = 0; j < rows; ++j) {
        const int sy = e->reflect_y[lo_y + j];  // image row lo_y - pad + j
        const float* src =
            input.pixels.data() + static_cast<std::size_t>(sy) * width * input.channels;
        double* row = real.data + static_cast<std::size_t>(j) * nx;
        for (int i = 0; i < cols; ++i)
          row[i] = src[static_cast<std::size_t>(e->reflect_x[lo_x + i]) * input.channels + c];
        std::fill(row + cols, row + nx, 0.0);
      }
      std::fill(real.data + static_cast<std::size_t>(rows) * nx,
                real.data + static_cast<std::size_t>(ny) * nx, 0.0);
      fftw_execute_dft_r2c(e->plans.forward, real.data, spectrum.data);
      // Multiply by the kernel's spectrum (grey images: the mean kernel's, made here).
      const std::complex<double>* k;
      if (colours == kColourChannels) {
        k = e->spectra[q * kColourChannels + c].data();
      } else {
        grey_spectrum.resize(spectrum_size);
        RealBuffer kreal(static_cast<std::size_t>(ny) * nx);
        ComplexBuffer kspec(spectrum_size);
        place_kernel(grid.grey_kernels[q].values.data(), grid.grey_kernels[q].radius, ny, nx,
                     kreal.data);
        fftw_execute_dft_r2c(e->plans.forward, kreal.data, kspec.data);
        const double scale = 1.0 / (static_cast<double>(nx) * ny);
        for (std::size_t i = 0; i < spectrum_size; ++i)
          grey_spectrum[i] = std::complex<double>(kspec.data[i][0], kspec.data[i][1]) * scale;
        k = grey_spectrum.data();
      }
      for (std::size_t i = 0; i < spectrum_size; ++i) {
        const std::complex<double> v =
            std::complex<double>(spectrum.data[i][0], spectrum.data[i][1]) * k[i];
        spectrum.data[i][0] = v.real();
        spectrum.data[i][1] = v.imag();
      }
      fftw_execute_dft_c2r(e->plans.backward, spectrum.data, real.data);
      // Weight the blurred patch by its window and add it into the image.
      float* out = acc.data() + plane * c;
      for (int j = 0; j < wy; ++j) {
        const double wyv = win_y[lo_y + j];
        const double* row = real.data + static_cast<std::size_t>(j + pad) * nx + pad;
        float* dst = out + static_cast<std::size_t>(lo_y + j) * width + lo_x;
        const double* wxv = win_x.data() + lo_x;
        for (int i = 0; i < wx; ++i) dst[i] += static_cast<float>(wyv * wxv[i] * row[i]);
      }
    }
  }
  FloatImage out = input;
#pragma omp parallel for num_threads(nthreads) schedule(static)
  for (std::size_t p = 0; p < plane; ++p) {
    for (int c = 0; c < colours; ++c) {
      float v = 0;
      for (const auto& acc : accumulators) v += acc[plane * c + p];
      out.pixels[p * out.channels + c] = v;
    }
  }
  return out;
}

RenderResult Renderer::render(const FloatImage& input, int threads) const {
  if (input.empty()) throw Error("cannot render an empty image");
  const int nthreads = threads > 0 ? threads : options_.threads;
  RenderResult result;
  result.colour_channels = colour_channel_count(input.channels);
  result.image = blur(input, nthreads);
  result.psnr_db = psnr_db(input, result.image, result.colour_channels, nthreads);
  result.ssim = ssim(input, result.image, result.colour_channels, nthreads);
  if (options_.relative_illumination) apply_relative_illumination(result.image, nthreads);
  if (options_.distortion) result.image = apply_distortion(result.image, nthreads);
  return result;
}

}  // namespace lensopt
