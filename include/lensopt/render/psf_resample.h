// Resampling a field PSF grid (G x G bins of D um, psf.h) to a patch's pixel kernel (render.h):
// a fixed linear map, templated on the scalar so the renderer (double) and the joint optimization
// (Jets, or its transpose for the adjoint) share it.
//
// Bin (row, col) sits at u = (col - c) s, v = (c - row) s pixels (s = D / pitch, c = (G - 1) / 2)
// in the PSF's frame (+v radially outward). Rotated to the patch azimuth a, with e_r = (cos a,
// sin a) and e_t = (-sin a, cos a) in image coordinates (rows down):
//   (dx, dy) = u e_t + v e_r.
// The bin's mass m goes bilinearly to the four pixels around (dx + r, dy + r) of the (2r+1)^2
// kernel (r the radius): with x0 = floor(dx + r), fx = dx + r - x0 (same in y),
//   A[y0][x0] += m (1-fx)(1-fy), A[y0][x0+1] += m fx (1-fy), A[y0+1][x0] += m (1-fx) fy,
//   A[y0+1][x0+1] += m fx fy.
// The kernel is K = A / T, T = sum_b m_b (sum 1; a grid without energy gives the unit kernel of
// radius 0, so the image is left unblurred). The map m -> A is linear with weights fixed by the
// geometry alone, so dK/dx = (L dm/dx) / T - K (sum_b dm_b/dx) / T and the adjoint of a gradient
// G = dLoss/dK is
//   dLoss/dm_b = (sum_i G_i L_ib - sum_i G_i K_i) / T.
// The radius r = floor(reach) + 1, reach the largest |dx| or |dy| of a bin with m > 0, holds every
// tap; bins with m <= 0 are skipped (a bin outside the radius must have m = 0).
#pragma once

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/core/scalar.h"
#include "lensopt/render/psf.h"

namespace lensopt {

// The fixed bin -> pixel weights of one patch (azimuth, pitch, radius).
struct PsfResampling {
  int grid_size = 0;
  int radius = 0;
  std::vector<int> corner;  // per bin: kernel index of its top-left tap, -1 if out of reach
  std::vector<double> fx, fy;
  int size() const { return 2 * radius + 1; }

  static PsfResampling make(const PsfOptions& options, double azimuth_rad, double pitch_um,
                            int radius) {
    const int g = options.grid_size;
    const int c = options.centre();
    const double erx = std::cos(azimuth_rad), ery = std::sin(azimuth_rad);
    const double etx = -ery, ety = erx;
    const double scale = options.bin_um / pitch_um;
    PsfResampling r;
    r.grid_size = g;
    r.radius = radius;
    const int size = r.size();
    const std::size_t cells = static_cast<std::size_t>(g) * g;
    r.corner.assign(cells, -1);
    r.fx.assign(cells, 0.0);
    r.fy.assign(cells, 0.0);
    for (int row = 0; row < g; ++row) {
      for (int col = 0; col < g; ++col) {
        const double u = (col - c) * scale;
        const double v = (c - row) * scale;
        const double px = u * etx + v * erx + radius, py = u * ety + v * ery + radius;
        const int x0 = static_cast<int>(std::floor(px)), y0 = static_cast<int>(std::floor(py));
        if (x0 < 0 || y0 < 0 || x0 + 1 >= size || y0 + 1 >= size) continue;
        const std::size_t b = static_cast<std::size_t>(row) * g + col;
        r.corner[b] = y0 * size + x0;
        r.fx[b] = px - x0;
        r.fy[b] = py - y0;
      }
    }
    return r;
  }
};

// The patch PSF sum_h a_h P_h of the field PSFs (`cells` bins each; psf_of_field(h) returns
// field h's grid), fields with a_h = 0 skipped; the same sums for the Renderer (make_psf_grid)
// and the joint imaging's patch kernels.
template <typename FieldPsf>
void mix_field_psfs(const std::vector<double>& a, std::size_t cells, FieldPsf&& psf_of_field,
                    std::vector<double>& mixed) {
  mixed.assign(cells, 0.0);
  for (std::size_t h = 0; h < a.size(); ++h) {
    if (a[h] == 0.0) continue;
    const std::vector<double>& psf = psf_of_field(static_cast<int>(h));
    for (std::size_t i = 0; i < cells; ++i) mixed[i] += a[h] * psf[i];
  }
}

// The largest PSF kernel radius in pixels (a kernel holds (2 r + 1)^2 values).
inline constexpr int kMaxPsfKernelRadiusPx = 4096;

// The radius that holds every bin of `grid` with positive mass (see the header).
inline int psf_kernel_radius(const std::vector<double>& grid, const PsfOptions& options,
                             double azimuth_rad, double pitch_um) {
  const int g = options.grid_size;
  const int c = options.centre();
  const double erx = std::cos(azimuth_rad), ery = std::sin(azimuth_rad);
  const double etx = -ery, ety = erx;
  const double scale = options.bin_um / pitch_um;
  double reach = 0;
  for (int row = 0; row < g; ++row) {
    for (int col = 0; col < g; ++col) {
      if (grid[static_cast<std::size_t>(row) * g + col] <= 0.0) continue;
      const double u = (col - c) * scale;
      const double v = (c - row) * scale;
      reach = std::max({reach, std::abs(u * etx + v * erx), std::abs(u * ety + v * ery)});
    }
  }
  // Checked before the int conversion and any allocation of (2 radius + 1)^2 values.
  if (!(reach < kMaxPsfKernelRadiusPx))
    throw Error(
        fmt::format("the PSF would be {:g} pixels wide (PSF bin {:g} um over a pixel "
                    "pitch of {:g} um); at most {} are supported: the sensor diagonal is "
                    "too small for the image size",
                    2 * reach + 1, options.bin_um, pitch_um, 2 * kMaxPsfKernelRadiusPx + 1));
  return static_cast<int>(std::floor(reach)) + 1;
}

// K = L m / T into `kernel` (size()^2 values). Returns false (and the unit kernel of radius 0
// in kernel[0], the caller's radius being 0) if the grid has no energy.
template <typename T>
bool resample_psf(const PsfResampling& r, const T* grid, std::vector<T>& kernel) {
  const int size = r.size();
  kernel.assign(static_cast<std::size_t>(size) * size, K<T>(0.0));
  T total = K<T>(0.0);
  const std::size_t cells = r.corner.size();
  for (std::size_t b = 0; b < cells; ++b) {
    const T& m = grid[b];
    if (!(value_of(m) > 0.0) || r.corner[b] < 0) continue;
    const double fx = r.fx[b], fy = r.fy[b];
    T* r0 = kernel.data() + r.corner[b];
    T* r1 = r0 + size;
    r0[0] = r0[0] + m * K<T>((1 - fx) * (1 - fy));
    r0[1] = r0[1] + m * K<T>(fx * (1 - fy));
    r1[0] = r1[0] + m * K<T>((1 - fx) * fy);
    r1[1] = r1[1] + m * K<T>(fx * fy);
    total = total + m;
  }
  if (!(value_of(total) > 0.0)) {
    kernel.assign(1, K<T>(1.0));
    return false;
  }
  const T inv = K<T>(1.0) / total;
  for (T& v : kernel) v = v * inv;
  return true;
}

// The adjoint: adds dLoss/dm (G x G) to `grad_grid` for G = dLoss/dK (`grad_kernel`), given the
// grid and its kernel K (from resample_psf). Nothing if the grid has no energy.
inline void resample_psf_adjoint(const PsfResampling& r, const double* grid,
                                 const std::vector<double>& kernel,
                                 const std::vector<double>& grad_kernel, double* grad_grid) {
  const int size = r.size();
  const std::size_t cells = r.corner.size();
  double total = 0;
  for (std::size_t b = 0; b < cells; ++b)
    if (grid[b] > 0.0 && r.corner[b] >= 0) total += grid[b];
  if (!(total > 0.0)) return;
  double gk = 0;  // sum_i G_i K_i
  for (std::size_t i = 0; i < kernel.size(); ++i) gk += grad_kernel[i] * kernel[i];
  const double inv = 1.0 / total;
  for (std::size_t b = 0; b < cells; ++b) {
    if (!(grid[b] > 0.0) || r.corner[b] < 0) continue;
    const double fx = r.fx[b], fy = r.fy[b];
    const double* g0 = grad_kernel.data() + r.corner[b];
    const double* g1 = g0 + size;
    const double lg = g0[0] * ((1 - fx) * (1 - fy)) + g0[1] * (fx * (1 - fy)) +
                      g1[0] * ((1 - fx) * fy) + g1[1] * (fx * fy);
    grad_grid[b] += (lg - gk) * inv;
  }
}

}  // namespace lensopt
