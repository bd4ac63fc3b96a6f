// The exact ray-trace kernel, one template for double and ceres::Jet.
//
// Rays are batched structure-of-arrays. Before surface k a ray's position (x, y, z) is relative
// to the vertex of surface k-1 (of surface 0 at the start); its direction cosines (l, m, n) have
// unit length with n > 0. For each surface k with curvature c:
//   1. Shift to vertex k:            z <- z - t_{k-1}
//   2. Transfer to the vertex plane: s0 = -z / n,  (x1, y1) = (x, y) + s0 (l, m)
//   3. Intersect the sphere c (x^2 + y^2 + z^2) - 2 z = 0 from (x1, y1, 0):
//        F = c (x1^2 + y1^2),  G = n - c (x1 l + y1 m),  zeta = G^2 - c F = cos^2(I)
//        s1 = F / (G + sqrt(zeta))       (finite and exact as c -> 0: a flat surface gives s1 = 0)
//      zeta < 0: the ray misses the surface (failure flag, never NaN).
//   4. Refract (Snell, vector form) with mu = n_before / n_after and unit normal
//      N = (-c x, -c y, 1 - c z):
//        zeta' = 1 - mu^2 (1 - zeta) = cos^2(I'),  zeta' < 0: total internal reflection
//        d' = mu d + (sqrt(zeta') - mu sqrt(zeta)) N
//   5. Clear aperture (only at a surface with a semi-diameter r_k > 0): a ray whose intersection
//      has x2^2 + y2^2 > r_k^2 is vignetted (kRayVignetted; a select, not a jump).
// Steps 3-4 are those of a sphere; a conic or even-asphere surface (TraceLens::profile) runs the
// loops of trace/profile.h instead (closed-form conic, Newton for the asphere), one loop per
// surface, so an all-spherical lens runs exactly this sphere loop. In double every loop is built
// for several x86-64 levels (src/trace/kernel_double.cpp).
// After the last surface the ray is transferred to the image plane at t_{K-1}.
// Per ray and surface the kernel can record what the design losses need: the axial travel
// dz_k = t_k + z_{k+1} - z_k in every space k (after surface k, the last one up to the image),
// and zeta, zeta' at every surface; optionally the optical path (wave optics, analysis/wavefront.h)
//   OPL += n_{k-1} s_k,  s_k = (z_k - z_{k-1}') / n_dir   (geometric length of the segment that
// ends on surface k; z_{k-1}' the start point's z in vertex-k coordinates, n_dir the segment's
// z direction cosine), and n_{K-1} s for the last segment to the image plane.
#pragma once

#include <cstdint>
#include <type_traits>
#include <vector>

#include "lensopt/core/jet_width.h"
#include "lensopt/core/scalar.h"
#include "lensopt/lens/trace_lens.h"

namespace lensopt {

// Per-ray status: 0 = traced; otherwise the failure kind (the first one wins).
enum RayStatus : std::uint8_t {
  kRayOk = 0,
  kRayMissedSurface = 1,            // zeta < 0: no intersection with the sphere
  kRayTotalInternalReflection = 2,  // zeta' < 0
  kRayBackwards = 3,                // direction with n <= 0 (cannot reach the next surface)
  kRayVignetted = 4,                // outside a surface's clear semi-diameter (x^2 + y^2 > r^2)
};

}  // namespace lensopt

#include "lensopt/trace/profile.h"  // needs RayStatus

namespace lensopt {

// A batch of rays, structure of arrays. All arrays have size() entries.
template <typename T>
struct RayBundle {
  std::vector<T> x, y, z;  // mm
  std::vector<T> l, m, n;  // direction cosines
  std::vector<std::uint8_t> status;
  std::vector<std::int8_t> failed_surface;    // surface index of the failure, -1 if none
  std::vector<std::int32_t> failure_scratch;  // per-surface failure codes (kernel scratch)

  void resize(std::size_t count) {
    x.resize(count);
    y.resize(count);
    z.resize(count);
    l.resize(count);
    m.resize(count);
    n.resize(count);
    status.assign(count, kRayOk);
    failed_surface.assign(count, -1);
  }
  std::size_t size() const { return x.size(); }
};

// Optional per-ray records for the design losses. Arrays are [surface][ray].
template <typename T>
struct RayRecord {
  std::vector<std::vector<T>> axial_travel_mm;  // K spaces: after surface k (the last: to image)
  std::vector<std::vector<T>> cos2_incidence;   // K surfaces: zeta
  std::vector<std::vector<T>> cos2_refraction;  // K surfaces: zeta'
  // Optical path (mm) per ray, accumulated only when sized to the ray count: the kernel adds
  // every segment's n s to the value the caller set (the path before the first point).
  std::vector<T> optical_path_mm;
  std::vector<T> path_start_z, path_start_n;  // kernel scratch for the optical path

  // Every array zeroed; a record resized again to the same shape reuses its memory.
  void resize(int surface_count, std::size_t ray_count, bool optical_path = false) {
    auto fit = [&](std::vector<std::vector<T>>& arrays) {
      arrays.resize(surface_count);
      for (std::vector<T>& a : arrays) a.assign(ray_count, K<T>(0.0));
    };
    fit(axial_travel_mm);
    fit(cos2_incidence);
    fit(cos2_refraction);
    optical_path_mm.assign(optical_path ? ray_count : 0, K<T>(0.0));
    path_start_z.resize(optical_path ? ray_count : 0);
    path_start_n.resize(optical_path ? ray_count : 0);
  }
};

namespace detail {

// Steps 1-4 of the header for every ray at one surface. Branch-free in the ray loop (selects,
// not jumps) so that the double instantiation vectorizes; kRecord adds the loss records.
template <typename T, bool kRecord>
inline __attribute__((always_inline)) void trace_surface(
    const T& c, const T& shift, const T& mu, std::size_t count, T* __restrict x, T* __restrict y,
    T* __restrict z, T* __restrict l, T* __restrict m, T* __restrict n,
    std::int32_t* __restrict failure, T* __restrict travel, T* __restrict zeta_out,
    T* __restrict zeta_prime_out) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  const T mu2 = mu * mu;
  for (std::size_t i = 0; i < count; ++i) {
    // Shift to vertex k and transfer to its tangent plane.
    const T z_rel = z[i] - shift;
    const T s0 = -z_rel / n[i];
    const T x1 = x[i] + s0 * l[i];
    const T y1 = y[i] + s0 * m[i];
    // Intersect the sphere.
    const T f = c * (x1 * x1 + y1 * y1);
    const T g = n[i] - c * (x1 * l[i] + y1 * m[i]);
    const T zeta_raw = g * g - c * f;
    const bool miss = zeta_raw < zero;
    const T zeta = miss ? one : zeta_raw;  // keep numbers finite; the ray is flagged
    const T cos_i = sqrt(zeta);
    const T s1 = f / (g + cos_i);
    const T x2 = x1 + s1 * l[i];
    const T y2 = y1 + s1 * m[i];
    const T z2 = s1 * n[i];
    // Refract.
    const T zeta_prime_raw = one - mu2 * (one - zeta);
    const bool tir = zeta_prime_raw < zero;
    const T zeta_prime = tir ? zeta : zeta_prime_raw;
    if constexpr (kRecord) {
      if (travel) travel[i] = z2 - z_rel;
      zeta_out[i] = zeta_raw;              // before clamping: a miss shows as zeta < 0
      zeta_prime_out[i] = zeta_prime_raw;  // before clamping: TIR shows as zeta' < 0
    }
    failure[i] = miss ? kRayMissedSurface : (tir ? kRayTotalInternalReflection : kRayOk);
    const T gamma = sqrt(zeta_prime) - mu * cos_i;
    l[i] = mu * l[i] - gamma * c * x2;
    m[i] = mu * m[i] - gamma * c * y2;
    n[i] = mu * n[i] + gamma * (one - c * z2);
    x[i] = x2;
    y[i] = y2;
    z[i] = z2;
  }
}

// The double instantiation, compiled for several instruction sets (function multi-versioning,
// src/trace/kernel_double.cpp) and picked at load time: AVX-512 / AVX2+FMA where the CPU has
// them, plain x86-64 elsewhere.
void trace_surface_double(double c, double shift, double mu, std::size_t count, double* x,
                          double* y, double* z, double* l, double* m, double* n,
                          std::int32_t* failure, double* travel, double* zeta_out,
                          double* zeta_prime_out, bool record);

}  // namespace detail

namespace detail {

// Whether some direction cosine n[i] is not > 0 (or NaN): a ray that cannot travel forwards.
template <typename T>
bool any_not_forward(const T* n, std::size_t count) {
  if constexpr (std::is_same_v<T, double>) {
    // Branch-free count (vectorizes): !(n > 0) is true for n <= 0 and for NaN.
    std::size_t bad = 0;
    for (std::size_t i = 0; i < count; ++i) bad += !(n[i] > 0.0);
    return bad != 0;
  } else {
    for (std::size_t i = 0; i < count; ++i)
      if (!(n[i] > K<T>(0.0))) return true;
    return false;
  }
}

}  // namespace detail

namespace detail {

// The Jet traces of the widths of core/jet_width.h, compiled once each for several x86-64 levels
// with every Jet operation inlined (src/trace/kernel_jet.cpp.in, one translation unit per width).
#define LENSOPT_DECLARE_JET_TRACE(N)                                                  \
  void trace_bundle_jet(const TraceLens<ceres::Jet<double, N>>& lens, int w, int end, \
                        bool to_image, RayBundle<ceres::Jet<double, N>>& rays,        \
                        RayRecord<ceres::Jet<double, N>>* record);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_DECLARE_JET_TRACE)
#undef LENSOPT_DECLARE_JET_TRACE

}  // namespace detail

// trace_bundle (below) on ceres::Jet<double, N> for a listed width N: the compiled trace above.
template <int N>
requires(is_jet_width(N)) void trace_bundle(const TraceLens<ceres::Jet<double, N>>& lens, int w,
                                            int end, bool to_image,
                                            RayBundle<ceres::Jet<double, N>>& rays,
                                            RayRecord<ceres::Jet<double, N>>* record) {
  detail::trace_bundle_jet(lens, w, end, to_image, rays, record);
}

// Traces every ray of `rays` through surfaces [0, end) at wavelength number w (end = K for the
// whole lens), leaving positions relative to vertex end-1 on that surface. If `to_image`, rays
// continue to the image plane (end must be K) and end with z = 0 relative to the image plane.
// `record` may be null.
template <typename T>
void trace_bundle(const TraceLens<T>& lens, int w, int end, bool to_image, RayBundle<T>& rays,
                  RayRecord<T>* record) {
  using std::sqrt;
  const std::size_t count = rays.size();
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  T* x = rays.x.data();
  T* y = rays.y.data();
  T* z = rays.z.data();
  T* l = rays.l.data();
  T* m = rays.m.data();
  T* n = rays.n.data();
  std::uint8_t* status = rays.status.data();
  std::int8_t* failed_at = rays.failed_surface.data();
  rays.failure_scratch.resize(count);
  std::int32_t* failure = rays.failure_scratch.data();
  // Optical path: only on the recording path, so the plain trace is untouched.
  const bool path = record && record->optical_path_mm.size() == count;
  T* opl = path ? record->optical_path_mm.data() : nullptr;
  T* start_z = path ? record->path_start_z.data() : nullptr;
  T* start_n = path ? record->path_start_n.data() : nullptr;

  // A ray must travel forwards. The checks below first ask whether any ray needs the
  // bookkeeping (a reduction that vectorizes), so a bundle without failures, the usual case,
  // skips the per-ray status loops.
  if (detail::any_not_forward(n, count)) {
    for (std::size_t i = 0; i < count; ++i) {
      if (!(n[i] > zero) && status[i] == kRayOk) {
        status[i] = kRayBackwards;
        failed_at[i] = 0;
        n[i] = one;
      }
    }
  }

  for (int k = 0; k < end; ++k) {
    const T c = lens.curvature_per_mm[k];
    const T shift = k > 0 ? lens.thickness_mm[k - 1] : zero;
    const T mu = lens.index(k - 1, w) / lens.index(k, w);
    if (path) {
      for (std::size_t i = 0; i < count; ++i) {
        start_z[i] = z[i] - shift;
        start_n[i] = n[i] > zero ? n[i] : one;  // a backwards ray is flagged; keep it finite
      }
    }
    const std::uint8_t profile = lens.has_profiles() ? lens.profile[k] : kProfileSphere;
    if (profile != kProfileSphere) {
      // Conic or even asphere (trace/profile.h).
      T* travel = record && k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr;
      T* zeta_rec = record ? record->cos2_incidence[k].data() : nullptr;
      T* zeta_prime_rec = record ? record->cos2_refraction[k].data() : nullptr;
      const T& conic = lens.conic[k];
      const T* a = lens.asphere.data() + static_cast<std::size_t>(k) * kAsphereTerms;
      if constexpr (std::is_same_v<T, double>) {
        detail::trace_surface_profile_double(profile, c, conic, a, shift, mu, count, x, y, z, l, m,
                                             n, failure, travel, zeta_rec, zeta_prime_rec,
                                             record != nullptr);
      } else if (profile == kProfileConic) {
        if (record)
          detail::trace_surface_conic<T, true>(c, conic, shift, mu, count, x, y, z, l, m, n,
                                               failure, travel, zeta_rec, zeta_prime_rec);
        else
          detail::trace_surface_conic<T, false>(c, conic, shift, mu, count, x, y, z, l, m, n,
                                                failure, nullptr, nullptr, nullptr);
      } else if (record) {
        detail::trace_surface_asphere<T, true>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                               failure, travel, zeta_rec, zeta_prime_rec);
      } else {
        detail::trace_surface_asphere<T, false>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                                failure, nullptr, nullptr, nullptr);
      }
    } else if constexpr (std::is_same_v<T, double>) {
      detail::trace_surface_double(
          c, shift, mu, count, x, y, z, l, m, n, failure,
          record && k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr,
          record ? record->cos2_incidence[k].data() : nullptr,
          record ? record->cos2_refraction[k].data() : nullptr, record != nullptr);
    } else if (record) {
      detail::trace_surface<T, true>(c, shift, mu, count, x, y, z, l, m, n, failure,
                                     k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr,
                                     record->cos2_incidence[k].data(),
                                     record->cos2_refraction[k].data());
    } else {
      detail::trace_surface<T, false>(c, shift, mu, count, x, y, z, l, m, n, failure, nullptr,
                                      nullptr, nullptr);
    }
    // Step 5: the clear aperture of surface k, if it has one.
    if (!lens.semi_diameter_mm.empty() && lens.semi_diameter_mm[k] > 0.0) {
      const T limit = K<T>(lens.semi_diameter_mm[k] * lens.semi_diameter_mm[k]);
      for (std::size_t i = 0; i < count; ++i) {
        const bool outside = x[i] * x[i] + y[i] * y[i] > limit;
        failure[i] = (outside && failure[i] == kRayOk) ? std::int32_t{kRayVignetted} : failure[i];
      }
    }
    if (path) {
      const T n_before = lens.index(k - 1, w);
      for (std::size_t i = 0; i < count; ++i)
        opl[i] = opl[i] + n_before * (z[i] - start_z[i]) / start_n[i];
    }
    // The first failure of a ray wins.
    std::int32_t any_failure = 0;
    for (std::size_t i = 0; i < count; ++i) any_failure |= failure[i];
    if (any_failure != 0) {
      for (std::size_t i = 0; i < count; ++i) {
        if (failure[i] != kRayOk && status[i] == kRayOk) {
          status[i] = static_cast<std::uint8_t>(failure[i]);
          failed_at[i] = static_cast<std::int8_t>(k);
        }
      }
    }
  }

  if (to_image) {
    const int last = lens.surface_count() - 1;
    const T t = lens.thickness_mm[last];
    T* travel = record ? record->axial_travel_mm[last].data() : nullptr;
    const T n_image = path ? lens.index(last, w) : one;
    if (!travel && !path && !detail::any_not_forward(n, count)) {
      // Every ray travels forwards: the same transfer without the per-ray branch.
      for (std::size_t i = 0; i < count; ++i) {
        const T s = -(z[i] - t) / n[i];
        x[i] = x[i] + s * l[i];
        y[i] = y[i] + s * m[i];
        z[i] = zero;
      }
      return;
    }
    for (std::size_t i = 0; i < count; ++i) {
      const T z_rel = z[i] - t;
      if (travel) travel[i] = -z_rel;
      if (!(n[i] > zero)) {
        if (status[i] == kRayOk) {
          status[i] = kRayBackwards;
          failed_at[i] = static_cast<std::int8_t>(last);
        }
        continue;
      }
      const T s = -z_rel / n[i];
      if (path) opl[i] = opl[i] + n_image * s;
      x[i] = x[i] + s * l[i];
      y[i] = y[i] + s * m[i];
      z[i] = zero;
    }
  }
}

}  // namespace lensopt
