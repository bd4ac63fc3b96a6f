// RMS spot sizes (paper Eq. spot_loss), templated on the scalar, with the lens's wavelength and
// field weights as OpticStudio's RMS spot merit applies them.
//
// Definition: the mean RMS spot is the weighted mean over fields of each field's RMS spot radius,
// which is itself the wavelength-weighted RMS about the wavelength-weighted centroid. With
// wavelength weights omega_w and field weights phi_h (normalized to their largest, spot_weights),
// over the traced pupil rays p of field h and wavelength w (failed rays are left out):
//   M_h    = sum_w omega_w N_hw                                  (N_hw traced rays)
//   ybar_h = sum_{w,p} omega_w y / M_h,
//   S_h    = sqrt( sum_{w,p} omega_w ((y - ybar_h)^2 + x^2) / M_h ),
//   mean spot = sum_h phi_h S_h / sum_h phi_h.
// Equal weights give the paper's unweighted means (every normalized weight is exactly 1, so the
// sums are the unweighted ones bit for bit). A lens without weights (the paper's, its YAML) has
// equal weights; the paper's spec mode samples its own fields, each of weight 1.
// The x centroid is 0 by symmetry (half pupil, mirrored). A system that traces the full pupil
// (TraceSystem::full_pupil: some field's VDX or VAN is set) has an x centroid xbar_h as well:
//   xbar_h = sum_{w,p} omega_w x / M_h,
//   S_h    = sqrt( sum_{w,p} omega_w ((y - ybar_h)^2 + (x - xbar_h)^2) / M_h ),
// which is the formula above for a mirror-symmetric spot (xbar_h = 0). To keep precision when the
// spot is small compared with its height, sums are taken about a reference height y0 (the first
// traced ray): mean((y - ybar)^2) = mean((y - y0)^2) - (mean(y - y0))^2, exact for any y0; x is
// summed as it is (x_bar is of the order of the spot, not of the field height).
#pragma once

#include <omp.h>

#include <cmath>
#include <vector>

#include "lensopt/core/jet_width.h"
#include "lensopt/core/threads.h"
#include "lensopt/trace/system.h"

namespace lensopt {

template <typename T>
struct SpotResult {
  std::vector<T> rms_spot_mm;          // per field
  std::vector<T> centroid_y_mm;        // per field, over all wavelengths
  std::vector<T> centroid_x_mm;        // per field (0 unless the system traces full pupils)
  std::vector<int> traced_rays;        // per field: rays that reached the image (sys.pupil)
  std::vector<int> failed_rays;        // per field (vignetted rays are counted apart)
  std::vector<int> failed_by_surface;  // per surface where the failure happened
  std::vector<int> vignetted_rays;     // per field: rays clipped by a clear aperture
  std::vector<std::vector<int>> vignetted_by_field_surface;  // [field][surface]
  T mean_rms_spot_mm;
  int total_failed = 0;
};

// Accumulates the spot of one field over wavelengths.
template <typename T>
struct SpotAccumulator {
  bool full_pupil = false;  // the rays cover the full pupil: x has a centroid of its own
  bool has_reference = false;
  T y0 = K<T>(0.0);
  T sum_dy = K<T>(0.0);
  T sum_dy2 = K<T>(0.0);
  T sum_x2 = K<T>(0.0);
  T sum_x = K<T>(0.0);  // full_pupil only
  int count = 0;
  double weight_sum = 0.0;  // M_h: sum of the rays' weights (= count with unit weights)

  // The arrived rays of a bundle, each of weight `weight` (the wavelength's omega_w).
  void add(const RayBundle<T>& rays, double weight = 1.0) {
    for (std::size_t i = 0; i < rays.size(); ++i)
      if (rays.status[i] == kRayOk) add_ray(rays.x[i], rays.y[i], weight);
  }
  // One arrived ray at (x, y) mm of weight `weight`; the first one becomes the reference y0.
  // A weight of exactly 1 takes the unweighted sums (the same bits as without weights).
  void add_ray(const T& x, const T& y, double weight = 1.0) {
    if (!has_reference) {
      has_reference = true;
      y0 = y;
      sum_dy = K<T>(0.0);
      sum_dy2 = K<T>(0.0);
      sum_x2 = K<T>(0.0);
      sum_x = K<T>(0.0);
    }
    const T dy = y - y0;
    if (weight == 1.0) {
      sum_dy = sum_dy + dy;
      sum_dy2 = sum_dy2 + dy * dy;
      sum_x2 = sum_x2 + x * x;
      if (full_pupil) sum_x = sum_x + x;
    } else {
      const T w = K<T>(weight);
      sum_dy = sum_dy + w * dy;
      sum_dy2 = sum_dy2 + w * (dy * dy);
      sum_x2 = sum_x2 + w * (x * x);
      if (full_pupil) sum_x = sum_x + w * x;
    }
    ++count;
    weight_sum += weight;
  }
  // RMS radius (mm); 0 when no ray arrived (or every arrived ray has weight 0).
  T rms() const {
    using std::sqrt;
    if (count == 0 || !(weight_sum > 0.0)) return K<T>(0.0);
    const T inv = K<T>(1.0 / weight_sum);
    const T mean_dy = sum_dy * inv;
    T var = sum_dy2 * inv - mean_dy * mean_dy + sum_x2 * inv;
    if (full_pupil) {
      const T mean_x = sum_x * inv;
      var = var - mean_x * mean_x;
    }
    if (!(var > K<T>(0.0))) return K<T>(0.0);
    return sqrt(var);
  }
  T centroid() const {
    return count == 0 || !(weight_sum > 0.0) ? K<T>(0.0) : y0 + sum_dy * K<T>(1.0 / weight_sum);
  }
  // xbar_h: 0 for a mirrored half pupil (by symmetry).
  T centroid_x() const {
    return !full_pupil || count == 0 || !(weight_sum > 0.0) ? K<T>(0.0)
                                                            : sum_x * K<T>(1.0 / weight_sum);
  }
};

// The spot average's weights normalized to their largest: `weights` (one per item, >= 0) divided
// by their maximum, so equal weights are exactly 1. Wrong count, or no positive weight: all 1.
inline std::vector<double> normalized_spot_weights(const std::vector<double>& weights, int count) {
  std::vector<double> out(count, 1.0);
  if (static_cast<int>(weights.size()) != count) return out;
  double largest = 0.0;
  for (double v : weights)
    if (v > largest) largest = v;
  if (!(largest > 0.0) || !std::isfinite(largest)) return out;
  for (int i = 0; i < count; ++i) out[i] = weights[i] / largest;
  return out;
}

// omega_w (the system's wavelength weights) and phi_h (its field weights), normalized.
struct SpotWeights {
  std::vector<double> wavelength;  // W
  std::vector<double> field;       // F
  double field_sum = 0.0;          // sum_h phi_h (F with equal weights)
};
template <typename T>
SpotWeights spot_weights(const TraceSystem<T>& sys) {
  SpotWeights out;
  out.wavelength = normalized_spot_weights(sys.wavelength_weights, sys.wavelength_count);
  out.field = normalized_spot_weights(sys.field_weights, static_cast<int>(sys.fields_deg.size()));
  for (double v : out.field) out.field_sum += v;
  return out;
}

namespace detail {

// The ray slopes sx[i] = l[i] / n[i], sy[i] = m[i] / n[i] of `count` rays, built for several
// x86-64 levels (src/analysis/spot_moments.cpp). Each quotient is correctly rounded, so every
// build gives the same bits as the scalar division.
void ray_slopes(const double* l, const double* m, const double* n, std::size_t count, double* sx,
                double* sy);

}  // namespace detail

// The spot of one field through focus: SpotAccumulator's sums plus those of the ray slopes, so the
// spot on a plane shifted by tau (mm) along the axis follows without tracing again. A ray at
// (x, y) on the reference plane with slopes (sx, sy) = (l/n, m/n) lands at (x + tau sx,
// y + tau sy). With dy = y - y0, ds = sy - sy0 (y0, sy0 of the first ray):
//   S^2(tau) = var(dy) + 2 tau cov(dy, ds) + tau^2 var(ds) + E[x^2] + 2 tau E[x sx] + tau^2 E[sx^2]
// At tau = 0 it is SpotAccumulator's rms and centroid, the same numbers. On a full pupil
// (spot.full_pupil) x is taken about its centroid too: the x terms become
//   var(x) + 2 tau cov(x, sx) + tau^2 var(sx).
struct ThroughFocusSpot {
  SpotAccumulator<double> spot;  // the tau = 0 moments: y0, sum_dy, sum_dy2, sum_x2, count
  double sy0 = 0;
  double sum_ds = 0, sum_dyds = 0, sum_ds2 = 0, sum_xsx = 0, sum_sx2 = 0;
  double sum_sx = 0;  // spot.full_pupil only

  int count() const { return spot.count; }
  void add(const RayBundle<double>& rays, double weight = 1.0) {
    std::vector<double> slopes;
    add(rays, slopes, weight);
  }
  // The same with a scratch buffer for the slopes (reused across calls, no allocation). Each ray
  // has weight `weight` (the wavelength's omega_w, as SpotAccumulator; 1: the unweighted sums).
  void add(const RayBundle<double>& rays, std::vector<double>& slopes, double weight = 1.0) {
    const std::size_t count = rays.size();
    slopes.resize(2 * count);
    double* slope_x = slopes.data();
    double* slope_y = slope_x + count;
    detail::ray_slopes(rays.l.data(), rays.m.data(), rays.n.data(), count, slope_x, slope_y);
    for (std::size_t i = 0; i < count; ++i) {
      if (rays.status[i] != kRayOk) continue;
      const double sy = slope_y[i];
      const double sx = slope_x[i];
      if (!spot.has_reference) sy0 = sy;
      spot.add_ray(rays.x[i], rays.y[i], weight);
      const double dy = rays.y[i] - spot.y0;
      const double ds = sy - sy0;
      if (weight == 1.0) {
        sum_ds += ds;
        sum_dyds += dy * ds;
        sum_ds2 += ds * ds;
        sum_xsx += rays.x[i] * sx;
        sum_sx2 += sx * sx;
        if (spot.full_pupil) sum_sx += sx;
      } else {
        sum_ds += weight * ds;
        sum_dyds += weight * (dy * ds);
        sum_ds2 += weight * (ds * ds);
        sum_xsx += weight * (rays.x[i] * sx);
        sum_sx2 += weight * (sx * sx);
        if (spot.full_pupil) sum_sx += weight * sx;
      }
    }
  }
  // S^2(tau) (mm^2).
  double variance(double tau) const {
    const double inv = 1.0 / spot.weight_sum;
    const double mean_dy = spot.sum_dy * inv;
    const double mean_ds = sum_ds * inv;
    double a = spot.sum_dy2 * inv - mean_dy * mean_dy + spot.sum_x2 * inv;
    double b = sum_dyds * inv - mean_dy * mean_ds + sum_xsx * inv;
    double c = sum_ds2 * inv - mean_ds * mean_ds + sum_sx2 * inv;
    if (spot.full_pupil) {
      const double mean_x = spot.sum_x * inv, mean_sx = sum_sx * inv;
      a -= mean_x * mean_x;
      b -= mean_x * mean_sx;
      c -= mean_sx * mean_sx;
    }
    return a + tau * (2.0 * b + tau * c);
  }
  // RMS radius (mm) at shift tau; 0 when no ray arrived.
  double rms(double tau) const {
    if (spot.count == 0 || !(spot.weight_sum > 0.0)) return 0.0;
    if (tau == 0.0) return spot.rms();
    const double v = variance(tau);
    return v > 0.0 ? std::sqrt(v) : 0.0;
  }
  // Centroid height (mm) at shift tau: y0 + tau sy0 + mean(dy + tau ds).
  double centroid(double tau) const {
    if (spot.count == 0 || !(spot.weight_sum > 0.0)) return 0.0;
    if (tau == 0.0) return spot.centroid();
    const double inv = 1.0 / spot.weight_sum;
    return spot.y0 + tau * sy0 + (spot.sum_dy + tau * sum_ds) * inv;
  }
};

// Traces every field, wavelength and pupil sample of `sys` once and returns the spot sizes.
// Fields are spread over threads (OpenMP); `threads` <= 0 uses all. `on_rays(h, w, rays)` is
// called with every traced bundle (field h, spec wavelength w) inside the parallel loop, from
// the thread that traces field h: whatever it stores per field is written by one thread only.
// This is the one trace of the field products (analysis/field_optics.h measure_fields, the
// geometric PSFs of render/psf.h): they read these rays instead of tracing their own.
template <typename T, typename OnRays>
SpotResult<T> trace_fields(const TraceSystem<T>& sys, int threads, OnRays&& on_rays) {
  const int field_count = static_cast<int>(sys.fields_deg.size());
  SpotResult<T> out;
  out.rms_spot_mm.assign(field_count, K<T>(0.0));
  out.centroid_y_mm.assign(field_count, K<T>(0.0));
  out.centroid_x_mm.assign(field_count, K<T>(0.0));
  out.traced_rays.assign(field_count, 0);
  out.failed_rays.assign(field_count, 0);
  out.failed_by_surface.assign(sys.lens.surface_count(), 0);
  std::vector<std::vector<int>> failed_at(field_count,
                                          std::vector<int>(sys.lens.surface_count(), 0));
  out.vignetted_rays.assign(field_count, 0);
  out.vignetted_by_field_surface.assign(field_count, std::vector<int>(sys.lens.surface_count(), 0));
  const SpotWeights weights = spot_weights(sys);
  const int nthreads = thread_count(threads);
#pragma omp parallel num_threads(nthreads)
  {
    RayBundle<T> rays;
#pragma omp for schedule(dynamic, 1)
    for (int h = 0; h < field_count; ++h) {
      SpotAccumulator<T> acc;
      acc.full_pupil = sys.full_pupil;
      int failed = 0;
      for (int w = 0; w < sys.wavelength_count; ++w) {
        start_rays(sys, h, w, rays);
        trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                     static_cast<RayRecord<T>*>(nullptr));
        for (std::size_t i = 0; i < rays.size(); ++i) {
          if (rays.status[i] == kRayOk) continue;
          if (rays.status[i] == kRayVignetted) {
            ++out.vignetted_rays[h];
            ++out.vignetted_by_field_surface[h][rays.failed_surface[i]];
            continue;
          }
          ++failed;
          if (rays.failed_surface[i] >= 0) ++failed_at[h][rays.failed_surface[i]];
        }
        acc.add(rays, weights.wavelength[w]);
        on_rays(h, w, static_cast<const RayBundle<T>&>(rays));
      }
      out.rms_spot_mm[h] = acc.rms();
      out.centroid_y_mm[h] = acc.centroid();
      out.centroid_x_mm[h] = acc.centroid_x();
      out.traced_rays[h] = acc.count;
      out.failed_rays[h] = failed;
    }
  }
  T sum = K<T>(0.0);
  for (int h = 0; h < field_count; ++h) {
    if (weights.field[h] == 1.0)
      sum = sum + out.rms_spot_mm[h];
    else
      sum = sum + K<T>(weights.field[h]) * out.rms_spot_mm[h];
    out.total_failed += out.failed_rays[h];
    for (int k = 0; k < sys.lens.surface_count(); ++k) out.failed_by_surface[k] += failed_at[h][k];
  }
  // sum_h phi_h S_h / sum_h phi_h (the sum of the weights is F, exactly, when they are equal).
  out.mean_rms_spot_mm = weights.field_sum > 0.0 ? sum / K<T>(weights.field_sum) : K<T>(0.0);
  return out;
}

// The spot sizes alone (trace_fields without a reader of the rays).
template <typename T>
SpotResult<T> evaluate_spots(const TraceSystem<T>& sys, int threads = 0) {
  return trace_fields(sys, threads, [](int, int, const RayBundle<T>&) {});
}

// evaluate_spots on the Jets of core/jet_width.h is compiled once per width, in a translation unit
// of its own (src/analysis/spot_jet.cpp.in).
#define LENSOPT_EVALUATE_SPOTS_JET(N)                                                      \
  extern template SpotResult<ceres::Jet<double, N>> evaluate_spots<ceres::Jet<double, N>>( \
      const TraceSystem<ceres::Jet<double, N>>&, int);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_EVALUATE_SPOTS_JET)
#undef LENSOPT_EVALUATE_SPOTS_JET

}  // namespace lensopt
