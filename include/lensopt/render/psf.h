// Geometrical PSFs by kernel density estimation (paper "Geometrical PSFs"), templated on the
// scalar like the tracer so Jets flow through for the joint optimization.
//
// Grid: G x G bins (G = 65, odd) of width D = 4 um (260 um), centred on the field's polychromatic
// spot centroid (0, ybar_h), ybar_h the wavelength-weighted mean of y over every traced ray of
// every wavelength: the centroid of analysis/spot.h, measured on the same traced rays
// (trace_fields; analysis/field_optics.h), so the spot, the distortion and the PSF agree. With c =
// (G - 1) / 2, bin (row r, column i) has its centre at
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
// channels[w] == k, each ray of wavelength w with the energy omega_w (the lens's wavelength weight
// normalized to the largest: 1 for equal weights). Before normalization the energy share inside
// the grid is E_k = (grid sum) / (2 sum omega_w N_kw), N_kw the traced (unfailed) half-pupil rays
// of wavelength w in channel k;
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
                 std::array<int, 4>* support = nullptr, double energy = 1.0) {
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
  // The ray's energy (1: the unit energy of the paper, the same bits as without it).
  const T norm = energy == 1.0 ? K<T>(1.0) / (su * sv) : K<T>(energy) / (su * sv);
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

// The arrived rays of one field, per spec wavelength (image-plane x, y in mm), as trace_fields
// (analysis/spot.h) hands them over: the PSFs are built from the rays the field's spot,
// centroid and distortion were measured with (analysis/field_optics.h), not from a trace of
// their own.
template <typename T>
struct FieldRays {
  std::vector<std::vector<T>> x_mm, y_mm;  // [w][arrived ray]
  int failed_rays = 0;                     // over all wavelengths, vignetted included
  // Stores the arrived rays of a bundle of spec wavelength w (wavelength_count: for the size).
  void add(int w, int wavelength_count, const RayBundle<T>& rays) {
    if (static_cast<int>(x_mm.size()) < wavelength_count) {
      x_mm.resize(wavelength_count);
      y_mm.resize(wavelength_count);
    }
    x_mm[w].clear();
    y_mm[w].clear();
    x_mm[w].reserve(rays.size());
    y_mm[w].reserve(rays.size());
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (rays.status[i] != kRayOk) {
        ++failed_rays;
        continue;
      }
      x_mm[w].push_back(rays.x[i]);
      y_mm[w].push_back(rays.y[i]);
    }
  }
};

// The on_rays reader of trace_fields / measure_fields that keeps every field's rays for the
// PSFs (each field is written by the one thread that traces it).
template <typename T>
struct PsfRayCollector {
  int wavelength_count = 0;
  std::vector<FieldRays<T>> fields;
  explicit PsfRayCollector(const TraceSystem<T>& sys)
      : wavelength_count(sys.wavelength_count), fields(sys.fields_deg.size()) {}
  void operator()(int h, int w, const RayBundle<T>& rays) {
    fields[h].add(w, wavelength_count, rays);
  }
};

// The PSFs of one field from its arrived rays, the grid centred on `centroid_y_mm` (the field's
// wavelength-weighted centroid ybar_h, spot.h). Within a channel each ray of wavelength w
// carries the energy omega_w (the lens's wavelength weight normalized to the largest,
// spot_weights), so a channel fed by several wavelengths mixes them as the spot and the
// diffraction PSF do; E_k = (grid sum) / (mirror sum of the channel's ray energies).
template <typename T>
FieldPsf<T> deposit_field_psf(const TraceSystem<T>& sys, const FieldRays<T>& rays,
                              const T& centroid_y_mm, const std::vector<int>& channels,
                              const PsfOptions& options) {
  const int g = options.grid_size;
  const std::size_t cells = static_cast<std::size_t>(g) * g;
  const std::vector<double> omega =
      normalized_spot_weights(sys.wavelength_weights, sys.wavelength_count);
  FieldPsf<T> out;
  out.failed_rays = rays.failed_rays;
  out.centroid_y_mm = centroid_y_mm;
  const T inv_bin_mm = K<T>(1000.0 / options.bin_um);
  for (int k = 0; k < kColourChannels; ++k) {
    out.psf[k].assign(cells, K<T>(0.0));
    out.support[k] = {g, 0, g, 0};
  }
  const std::vector<double> spec_nm(sys.lens.wavelengths_nm.begin(),
                                    sys.lens.wavelengths_nm.begin() + sys.wavelength_count);
  const auto members = channel_wavelengths(channels, spec_nm);
  std::array<double, kColourChannels> energy{};
  for (int k = 0; k < kColourChannels; ++k) {
    for (const int w : members[k]) {
      if (w >= static_cast<int>(rays.x_mm.size())) continue;
      std::vector<T>& grid = out.psf[k];
      const std::vector<T>& xs = rays.x_mm[w];
      const std::vector<T>& ys = rays.y_mm[w];
      for (std::size_t i = 0; i < xs.size(); ++i) {
        detail::kde_deposit(xs[i] * inv_bin_mm, (ys[i] - out.centroid_y_mm) * inv_bin_mm, options,
                            grid, &out.support[k], omega[w]);
      }
      out.traced_rays[k] += static_cast<int>(xs.size());
      energy[k] += omega[w] * static_cast<double>(xs.size());
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
    const double mirror = sys.full_pupil ? 1.0 : 2.0;
    out.energy_share[k] = energy[k] > 0.0 ? total / K<T>(mirror * energy[k]) : K<T>(0.0);
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

// The PSFs of every field from the rays trace_fields / measure_fields collected, each centred on
// the field's centroid in `spots` (fields spread over threads; `threads` <= 0: all cores).
template <typename T>
PsfSet<T> psfs_from_rays(const TraceSystem<T>& sys, const SpotResult<T>& spots,
                         const PsfRayCollector<T>& rays, const std::vector<int>& channels,
                         const PsfOptions& options, int threads = 0) {
  options.validate();
  validate_wavelength_channels(channels, sys.wavelength_count);
  PsfSet<T> set;
  set.options = options;
  set.fields_deg = sys.fields_deg;
  const int field_count = static_cast<int>(sys.fields_deg.size());
  set.fields.resize(field_count);
  const int nthreads = thread_count(threads);
#pragma omp parallel for schedule(dynamic, 1) num_threads(nthreads)
  for (int h = 0; h < field_count; ++h)
    set.fields[h] =
        deposit_field_psf(sys, rays.fields[h], spots.centroid_y_mm[h], channels, options);
  return set;
}

// Traces every wavelength of field h alone and returns its PSFs (the same numbers as that field
// of compute_psfs). `rays` is scratch space.
template <typename T>
FieldPsf<T> field_psf(const TraceSystem<T>& sys, int h, const std::vector<int>& channels,
                      const PsfOptions& options, RayBundle<T>& rays) {
  const SpotWeights weights = spot_weights(sys);
  SpotAccumulator<T> spot;
  spot.full_pupil = sys.full_pupil;
  FieldRays<T> traced;
  for (int w = 0; w < sys.wavelength_count; ++w) {
    start_rays(sys, h, w, rays);
    trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                 static_cast<RayRecord<T>*>(nullptr));
    spot.add(rays, weights.wavelength[w]);
    traced.add(w, sys.wavelength_count, rays);
  }
  return deposit_field_psf(sys, traced, spot.centroid(), channels, options);
}

// The PSFs of every field of `sys`: one trace (trace_fields), each field's grid centred on its
// wavelength-weighted centroid (fields spread over threads; `threads` <= 0: all cores).
template <typename T>
PsfSet<T> compute_psfs(const TraceSystem<T>& sys, const std::vector<int>& channels,
                       const PsfOptions& options, int threads = 0) {
  options.validate();
  validate_wavelength_channels(channels, sys.wavelength_count);
  PsfRayCollector<T> collector(sys);
  const SpotResult<T> spots = trace_fields(sys, threads, collector);
  return psfs_from_rays(sys, spots, collector, channels, options, threads);
}

}  // namespace lensopt
