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
#include "render/metrics_views.h"
#include "render/overlap_add.h"

namespace lensopt {
// Everything a render of one image size needs beyond the PSF grid: windows, patch extents, one
// FFT size for every block (the widest window plus the largest PSF radius on each side), and the
// kernels' spectra K^ (render/overlap_add.h).
struct Renderer::GridEntry {
  std::shared_ptr<const PsfGrid> grid;
  int pad = 0;
  std::vector<std::vector<double>> window_x, window_y;  // [patch][pixel]
  std::vector<int> lo_x, hi_x, lo_y, hi_y;              // window extents in the image
  int nx = 0, ny = 0;
  std::vector<std::vector<std::complex<double>>> spectra;  // [patch * 3 + channel]
};

Renderer::Renderer(ImagingModel model, RenderOptions options)
    : model_(std::move(model)), options_(options) {
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

  // Kernel spectra, once per image size.
  const int tasks = PsfGrid::kPatches * PsfGrid::kPatches * kColourChannels;
  e->spectra.resize(tasks);
#pragma omp parallel num_threads(thread_count(options_.threads))
  {
    OverlapAddBuffers buffers(e->ny, e->nx);
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < tasks; ++t) {
      const PixelKernel& k = grid->kernels[t / kColourChannels][t % kColourChannels];
      kernel_spectrum(k.values.data(), k.radius, buffers, e->spectra[t]);
    }
  }
  grids_.insert(width, height, e);
  return e;
}

std::shared_ptr<const PsfGrid> Renderer::psf_grid(int width, int height) const {
  return entry(width, height)->grid;
}

std::vector<float> Renderer::blur_planes(const FloatImage& input, int nthreads) const {
  const std::shared_ptr<GridEntry> e = entry(input.width, input.height);
  const PsfGrid& grid = *e->grid;
  const int width = input.width, height = input.height;
  const int colours = colour_channel_count(input.channels);
  const std::size_t plane = static_cast<std::size_t>(width) * height;
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

  // The colour planes extended by symmetric reflection by the pad on each side (the pad is at
  // most the image's size: check_image_holds_psf), so that each block is a contiguous copy.
  const int pad = e->pad;
  const int padded_w = width + 2 * pad, padded_h = height + 2 * pad;
  const std::size_t padded_plane = static_cast<std::size_t>(padded_w) * padded_h;
  std::vector<float> padded(padded_plane * colours);
  std::vector<int> source_x(padded_w);
  for (int i = 0; i < padded_w; ++i) source_x[i] = reflect_index(i - pad, width) * input.channels;
  std::vector<float> acc(plane * colours, 0.0f);
#pragma omp parallel num_threads(nthreads)
  {
#pragma omp for schedule(static)
    for (int j = 0; j < padded_h; ++j) {
      const float* src =
          input.pixels.data() +
          static_cast<std::size_t>(reflect_index(j - pad, height)) * width * input.channels;
      for (int c = 0; c < colours; ++c) {
        float* dst = padded.data() + padded_plane * c + static_cast<std::size_t>(j) * padded_w;
        for (int i = 0; i < padded_w; ++i) dst[i] = src[source_x[i] + c];
      }
    }  // the barrier: the planes are complete
    OverlapAddBuffers buffers(e->ny, e->nx);
    std::vector<std::complex<double>> grey_spectrum;
    for (const std::vector<int>& phase : phases) {
      const int tasks = static_cast<int>(phase.size()) * colours;
#pragma omp for schedule(dynamic, 1)
      for (int t = 0; t < tasks; ++t) {
        const int q = phase[t / colours], c = t % colours;
        const int px = q % n, py = q / n;
        const int lo_x = e->lo_x[px], lo_y = e->lo_y[py];
        const int hi_x = e->hi_x[px], hi_y = e->hi_y[py];
        // The kernel's spectrum (grey images: the mean kernel's, made here, before the block
        // fills the buffers).
        const std::complex<double>* k;
        if (colours == kColourChannels) {
          k = e->spectra[q * kColourChannels + c].data();
        } else {
          kernel_spectrum(grid.grey_kernels[q].values.data(), grid.grey_kernels[q].radius, buffers,
                          grey_spectrum);
          k = grey_spectrum.data();
        }
        // The patch's input: its window's extent plus the largest PSF reach on each side (image
        // column lo_x - pad is the padded plane's column lo_x).
        load_padded_block(padded.data() + padded_plane * c, padded_w, lo_x, lo_y,
                          hi_x - lo_x + 2 * pad, hi_y - lo_y + 2 * pad, buffers);
        convolve_loaded_block(k, buffers);
        add_windowed_block(buffers, pad, lo_x, hi_x, lo_y, hi_y, e->window_x[px], e->window_y[py],
                           acc.data() + plane * c, width, 0, 0);
      }  // the omp for's barrier ends the phase
    }
  }
  return acc;
}

namespace {

// The image `input` with its colour channels replaced by the planes `acc`, each value times
// factor[p] if `factor` is not null (the relative illumination); other channels (alpha) kept.
FloatImage interleave(const FloatImage& input, const std::vector<float>& acc, const float* factor,
                      int nthreads) {
  const int colours = colour_channel_count(input.channels), channels = input.channels;
  const std::size_t plane = static_cast<std::size_t>(input.width) * input.height;
  FloatImage out;
  out.width = input.width;
  out.height = input.height;
  out.channels = channels;
  out.pixels.resize(plane * channels);
  float* o = out.pixels.data();
  const float* a = acc.data();
  const float* in = input.pixels.data();
#pragma omp parallel for num_threads(nthreads) schedule(static)
  for (int j = 0; j < input.height; ++j) {
    const std::size_t p0 = static_cast<std::size_t>(j) * input.width, p1 = p0 + input.width;
    if (colours == 3 && channels == 3) {
      for (std::size_t p = p0; p < p1; ++p) {
        const float f = factor ? factor[p] : 1.0f;
        for (int c = 0; c < 3; ++c) o[p * 3 + c] = factor ? a[plane * c + p] * f : a[plane * c + p];
      }
      continue;
    }
    for (std::size_t p = p0; p < p1; ++p) {
      for (int c = 0; c < channels; ++c) {
        float v = in[p * channels + c];
        if (c < colours) v = factor ? a[plane * c + p] * factor[p] : a[plane * c + p];
        o[p * channels + c] = v;
      }
    }
  }
  return out;
}

}  // namespace

FloatImage Renderer::blur(const FloatImage& input, int threads) const {
  const int nthreads = thread_count(threads > 0 ? threads : options_.threads);
  return interleave(input, blur_planes(input, nthreads), nullptr, nthreads);
}

RenderResult Renderer::render(const FloatImage& input, int threads) const {
  if (input.empty()) throw Error("cannot render an empty image");
  const int nthreads = thread_count(threads > 0 ? threads : options_.threads);
  RenderResult result;
  result.colour_channels = colour_channel_count(input.channels);
  const int width = input.width, height = input.height, colours = result.colour_channels;
  // The blur's planes feed the metrics directly, and the relative illumination is applied while
  // they are interleaved: the same values as blur(), then apply_relative_illumination().
  const std::vector<float> acc = blur_planes(input, nthreads);
  const ChannelView blurred = ChannelView::planar(acc.data(), width, height);
  result.psnr_db = psnr_db(ChannelView::of(input), blurred, width, height, colours, nthreads);
  result.ssim = ssim(ChannelView::of(input), blurred, width, height, colours, nthreads);
  std::shared_ptr<const std::vector<float>> factor;
  if (options_.relative_illumination) factor = illumination_map(width, height);
  result.image = interleave(input, acc, factor ? factor->data() : nullptr, nthreads);
  if (options_.distortion) result.image = apply_distortion(result.image, nthreads);
  return result;
}

}  // namespace lensopt
