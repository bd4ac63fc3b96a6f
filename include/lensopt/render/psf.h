// Geometrical PSFs by kernel density estimation (paper "Geometrical PSFs"), templated on the
// scalar like the tracer so Jets flow through for the joint optimization.
//
// Grid: G x G bins (G = 65, odd) of width D = 4 um (260 um), centred on the field's polychromatic
// spot centroid (0, ybar_h), ybar_h = mean of y over every traced ray of every wavelength (the same
// centroid as analysis/spot.h). With c = (G - 1) / 2, bin (row r, column i) has its centre at
//   u_i = (i - c) D,   v_r = (c - r) D        relative to (0, ybar_h),
// so row 0 is the top: sensor +y (radially outward) points up when the grid is viewed as an image.
// KDE: a traced ray at (x, y) is at (u, v) = (x, y - ybar_h) and deposits into bin (r, i)
//   g(u - u_i) g(v - v_r) / (sum_i' g(u - u_i') sum_r' g(v - v_r')),  g(d) = exp(-d^2 / (2 s^2)),
// s = D / 2 (the paper's bandwidth of half a bin), evaluated at bin centres. The sums run over the
// 2 S + 1 bins nearest the ray (S = 2: the next bin is 5 s away, g < 4e-6), whether or not they are
// inside the grid, so a ray deposits exactly its unit energy when it is inside (without this the
// sampled Gaussian's sum ripples by +-1.4 % per axis with the ray's position inside a bin) and
// less near the edge; the part outside the grid is lost. The kernel is separable: per ray 2 (2S+1)
// exponentials and (2S+1)^2 products, no allocation.
// Symmetry: the tracer samples the half pupil x >= 0; every ray is mirrored to (-x, y), which is
// done once per grid by adding the grid to its left-right mirror (the bins are symmetric in u).
// A system that traces full pupils (TraceSystem::full_pupil: a field's VDX or VAN is set) has
// every ray traced, so there is no mirror, and the factor 2 below is 1; the grid stays centred
// on (0, ybar_h), so an x shift of the spot shows in the PSF.
// Channels: channel k (0 = R, 1 = G, 2 = B) collects the rays of the wavelengths w with
// channels[w] == k, each ray with equal energy. Before normalization the energy share inside the
// grid is E_k = (grid sum) / (2 N_k), N_k the traced (unfailed) half-pupil rays of channel k;
// then each channel is divided by its grid sum so it sums to 1. Failed rays are left out, as in
// the spot size.
// Support: every non-zero bin of a channel lies in rows [r0, r1) and columns [c0, c1) (the
// columns symmetric about the centre); the mirror and normalization loops run over that box
// only, which is most of the speed with Jets (a grid of Jets is large, the spot small).
#pragma once

#include <ceres/jet.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "lensopt/analysis/spot.h"
#include "lensopt/core/scalar.h"
#include "lensopt/core/threads.h"
#include "lensopt/trace/system.h"

namespace lensopt {

inline constexpr int kColourChannels = 3;  // R, G, B

// PSF grid and kernel parameters (validated by validate()).
struct PsfOptions {
  int grid_size = 65;       // G, odd
  double bin_um = 4.0;      // D
  double sigma_bins = 0.5;  // s / D
  int support_bins = 2;     // S: bins either side of the nearest one that get a ray's energy

  // Throws Error for out-of-range values.
  void validate() const;
  double sigma_um() const { return sigma_bins * bin_um; }
  int centre() const { return (grid_size - 1) / 2; }
};

// The PSFs of one field, one G x G grid per channel (row-major, see the header for the layout).
template <typename T>
struct FieldPsf {
  std::array<std::vector<T>, kColourChannels> psf;  // sums to 1 per channel (0 if no energy)
  T centroid_y_mm;                                  // ybar_h, grid centre
  std::array<T, kColourChannels> energy_share;      // E_k before normalization
  std::array<int, kColourChannels> traced_rays{};   // N_k (half pupil)
  std::array<std::array<int, 4>, kColourChannels> support{};  // r0, r1, c0, c1 (see the header)
  int failed_rays = 0;                                        // over all wavelengths (half pupil)
};

// The PSFs of every field of a traced system.
template <typename T>
struct PsfSet {
  PsfOptions options;
  std::vector<double> fields_deg;
  std::vector<FieldPsf<T>> fields;
};

// Checks a wavelength-to-channel list against a wavelength count: one entry per wavelength,
// each 0..2. Throws Error naming the problem. (A channel without a wavelength borrows one.)
void validate_wavelength_channels(const std::vector<int>& channels, int wavelength_count);

// The wavelengths feeding each colour channel: those assigned to it, or, for a channel without
// one, the wavelength nearest its centre (R 620 nm, G 550 nm, B 460 nm): a single wavelength
// feeds all three channels, two feed the third by proximity.
std::array<std::vector<int>, kColourChannels> channel_wavelengths(
    const std::vector<int>& channels, const std::vector<double>& wavelengths_nm);

namespace detail {

// acc += a b. For Jet<double, N> written out (value and derivative parts, the same products and
// sums as the Jet operators): the KDE does this (2 S + 1)^2 times per ray, and Eigen's
// non-inlined Jet sum is then most of a Jet PSF's time.
template <typename T>
inline void add_product(T& acc, const T& a, const T& b) {
  acc = acc + a * b;
}
template <int N>
inline void add_product(ceres::Jet<double, N>& acc, const ceres::Jet<double, N>& a,
                        const ceres::Jet<double, N>& b) {
  acc.a += a.a * b.a;
  for (int j = 0; j < N; ++j) acc.v[j] += a.a * b.v[j] + a.v[j] * b.a;
}

// Adds one ray's kernel (unit energy, truncated to the grid) at grid offsets (u, v) in bins
// (u = 0, v = 0 at the grid centre; v up) into `grid` (G x G, row-major). `support` (r0, r1,
// c0, c1), if given, is widened to hold the bins written.
template <typename T>
void kde_deposit(const T& u_bins, const T& v_bins, const PsfOptions& options, std::vector<T>& grid,
                 std::array<int, 4>* support = nullptr) {
  using std::exp;
  constexpr int kMaxTaps = 2 * 8 + 1;
  const int g = options.grid_size;
  const int c = options.centre();
  const int s = options.support_bins;
  const int taps = 2 * s + 1;
  const double inv_two_sigma2 = 1.0 / (2.0 * options.sigma_bins * options.sigma_bins);
  // A ray whose kernel cannot reach the grid (or a non-finite one) deposits nothing.
  const double reach = c + s + 1.0;
  if (!(std::abs(value_of(u_bins)) < reach && std::abs(value_of(v_bins)) < reach)) return;
  // Nearest bin (the integer choice carries no derivative; the weights do).
  const int iu = static_cast<int>(std::lround(value_of(u_bins)));
  const int iv = static_cast<int>(std::lround(value_of(v_bins)));
  T wu[kMaxTaps], wv[kMaxTaps];
  T su = K<T>(0.0), sv = K<T>(0.0);
  for (int k = 0; k < taps; ++k) {
    const T du = u_bins - K<T>(static_cast<double>(iu - s + k));
    const T dv = v_bins - K<T>(static_cast<double>(iv - s + k));
    wu[k] = exp(-(du * du) * K<T>(inv_two_sigma2));
    wv[k] = exp(-(dv * dv) * K<T>(inv_two_sigma2));
    su = su + wu[k];
    sv = sv + wv[k];
  }
  const T norm = K<T>(1.0) / (su * sv);
  if (support) {
    std::array<int, 4>& b = *support;
    b[0] = std::max(0, std::min(b[0], c - (iv + s)));
    b[1] = std::min(g, std::max(b[1], c - (iv - s) + 1));
    b[2] = std::max(0, std::min(b[2], c + iu - s));
    b[3] = std::min(g, std::max(b[3], c + iu + s + 1));
  }
  for (int kv = 0; kv < taps; ++kv) {
    const int row = c - (iv - s + kv);  // v up: row = c - v
    if (row < 0 || row >= g) continue;
    const T wrow = wv[kv] * norm;
    T* line = grid.data() + static_cast<std::size_t>(row) * g;
    for (int ku = 0; ku < taps; ++ku) {
      const int col = c + (iu - s + ku);
      if (col < 0 || col >= g) continue;
      add_product(line[col], wrow, wu[ku]);
    }
  }
}

}  // namespace detail

// Traces every wavelength of field h and returns its PSFs. `channels[w]` is the colour channel of
// the spec wavelength w (Specs::wavelength_channels). `rays` is scratch space.
template <typename T>
FieldPsf<T> field_psf(const TraceSystem<T>& sys, int h, const std::vector<int>& channels,
                      const PsfOptions& options, RayBundle<T>& rays) {
  const int wavelength_count = sys.wavelength_count;
  const int g = options.grid_size;
  const std::size_t cells = static_cast<std::size_t>(g) * g;
  // Trace all wavelengths first: the grid centre is the centroid over all of them.
  std::vector<std::vector<T>> xs(wavelength_count), ys(wavelength_count);
  SpotAccumulator<T> spot;
  FieldPsf<T> out;
  for (int w = 0; w < wavelength_count; ++w) {
    start_rays(sys, h, w, rays);
    trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                 static_cast<RayRecord<T>*>(nullptr));
    spot.add(rays);
    xs[w].reserve(rays.size());
    ys[w].reserve(rays.size());
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (rays.status[i] != kRayOk) {
        ++out.failed_rays;
        continue;
      }
      xs[w].push_back(rays.x[i]);
      ys[w].push_back(rays.y[i]);
    }
  }
  out.centroid_y_mm = spot.centroid();
  const T inv_bin_mm = K<T>(1000.0 / options.bin_um);
  for (int k = 0; k < kColourChannels; ++k) {
    out.psf[k].assign(cells, K<T>(0.0));
    out.support[k] = {g, 0, g, 0};
  }
  const std::vector<double> spec_nm(sys.lens.wavelengths_nm.begin(),
                                    sys.lens.wavelengths_nm.begin() + wavelength_count);
  const auto members = channel_wavelengths(channels, spec_nm);
  for (int k = 0; k < kColourChannels; ++k) {
    for (const int w : members[k]) {
      std::vector<T>& grid = out.psf[k];
      for (std::size_t i = 0; i < xs[w].size(); ++i) {
        detail::kde_deposit((xs[w][i]) * inv_bin_mm, (ys[w][i] - out.centroid_y_mm) * inv_bin_mm,
                            options, grid, &out.support[k]);
      }
      out.traced_rays[k] += static_cast<int>(xs[w].size());
    }
  }
  for (int k = 0; k < kColourChannels; ++k) {
    std::vector<T>& grid = out.psf[k];
    std::array<int, 4>& b = out.support[k];
    if (b[1] <= b[0] || b[3] <= b[2]) {
      b = {0, 0, 0, 0};
    } else if (!sys.full_pupil) {  // the mirror makes the columns symmetric: [min(c0, g - c1),
                                   // max(c1, g - c0))
      const int c0 = std::min(b[2], g - b[3]), c1 = std::max(b[3], g - b[2]);
      b[2] = c0;
      b[3] = c1;
    }
    // Mirror across the y axis: every ray (x, y) also stands for (-x, y) (half pupil only).
    for (int r = b[0]; r < b[1] && !sys.full_pupil; ++r) {
      T* line = grid.data() + static_cast<std::size_t>(r) * g;
      for (int i = b[2]; i < g / 2; ++i) {
        const T sum = line[i] + line[g - 1 - i];
        line[i] = sum;
        line[g - 1 - i] = sum;
      }
      line[g / 2] = line[g / 2] + line[g / 2];
    }
    T total = K<T>(0.0);
    for (int r = b[0]; r < b[1]; ++r)
      for (int i = b[2]; i < b[3]; ++i) total = total + grid[static_cast<std::size_t>(r) * g + i];
    const int n = out.traced_rays[k];
    const double mirror = sys.full_pupil ? 1.0 : 2.0;
    out.energy_share[k] = n > 0 ? total / K<T>(mirror * n) : K<T>(0.0);
    if (value_of(total) > 0.0) {
      const T inv = K<T>(1.0) / total;
      for (int r = b[0]; r < b[1]; ++r)
        for (int i = b[2]; i < b[3]; ++i) {
          T& v = grid[static_cast<std::size_t>(r) * g + i];
          v = v * inv;
        }
    }
  }
  return out;
}

// The PSFs of every field of `sys` (fields spread over threads; `threads` <= 0: all cores).
template <typename T>
PsfSet<T> compute_psfs(const TraceSystem<T>& sys, const std::vector<int>& channels,
                       const PsfOptions& options, int threads = 0) {
  options.validate();
  validate_wavelength_channels(channels, sys.wavelength_count);
  PsfSet<T> set;
  set.options = options;
  set.fields_deg = sys.fields_deg;
  const int field_count = static_cast<int>(sys.fields_deg.size());
  set.fields.resize(field_count);
  const int nthreads = thread_count(threads);
#pragma omp parallel num_threads(nthreads)
  {
    RayBundle<T> rays;
#pragma omp for schedule(dynamic, 1)
    for (int h = 0; h < field_count; ++h) {
      set.fields[h] = field_psf(sys, h, channels, options, rays);
    }
  }
  return set;
}

}  // namespace lensopt
