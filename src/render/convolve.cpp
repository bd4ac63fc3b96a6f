// The spatially varying overlap-add convolution, by FFT, and the Renderer.
//
// FFTW rather than a hand-written FFT: patch buffers have arbitrary sizes (we pick products of
// 2, 3, 5, 7), FFTW is fast for all of them, and its plans, made once per size, may be executed
// concurrently from many threads on different arrays (fftw_execute_dft_r2c / _c2r).
#include <fftw3.h>
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstring>

#include "lensopt/core/error.h"
#include "lensopt/render/metrics.h"
#include "lensopt/render/render.h"

namespace lensopt {
namespace {

int thread_count(int threads) {
  return threads > 0 ? threads : omp_get_max_threads();
}

// The smallest n >= m whose prime factors are 2, 3, 5 and 7.
int fft_size(int m) {
  for (int n = std::max(m, 1);; ++n) {
    int r = n;
    for (int p : {2, 3, 5, 7})
      while (r % p == 0) r /= p;
    if (r == 1) return n;
  }
}

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

// Forward (r2c) and backward (c2r) plans of one ny x nx size, made once per process. The FFTW
// planner is not thread-safe: every planner call holds planner_mutex().
struct FftPlans {
  fftw_plan forward = nullptr;
  fftw_plan backward = nullptr;
};
std::mutex& planner_mutex() {
  static std::mutex m;
  return m;
}
FftPlans fft_plans(int ny, int nx) {
  static std::map<std::pair<int, int>, FftPlans> cache;
  std::lock_guard<std::mutex> lock(planner_mutex());
  auto it = cache.find({ny, nx});
  if (it != cache.end()) return it->second;
  RealBuffer real(static_cast<std::size_t>(ny) * nx);
  ComplexBuffer spectrum(static_cast<std::size_t>(ny) * (nx / 2 + 1));
  FftPlans plans;
  // FFTW_ESTIMATE: planning costs microseconds and does not touch the arrays.
  plans.forward = fftw_plan_dft_r2c_2d(ny, nx, real.data, spectrum.data, FFTW_ESTIMATE);
  plans.backward = fftw_plan_dft_c2r_2d(ny, nx, spectrum.data, real.data, FFTW_ESTIMATE);
  if (!plans.forward || !plans.backward) throw Error(fmt::format("FFTW cannot plan {}x{}", ny, nx));
  cache.emplace(std::make_pair(ny, nx), plans);
  return plans;
}

// Symmetric reflection of index i into [0, n): ..., 1, 0 | 0, 1, ..., n-1 | n-1, ...
int reflect(int i, int n) {
  const int period = 2 * n;
  int m = i % period;
  if (m < 0) m += period;
  return m < n ? m : period - 1 - m;
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

namespace {

// Places a kernel centred at the origin (wrapped) into a zeroed ny x nx buffer.
void place_kernel(const PixelKernel& k, int ny, int nx, double* buffer) {
  std::memset(buffer, 0, sizeof(double) * static_cast<std::size_t>(ny) * nx);
  for (int dy = -k.radius; dy <= k.radius; ++dy) {
    const int row = (dy + ny) % ny;
    for (int dx = -k.radius; dx <= k.radius; ++dx) {
      buffer[static_cast<std::size_t>(row) * nx + (dx + nx) % nx] = k.at(dx, dy);
    }
  }
}

}  // namespace

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
  // Extents: where each patch's window is non-zero inside the image.
  auto extents = [&](const std::vector<std::vector<double>>& w, std::vector<int>& lo,
                     std::vector<int>& hi) {
    int widest = 0;
    for (const auto& wk : w) {
      int first = -1, last = -1;
      for (int i = 0; i < static_cast<int>(wk.size()); ++i) {
        if (wk[i] > 0) {
          if (first < 0) first = i;
          last = i;
        }
      }
      lo.push_back(first);
      hi.push_back(last + 1);
      widest = std::max(widest, last + 1 - first);
    }
    return widest;
  };
  const int widest_x = extents(e->window_x, e->lo_x, e->hi_x);
  const int widest_y = extents(e->window_y, e->lo_y, e->hi_y);
  e->nx = fft_size(widest_x + 2 * e->pad);
  e->ny = fft_size(widest_y + 2 * e->pad);
  e->plans = fft_plans(e->ny, e->nx);
  for (int i = -e->pad; i < width + e->pad; ++i) e->reflect_x.push_back(reflect(i, width));
  for (int j = -e->pad; j < height + e->pad; ++j) e->reflect_y.push_back(reflect(j, height));

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
      place_kernel(grid->kernels[t / kColourChannels][t % kColourChannels], e->ny, e->nx,
                   real.data);
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
        place_kernel(grid.grey_kernels[q], ny, nx, kreal.data);
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
