// The Renderer: the spatially varying overlap-add convolution (its blocks in
// render/overlap_add.h), then relative illumination and distortion (warp.cpp).
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstring>

#include "core/fft.h"
#include "lensopt/core/error.h"
#include "lensopt/core/threads.h"
#include "lensopt/render/metrics.h"
#include "lensopt/render/render.h"
#include "render/huge_pages.h"
#include "render/metrics_views.h"
#include "render/overlap_add.h"

namespace lensopt {
namespace {

// The kernel spectra of one image size are cached when they take at most this much memory
// (1280 x 720: 56 MB); above it (a 4K image's would take 360 MB) each block transforms its kernel
// again (one more FFT per block), so memory does not grow with the image beyond the images.
constexpr std::size_t kSpectraBudgetBytes = std::size_t{96} << 20;

}  // namespace

// Everything a render of one image size needs beyond the PSF grid: windows, patch extents, one
// FFT size for every block (the widest window plus the largest PSF radius on each side), and the
// kernels' spectra K^ (render/overlap_add.h) when they fit kSpectraBudgetBytes (else empty).
struct Renderer::GridEntry {
  std::shared_ptr<const PsfGrid> grid;
  int pad = 0;
  std::vector<std::vector<double>> window_x, window_y;  // [patch][pixel]
  std::vector<int> lo_x, hi_x, lo_y, hi_y;              // window extents in the image
  int nx = 0, ny = 0;
  std::vector<std::vector<std::complex<double>>> spectra;  // [patch * 3 + channel] or empty
};

Renderer::Renderer(ImagingModel model, RenderOptions options)
    : model_(std::move(model)),
      options_(options),
      buffer_pool_(std::make_unique<OverlapAddPool>()) {
  options_.validate();
  if (options_.relative_illumination) require_relative_illumination(model_);
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

  // Kernel spectra, once per image size, if they fit the budget.
  const int tasks = PsfGrid::kPatches * PsfGrid::kPatches * kColourChannels;
  const std::size_t spectrum_bytes = sizeof(std::complex<double>) *
                                     static_cast<std::size_t>(e->ny) *
                                     static_cast<std::size_t>(e->nx / 2 + 1);
  if (spectrum_bytes * tasks <= kSpectraBudgetBytes) {
    e->spectra.resize(tasks);
#pragma omp parallel num_threads(thread_count(options_.threads))
    {
      std::unique_ptr<OverlapAddBuffers> buffers = buffer_pool_->acquire(e->ny, e->nx);
#pragma omp for schedule(dynamic, 1)
      for (int t = 0; t < tasks; ++t) {
        const PixelKernel& k = grid->kernels[t / kColourChannels][t % kColourChannels];
        kernel_spectrum(k.values.data(), k.radius, *buffers, e->spectra[t]);
      }
      buffer_pool_->release(std::move(buffers));
    }
  }
  grids_.insert(width, height, e);
  return e;
}

std::shared_ptr<const PsfGrid> Renderer::psf_grid(int width, int height) const {
  return entry(width, height)->grid;
}

void Renderer::blur_into(const FloatImage& input, FloatImage& out, int nthreads) const {
  const std::shared_ptr<GridEntry> e = entry(input.width, input.height);
  const PsfGrid& grid = *e->grid;
  const int width = input.width, height = input.height, channels = input.channels;
  const int colours = colour_channel_count(channels);
  constexpr int n = PsfGrid::kPatches;
  // Deterministic overlap-add: the patches are added in four phases by the parity of (px, py).
  // A window reaches at most (1 + kOverlap) / 2 < 1 patch width from its centre, so two patches
  // of one phase never write the same pixel: within a phase the tasks run in parallel on one
  // accumulator, and every pixel receives its terms in the same order whatever the thread count
  // (the image is then byte-identical for any --threads, a resumed run or a shard). Should a
  // layout ever overlap within a phase, each patch becomes its own phase.
  std::vector<std::vector<int>> phases(4);
  for (int q = 0; q < n * n; ++q) phases[(q % n) % 2 + 2 * ((q / n) % 2)].push_back(q);
  auto disjoint = [](const std::vector<int>& lo, const std::vector<int>& hi, int a, int b) {
    return hi[a] <= lo[b] || hi[b] <= lo[a];
  };
  bool separable = true;
  for (const auto& phase : phases)
    for (std::size_t i = 0; i < phase.size(); ++i)
      for (std::size_t j = i + 1; j < phase.size(); ++j) {
        const int a = phase[i], b = phase[j];
        if (!disjoint(e->lo_x, e->hi_x, a % n, b % n) && !disjoint(e->lo_y, e->hi_y, a / n, b / n))
          separable = false;
      }
  if (!separable) {
    phases.assign(n * n, {});
    for (int q = 0; q < n * n; ++q) phases[q] = {q};
  }

  // The accumulator is the output image itself (interleaved, its colour channels zeroed, other
  // channels copied): no plane of the image's size beside the input and the output. Its huge
  // pages are advised before the first touch (render/huge_pages.h).
  const std::size_t values = static_cast<std::size_t>(width) * height * channels;
  out.width = width;
  out.height = height;
  out.channels = channels;
  resize_with_huge_pages(out.pixels, values);
  float* acc = out.pixels.data();
  const float* in = input.pixels.data();
#pragma omp parallel num_threads(nthreads)
  {
    if (colours != channels) {
#pragma omp for schedule(static)
      for (int j = 0; j < height; ++j) {
        const std::size_t p0 = static_cast<std::size_t>(j) * width * channels;
        for (std::size_t p = p0; p < p0 + static_cast<std::size_t>(width) * channels; ++p)
          if ((p - p0) % channels >= static_cast<std::size_t>(colours)) acc[p] = in[p];
      }  // the barrier: the accumulator is ready
    }
    std::unique_ptr<OverlapAddBuffers> buffers = buffer_pool_->acquire(e->ny, e->nx);
    std::vector<std::complex<double>>& spectrum = buffers->kernel;
    for (const std::vector<int>& phase : phases) {
      const int tasks = static_cast<int>(phase.size()) * colours;
#pragma omp for schedule(dynamic, 1)
      for (int t = 0; t < tasks; ++t) {
        const int q = phase[t / colours], c = t % colours;
        const int px = q % n, py = q / n;
        const int lo_x = e->lo_x[px], lo_y = e->lo_y[py];
        const int hi_x = e->hi_x[px], hi_y = e->hi_y[py];
        // The kernel's spectrum: cached per image size (when the cache fits its budget), else
        // made here, before the block fills the buffers (grey images: the mean kernel's).
        const std::complex<double>* k;
        if (colours == kColourChannels && !e->spectra.empty()) {
          k = e->spectra[q * kColourChannels + c].data();
        } else {
          const PixelKernel& kernel =
              colours == kColourChannels ? grid.kernels[q][c] : grid.grey_kernels[q];
          kernel_spectrum(kernel.values.data(), kernel.radius, *buffers, spectrum);
          k = spectrum.data();
        }
        // The patch's input: its window's extent plus the largest PSF reach on each side, read
        // from the interleaved input with symmetric reflection at the borders.
        load_reflected_block(input, c, lo_x - e->pad, lo_y - e->pad, hi_x - lo_x + 2 * e->pad,
                             hi_y - lo_y + 2 * e->pad, *buffers);
        convolve_loaded_block(k, *buffers);
        add_windowed_block(*buffers, e->pad, lo_x, hi_x, lo_y, hi_y, e->window_x[px],
                           e->window_y[py], acc + c, static_cast<std::size_t>(width) * channels, 0,
                           0, static_cast<std::size_t>(channels));
      }  // the omp for's barrier ends the phase
    }
    buffer_pool_->release(std::move(buffers));
  }
}

FloatImage Renderer::blur(const FloatImage& input, int threads) const {
  const int nthreads = thread_count(threads > 0 ? threads : options_.threads);
  FloatImage out;
  blur_into(input, out, nthreads);
  return out;
}

RenderResult Renderer::render(const FloatImage& input, int threads) const {
  return render_impl(input, nullptr, threads);
}

RenderResult Renderer::render(FloatImage&& input, int threads) const {
  return render_impl(input, &input, threads);
}

RenderResult Renderer::render_impl(const FloatImage& input, FloatImage* reuse, int threads) const {
  if (input.empty()) throw Error("cannot render an empty image");
  const int nthreads = thread_count(threads > 0 ? threads : options_.threads);
  RenderResult result;
  result.colour_channels = colour_channel_count(input.channels);
  const int width = input.width, height = input.height, colours = result.colour_channels;
  // Blur into one image the size of the input; the metrics compare it with the input; the
  // relative illumination dims it in place; the warp reads it and writes the output (into the
  // input's memory when the caller gives it up). At most three images of the input's size are
  // alive at once (input, blurred, warped), two when the input's memory is reused.
  FloatImage blurred;
  blur_into(input, blurred, nthreads);
  const ChannelView view = ChannelView::of(blurred);
  result.psnr_db = psnr_db(ChannelView::of(input), view, width, height, colours, nthreads);
  result.ssim = ssim(ChannelView::of(input), view, width, height, colours, nthreads);
  if (options_.relative_illumination) apply_relative_illumination(blurred, nthreads);
  if (!options_.distortion) {
    result.image = std::move(blurred);
    return result;
  }
  FloatImage out;
  if (reuse) {
    out.pixels = std::move(reuse->pixels);  // the input is not read any more
    *reuse = FloatImage();
  }
  warp_into(blurred, out, nthreads);
  result.image = std::move(out);
  return result;
}

}  // namespace lensopt
