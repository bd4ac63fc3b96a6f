// The patch kernels of one full-image size (src/joint/imaging_detail.h). K_q[c] is linear in the
// field PSFs with fixed weights: K_q[c] = L_q (sum_h a_qh P_h[c]) / T (render/psf_resample.h:
// the mixing and L_q are the Renderer's), a_qh fixed by the value of y_ref (piecewise constant
// in x: no derivative), L_q fixed by the geometry, and the radius r_q (the largest channel's, so
// every channel's kernel, and the grey mean, share one size) fixed per prepare(). The adjoint
// therefore goes through L_q^T to the field PSFs (imaging_backward.cpp).
#include <omp.h>

#include <algorithm>

#include "imaging_detail.h"
#include "lensopt/core/threads.h"

namespace lensopt::imaging_detail {

std::shared_ptr<Geometry> make_geometry(const Optics& o, const DifferentiableImagingOptions& opt,
                                        double sensor_diagonal_mm, int width, int height) {
  auto g = std::make_shared<Geometry>();
  g->width = width;
  g->height = height;
  g->layout =
      make_psf_grid_layout(o.reference_y_mm, sensor_diagonal_mm, width, height, opt.res_factor);
  g->window_x = overlap_windows(g->layout.bounds_x, width, 0);
  g->window_y = overlap_windows(g->layout.bounds_y, height, 0);
  overlap_window_extents(g->window_x, g->lo_x, g->hi_x);
  overlap_window_extents(g->window_y, g->lo_y, g->hi_y);
  constexpr int n = PsfGrid::kPatches;
  const std::size_t cells = static_cast<std::size_t>(opt.psf.grid_size) * opt.psf.grid_size;
  const double pitch_um = g->layout.geometry.pitch_mm * 1000.0;
  g->patches.resize(n * n);
#pragma omp parallel for schedule(dynamic, 1) num_threads(thread_count(opt.threads))
  for (int q = 0; q < n * n; ++q) {
    PatchKernels& pk = g->patches[q];
    const std::vector<double>& a = g->layout.field_weights[q];
    const double azimuth = g->layout.azimuth_rad[q];
    int radius = 0;
    for (int c = 0; c < kColourChannels; ++c) {
      mix_field_psfs(
          a, cells, [&](int h) -> const std::vector<double>& { return o.psf[h][c]; }, pk.mixed[c]);
      radius = std::max(radius, psf_kernel_radius(pk.mixed[c], opt.psf, azimuth, pitch_um));
    }
    pk.radius = radius;
    pk.resampling = PsfResampling::make(opt.psf, azimuth, pitch_um, radius);
    const int size = 2 * radius + 1;
    pk.grey.assign(static_cast<std::size_t>(size) * size, 0.0);
    for (int c = 0; c < kColourChannels; ++c) {
      if (!resample_psf(pk.resampling, pk.mixed[c].data(), pk.kernel[c])) {
        pk.kernel[c].assign(static_cast<std::size_t>(size) * size, 0.0);  // unit kernel
        pk.kernel[c][static_cast<std::size_t>(radius) * size + radius] = 1.0;
      }
      for (std::size_t i = 0; i < pk.grey.size(); ++i)
        pk.grey[i] += pk.kernel[c][i] / kColourChannels;
    }
  }
  for (const PatchKernels& pk : g->patches) g->max_radius = std::max(g->max_radius, pk.radius);
  check_image_holds_psf(width, height, g->max_radius, pitch_um);
  return g;
}

}  // namespace lensopt::imaging_detail
