// The PSF grid: overlap-add windows, patch field weights, rotated and resampled patch PSFs.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "lensopt/core/error.h"
#include "lensopt/render/psf_resample.h"
#include "lensopt/render/render.h"

namespace lensopt {
namespace {

// Index of the field whose reference height is nearest to r (heights increasing).
int nearest_field(const std::vector<double>& heights, double r) {
  const auto it = std::lower_bound(heights.begin(), heights.end(), r);
  if (it == heights.begin()) return 0;
  if (it == heights.end()) return static_cast<int>(heights.size()) - 1;
  const int hi = static_cast<int>(it - heights.begin());
  return (r - heights[hi - 1] <= heights[hi] - r) ? hi - 1 : hi;
}

// A G x G field-averaged PSF (one channel) resampled to the pixel grid (psf_resample.h).
PixelKernel resample_to_pixels(const std::vector<double>& grid, const PsfOptions& options,
                               double azimuth_rad, double pitch_um) {
  const PsfResampling r = PsfResampling::make(
      options, azimuth_rad, pitch_um, psf_kernel_radius(grid, options, azimuth_rad, pitch_um));
  std::vector<double> values;
  PixelKernel kernel;
  kernel.radius = resample_psf(r, grid.data(), values) ? r.radius : 0;
  kernel.values.assign(values.begin(), values.end());
  return kernel;
}

// The mean of kernels (grey images), on the largest radius.
PixelKernel mean_kernel(const std::array<PixelKernel, kColourChannels>& kernels) {
  PixelKernel out;
  for (const PixelKernel& k : kernels) out.radius = std::max(out.radius, k.radius);
  const int size = out.size();
  out.values.assign(static_cast<std::size_t>(size) * size, 0.0f);
  for (const PixelKernel& k : kernels) {
    const int shift = out.radius - k.radius;
    for (int y = 0; y < k.size(); ++y)
      for (int x = 0; x < k.size(); ++x)
        out.values[static_cast<std::size_t>(y + shift) * size + (x + shift)] +=
            k.values[static_cast<std::size_t>(y) * k.size() + x] / kColourChannels;
  }
  return out;
}

}  // namespace

std::vector<std::vector<double>> overlap_windows(const std::vector<int>& bounds, int extent,
                                                 int pad, std::vector<double>* raw_sum) {
  const int patches = static_cast<int>(bounds.size()) - 1;
  const int span = extent + 2 * pad;
  std::vector<std::vector<double>> w(patches, std::vector<double>(span, 0.0));
  std::vector<double> sum(span, 0.0);
  for (int k = 0; k < patches; ++k) {
    const double width = bounds[k + 1] - bounds[k];
    const double centre = 0.5 * (bounds[k] + bounds[k + 1]);
    const double length = (1.0 + PsfGrid::kOverlap) * width;
    for (int i = 0; i < span; ++i) {
      const double t = (i - pad) + 0.5 - centre;
      double value = 0;
      if ((k == 0 && t <= 0) || (k == patches - 1 && t >= 0)) {
        value = 1;  // the outer patches reach into the padding
      } else if (std::abs(t) < 0.5 * length) {
        const double cosine = std::cos(kPi * t / length);
        value = cosine * cosine;
      }
      w[k][i] = value;
      sum[i] += value;
    }
  }
  for (int k = 0; k < patches; ++k)
    for (int i = 0; i < span; ++i) w[k][i] /= sum[i];
  if (raw_sum) *raw_sum = sum;
  return w;
}

PsfGrid make_psf_grid_layout(const std::vector<double>& reference_y_mm, double sensor_diagonal_mm,
                             int width, int height, int res_factor) {
  constexpr int n = PsfGrid::kPatches;
  if (width < 2 * n || height < 2 * n) {
    throw Error(
        fmt::format("image {}x{} is too small: the renderer needs at least {} pixels in "
                    "each direction (2 per patch)",
                    width, height, 2 * n));
  }
  PsfGrid grid;
  grid.geometry = SensorGeometry::make(width, height, res_factor, sensor_diagonal_mm);
  const SensorGeometry& geo = grid.geometry;
  for (int k = 0; k <= n; ++k) {
    grid.bounds_x.push_back(static_cast<int>(std::lround(static_cast<double>(k) * width / n)));
    grid.bounds_y.push_back(static_cast<int>(std::lround(static_cast<double>(k) * height / n)));
  }
  const int field_count = static_cast<int>(reference_y_mm.size());
  grid.field_weights.assign(n * n, std::vector<double>(field_count, 0.0));
  grid.azimuth_rad.assign(n * n, 0.0);
  for (int py = 0; py < n; ++py) {
    for (int px = 0; px < n; ++px) {
      const int q = grid.patch_index(px, py);
      // Field weights: share of the patch's pixels nearest to each field.
      std::vector<double>& a = grid.field_weights[q];
      const int x0 = grid.bounds_x[px], x1 = grid.bounds_x[px + 1];
      const int y0 = grid.bounds_y[py], y1 = grid.bounds_y[py + 1];
      for (int j = y0; j < y1; ++j)
        for (int i = x0; i < x1; ++i) a[nearest_field(reference_y_mm, geo.radius_mm(i, j))] += 1;
      const double count = static_cast<double>(x1 - x0) * (y1 - y0);
      for (double& v : a) v /= count;
      // Azimuth of the patch centre (the axis patch keeps +y pointing up).
      const double cx = 0.5 * (x0 + x1) - geo.axis_x, cy = 0.5 * (y0 + y1) - geo.axis_y;
      grid.azimuth_rad[q] = (std::hypot(cx, cy) < 1e-9) ? -0.5 * kPi : std::atan2(cy, cx);
    }
  }
  return grid;
}

PsfGrid make_psf_grid(const ImagingModel& model, int width, int height, int res_factor) {
  constexpr int n = PsfGrid::kPatches;
  PsfGrid grid = make_psf_grid_layout(model.reference_y_mm, model.sensor_diagonal_mm, width, height,
                                      res_factor);
  const PsfOptions& popt = model.psfs.options;
  const std::size_t cells = static_cast<std::size_t>(popt.grid_size) * popt.grid_size;
  const double pitch_um = grid.geometry.pitch_mm * 1000.0;
  grid.kernels.resize(n * n);
  grid.grey_kernels.resize(n * n);
  for (int q = 0; q < n * n; ++q) {
    const std::vector<double>& a = grid.field_weights[q];
    for (int ch = 0; ch < kColourChannels; ++ch) {
      std::vector<double> mixed;
      mix_field_psfs(
          a, cells,
          [&](int h) -> const std::vector<double>& { return model.psfs.fields[h].psf[ch]; }, mixed);
      grid.kernels[q][ch] = resample_to_pixels(mixed, popt, grid.azimuth_rad[q], pitch_um);
      grid.max_radius = std::max(grid.max_radius, grid.kernels[q][ch].radius);
    }
    grid.grey_kernels[q] = mean_kernel(grid.kernels[q]);
  }
  check_image_holds_psf(width, height, grid.max_radius, grid.geometry.pitch_mm * 1000.0);
  return grid;
}

void check_image_holds_psf(int width, int height, int max_radius, double pitch_um) {
  const int psf_size = 2 * max_radius + 1;
  if (width < psf_size || height < psf_size) {
    throw Error(
        fmt::format("image {}x{} is smaller than the lens's PSF ({}x{} pixels at a pitch "
                    "of {:.2f} um): use a larger image",
                    width, height, psf_size, psf_size, pitch_um));
  }
}

int overlap_window_extents(const std::vector<std::vector<double>>& windows, std::vector<int>& lo,
                           std::vector<int>& hi) {
  int widest = 0;
  for (const auto& wk : windows) {
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
}

}  // namespace lensopt
