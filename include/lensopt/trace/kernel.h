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
//
// Mirrors (issue 32): reflection is refraction into the index -n (TraceLens::index is negative
// in a medium traversed backwards, after an odd number of mirrors). The kernel carries the
// direction d_s = sign(n_k) d, so a reflected ray keeps n_s > 0 in a medium whose thicknesses
// are negative (OpticStudio's convention): with mu = n / (-n) = -1, step 4 gives
// d' = -d + 2 cos(I) N = -(d - 2 cos(I) N), the reflected direction with the sign of the medium;
// refraction of -d is -(refraction of d) (Snell's law reversed), the transfers s0 = -z / n_s move
// along the true line, and OPL += n_{k-1} s stays positive (both factors change sign). The
// rotationally symmetric loops therefore trace mirrors unchanged.
// 3D placement (TraceGeometry, lens.h Placement): a lens with a decenter, tilt, coordinate break
// or decentred aperture runs trace_bundle_placed instead: before surface k the ray is shifted by
// t_{k-1} along the current z and, if the surface is placed, turned into its frame,
//   p_local = R^T (p - D), d_local = R^T d   (decenter first; tilt first: R^T p - D),
// then steps 2-5 run in that frame with shift 0 (apertures and obscurations about their centre).
// A coordinate break only changes the frame; a restore_frame surface turns the ray back to the
// parent frame after it (p = D + R p_local). Everything after a placed surface is in its frame.
// The image plane is z = t_{K-1} in the last frame, reached along the ray's line in either
// direction. A lens without placements never enters that path: the loops above run as before.
#pragma once

#include <cstdint>
#include <type_traits>
#include <vector>

#include "lensopt/core/constants.h"
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
  // The field frame (trace/system.h, TraceSystem::field_azimuth_deg): the rays of a field off the
  // y axis of a lens with 3D placements are started in the frame turned about z by the field's
  // azimuth a, where the field lies on +y. The placed path turns them into the lens frame,
  // (x, y) -> (c x + s y, -s x + c y) with c = cos a, s = sin a (and so l, m), before surface 1,
  // and back after the last surface traced, so positions and directions come out in the field
  // frame. The rotationally symmetric path ignores it (the lens commutes with the turn).
  double frame_cos = 1.0, frame_sin = 0.0;
  bool turned() const { return frame_sin != 0.0 || frame_cos != 1.0; }

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

// The selects of the sphere step on one ray (a scalar T, a bool mask). A pack of rays
// (trace/dual.h, DualPack) overloads them lane by lane, found by argument-dependent lookup.
template <typename T>
inline __attribute__((always_inline)) T sphere_select(bool mask, const T& a, const T& b) {
  return mask ? a : b;
}
inline __attribute__((always_inline)) std::int32_t sphere_failure(bool miss, bool tir) {
  return miss ? kRayMissedSurface : (tir ? kRayTotalInternalReflection : kRayOk);
}

// Steps 1-4 of the header for one ray (or one pack of rays, trace/dual.h) at one surface, in
// place: the one implementation of the sphere's physics, shared by trace_surface below and the
// compiled Jet loop (src/trace/kernel_jet.cpp.in). mu2 = mu * mu, one and zero are the constants
// K<T>(1.0) and K<T>(0.0). With kRecord, *travel (when travel is not null), *zeta_out and
// *zeta_prime_out receive the loss records.
template <typename T, bool kRecord, typename Failure>
inline __attribute__((always_inline)) void sphere_step(const T& c, const T& shift, const T& mu,
                                                       const T& mu2, const T& one, const T& zero,
                                                       T& x, T& y, T& z, T& l, T& m, T& n,
                                                       Failure& failure, T* travel, T* zeta_out,
                                                       T* zeta_prime_out) {
  using std::sqrt;
  // Shift to vertex k and transfer to its tangent plane.
  const T z_rel = z - shift;
  const T s0 = -z_rel / n;
  const T x1 = x + s0 * l;
  const T y1 = y + s0 * m;
  // Intersect the sphere.
  const T f = c * (x1 * x1 + y1 * y1);
  const T g = n - c * (x1 * l + y1 * m);
  const T zeta_raw = g * g - c * f;
  const auto miss = zeta_raw < zero;
  const T zeta = sphere_select(miss, one, zeta_raw);  // keep numbers finite; the ray is flagged
  const T cos_i = sqrt(zeta);
  const T s1 = f / (g + cos_i);
  const T x2 = x1 + s1 * l;
  const T y2 = y1 + s1 * m;
  const T z2 = s1 * n;
  // Refract.
  const T zeta_prime_raw = one - mu2 * (one - zeta);
  const auto tir = zeta_prime_raw < zero;
  const T zeta_prime = sphere_select(tir, zeta, zeta_prime_raw);
  if constexpr (kRecord) {
    if (travel) *travel = z2 - z_rel;
    *zeta_out = zeta_raw;              // before clamping: a miss shows as zeta < 0
    *zeta_prime_out = zeta_prime_raw;  // before clamping: TIR shows as zeta' < 0
  }
  failure = sphere_failure(miss, tir);
  const T gamma = sqrt(zeta_prime) - mu * cos_i;
  l = mu * l - gamma * c * x2;
  m = mu * m - gamma * c * y2;
  n = mu * n + gamma * (one - c * z2);
  x = x2;
  y = y2;
  z = z2;
}

// Steps 1-4 of the header for every ray at one surface. Branch-free in the ray loop (selects,
// not jumps) so that the double instantiation vectorizes; kRecord adds the loss records.
template <typename T, bool kRecord>
inline __attribute__((always_inline)) void trace_surface(
    const T& c, const T& shift, const T& mu, std::size_t count, T* __restrict x, T* __restrict y,
    T* __restrict z, T* __restrict l, T* __restrict m, T* __restrict n,
    std::int32_t* __restrict failure, T* __restrict travel, T* __restrict zeta_out,
    T* __restrict zeta_prime_out) {
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  const T mu2 = mu * mu;
  for (std::size_t i = 0; i < count; ++i) {
    if constexpr (kRecord)
      sphere_step<T, true>(c, shift, mu, mu2, one, zero, x[i], y[i], z[i], l[i], m[i], n[i],
                           failure[i], travel ? travel + i : nullptr, zeta_out + i,
                           zeta_prime_out + i);
    else
      sphere_step<T, false>(c, shift, mu, mu2, one, zero, x[i], y[i], z[i], l[i], m[i], n[i],
                            failure[i], nullptr, nullptr, nullptr);
  }
}

// The double instantiation, compiled for several instruction sets (function multi-versioning,
// src/trace/kernel_double.cpp) and picked at load time: AVX-512 / AVX2+FMA where the CPU has
// them, plain x86-64 elsewhere.
void trace_surface_double(double c, double shift, double mu, std::size_t count, double* x,
                          double* y, double* z, double* l, double* m, double* n,
                          std::int32_t* failure, double* travel, double* zeta_out,
                          double* zeta_prime_out, bool record);

// The sphere loop (trace_surface) on ceres::Jet<double, N> of the listed widths, compiled for
// several x86-64 levels with the Jets' derivative arithmetic vectorized at each level's width
// (src/trace/kernel_jet.cpp.in, trace/dual.h): the bits of trace_surface<Jet, kRecord>. Used by
// the compiled Jet trace (trace_bundle_jet); `record`: whether the zeta records are written.
// trace_surface_jet_at runs the copy compiled for `level` (4, 3, else the baseline level;
// jet_trace_level() in trace/dual.h gives this CPU's), for the tests: a level the CPU lacks must
// not be asked for.
// clang-format off
#define LENSOPT_JET_SURFACE_PARAMETERS(N)                                          \
  const ceres::Jet<double, N>& c, const ceres::Jet<double, N>& shift,              \
  const ceres::Jet<double, N>& mu, std::size_t count, ceres::Jet<double, N>* x,    \
  ceres::Jet<double, N>* y, ceres::Jet<double, N>* z, ceres::Jet<double, N>* l,    \
  ceres::Jet<double, N>* m, ceres::Jet<double, N>* n, std::int32_t* failure,       \
  ceres::Jet<double, N>* travel, ceres::Jet<double, N>* zeta_out,                  \
  ceres::Jet<double, N>* zeta_prime_out, bool record
// clang-format on
#define LENSOPT_DECLARE_JET_SURFACE(N)                       \
  void trace_surface_jet(LENSOPT_JET_SURFACE_PARAMETERS(N)); \
  void trace_surface_jet_at(int level, LENSOPT_JET_SURFACE_PARAMETERS(N));
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_DECLARE_JET_SURFACE)
#undef LENSOPT_DECLARE_JET_SURFACE
#undef LENSOPT_JET_SURFACE_PARAMETERS

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

// Steps 1-4 at surface k (the sphere loop, or the profile loops of trace/profile.h). Always
// inlined, so that the symmetric driver compiles to the code it had with the dispatch written in
// it (not inlined, the Jet loops ran 3x slower: c, shift and mu became references the compiler
// could not keep in registers). kCompiled (the compiled Jet trace, trace_bundle_jet): the sphere
// loop of a Jet of a listed width runs trace_surface_jet, the same bits.
template <typename T, bool kCompiled = false>
inline __attribute__((always_inline)) void intersect_surface(
    const TraceLens<T>& lens, int k, const T& c, const T& shift, const T& mu, std::size_t count,
    T* x, T* y, T* z, T* l, T* m, T* n, std::int32_t* failure, RayRecord<T>* record) {
  const std::uint8_t profile = lens.has_profiles() ? lens.profile[k] : kProfileSphere;
  if (profile != kProfileSphere) {
    // Conic or even asphere (trace/profile.h).
    T* travel = record && k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr;
    T* zeta_rec = record ? record->cos2_incidence[k].data() : nullptr;
    T* zeta_prime_rec = record ? record->cos2_refraction[k].data() : nullptr;
    const T& conic = lens.conic[k];
    const T* a = lens.asphere.data() + static_cast<std::size_t>(k) * kAsphereTerms;
    if constexpr (std::is_same_v<T, double>) {
      detail::trace_surface_profile_double(profile, c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                           failure, travel, zeta_rec, zeta_prime_rec,
                                           record != nullptr);
    } else if (profile == kProfileConic) {
      if (record)
        detail::trace_surface_conic<T, true>(c, conic, shift, mu, count, x, y, z, l, m, n, failure,
                                             travel, zeta_rec, zeta_prime_rec);
      else
        detail::trace_surface_conic<T, false>(c, conic, shift, mu, count, x, y, z, l, m, n, failure,
                                              nullptr, nullptr, nullptr);
    } else if (record) {
      detail::trace_surface_asphere<T, true>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                             failure, travel, zeta_rec, zeta_prime_rec);
    } else {
      detail::trace_surface_asphere<T, false>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                              failure, nullptr, nullptr, nullptr);
    }
  } else if constexpr (std::is_same_v<T, double>) {
    detail::trace_surface_double(c, shift, mu, count, x, y, z, l, m, n, failure,
                                 record && k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr,
                                 record ? record->cos2_incidence[k].data() : nullptr,
                                 record ? record->cos2_refraction[k].data() : nullptr,
                                 record != nullptr);
  } else if constexpr (kCompiled) {
    detail::trace_surface_jet(c, shift, mu, count, x, y, z, l, m, n, failure,
                              record && k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr,
                              record ? record->cos2_incidence[k].data() : nullptr,
                              record ? record->cos2_refraction[k].data() : nullptr,
                              record != nullptr);
  } else if (record) {
    detail::trace_surface<T, true>(c, shift, mu, count, x, y, z, l, m, n, failure,
                                   k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr,
                                   record->cos2_incidence[k].data(),
                                   record->cos2_refraction[k].data());
  } else {
    detail::trace_surface<T, false>(c, shift, mu, count, x, y, z, l, m, n, failure, nullptr,
                                    nullptr, nullptr);
  }
}

}  // namespace detail

namespace detail {

// A central obscuration of radius r centred at (cx, cy): a ray inside is vignetted.
template <typename T>
inline void obscure(double r, double cx, double cy, std::size_t count, const T* x, const T* y,
                    std::int32_t* failure) {
  const T limit = K<T>(r * r);
  const T ox = K<T>(cx), oy = K<T>(cy);
  for (std::size_t i = 0; i < count; ++i) {
    const T dx = x[i] - ox, dy = y[i] - oy;
    const bool inside = dx * dx + dy * dy < limit;
    failure[i] = (inside && failure[i] == kRayOk) ? std::int32_t{kRayVignetted} : failure[i];
  }
}

// The placement of surface k (Placement in lens.h): p_parent = D + R p_local (decenter first) or
// R (D + p_local) (tilt first); r[i][j] is row i, column j of R.
template <typename T>
struct PlacementFrame {
  T r[3][3];
  T dx, dy;
  bool tilt_first;
};

template <typename T>
PlacementFrame<T> placement_frame(const TraceGeometry<T>& g, int k) {
  using std::cos;
  using std::sin;
  const T deg = K<T>(kPi / 180.0);
  const T a = g.value(k, 2) * deg, b = g.value(k, 3) * deg, c = g.value(k, 4) * deg;
  const T ca = cos(a), sa = sin(a), cb = cos(b), sb = sin(b), cc = cos(c), sc = sin(c);
  const T zero = K<T>(0.0), one = K<T>(1.0);
  const T rx[3][3] = {{one, zero, zero}, {zero, ca, -sa}, {zero, sa, ca}};
  const T ry[3][3] = {{cb, zero, sb}, {zero, one, zero}, {-sb, zero, cb}};
  const T rz[3][3] = {{cc, -sc, zero}, {sc, cc, zero}, {zero, zero, one}};
  PlacementFrame<T> f;
  f.tilt_first = (g.flags[k] & kPlacementTiltFirst) != 0;
  f.dx = g.value(k, 0);
  f.dy = g.value(k, 1);
  // Intrinsic rotations compose on the right: x, then the new y, then the new z is Rx Ry Rz.
  const auto& first = f.tilt_first ? rz : rx;
  const auto& last = f.tilt_first ? rx : rz;
  T tmp[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      tmp[i][j] = first[i][0] * ry[0][j] + first[i][1] * ry[1][j] + first[i][2] * ry[2][j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      f.r[i][j] = tmp[i][0] * last[0][j] + tmp[i][1] * last[1][j] + tmp[i][2] * last[2][j];
  return f;
}

// Parent frame to the surface's frame: p_local = R^T (p - D) (decenter first) or R^T p - D
// (tilt first); d_local = R^T d.
// (The order is a template argument and the frame's entries locals, so that the double loops
// vectorize: the same operations in the same order as one loop with the order inside.)
template <bool kTiltFirst, typename T>
void to_local_loop(const PlacementFrame<T>& f, std::size_t count, T* __restrict x, T* __restrict y,
                   T* __restrict z, T* __restrict l, T* __restrict m, T* __restrict n) {
  const T r00 = f.r[0][0], r01 = f.r[0][1], r02 = f.r[0][2];
  const T r10 = f.r[1][0], r11 = f.r[1][1], r12 = f.r[1][2];
  const T r20 = f.r[2][0], r21 = f.r[2][1], r22 = f.r[2][2];
  const T dx = f.dx, dy = f.dy;
  for (std::size_t i = 0; i < count; ++i) {
    T px, py;
    if constexpr (kTiltFirst) {
      px = x[i];
      py = y[i];
    } else {
      px = x[i] - dx;
      py = y[i] - dy;
    }
    const T pz = z[i];
    T qx = r00 * px + r10 * py + r20 * pz;
    T qy = r01 * px + r11 * py + r21 * pz;
    const T qz = r02 * px + r12 * py + r22 * pz;
    if constexpr (kTiltFirst) {
      qx = qx - dx;
      qy = qy - dy;
    }
    const T dl = r00 * l[i] + r10 * m[i] + r20 * n[i];
    const T dm = r01 * l[i] + r11 * m[i] + r21 * n[i];
    const T dn = r02 * l[i] + r12 * m[i] + r22 * n[i];
    x[i] = qx;
    y[i] = qy;
    z[i] = qz;
    l[i] = dl;
    m[i] = dm;
    n[i] = dn;
  }
}

template <typename T>
void to_local(const PlacementFrame<T>& f, std::size_t count, T* x, T* y, T* z, T* l, T* m, T* n) {
  if (f.tilt_first)
    to_local_loop<true>(f, count, x, y, z, l, m, n);
  else
    to_local_loop<false>(f, count, x, y, z, l, m, n);
}

// The inverse of to_local: p = D + R p_local (decenter first) or R (D + p_local) (tilt first).
template <bool kTiltFirst, typename T>
void to_parent_loop(const PlacementFrame<T>& f, std::size_t count, T* __restrict x, T* __restrict y,
                    T* __restrict z, T* __restrict l, T* __restrict m, T* __restrict n) {
  const T r00 = f.r[0][0], r01 = f.r[0][1], r02 = f.r[0][2];
  const T r10 = f.r[1][0], r11 = f.r[1][1], r12 = f.r[1][2];
  const T r20 = f.r[2][0], r21 = f.r[2][1], r22 = f.r[2][2];
  const T zero = K<T>(0.0);
  const T dx = f.dx, dy = f.dy;
  const T ox = kTiltFirst ? zero : dx;
  const T oy = kTiltFirst ? zero : dy;
  for (std::size_t i = 0; i < count; ++i) {
    T px, py;
    if constexpr (kTiltFirst) {
      px = x[i] + dx;
      py = y[i] + dy;
    } else {
      px = x[i];
      py = y[i];
    }
    const T pz = z[i];
    const T qx = ox + (r00 * px + r01 * py + r02 * pz);
    const T qy = oy + (r10 * px + r11 * py + r12 * pz);
    const T qz = r20 * px + r21 * py + r22 * pz;
    const T dl = r00 * l[i] + r01 * m[i] + r02 * n[i];
    const T dm = r10 * l[i] + r11 * m[i] + r12 * n[i];
    const T dn = r20 * l[i] + r21 * m[i] + r22 * n[i];
    x[i] = qx;
    y[i] = qy;
    z[i] = qz;
    l[i] = dl;
    m[i] = dm;
    n[i] = dn;
  }
}

template <typename T>
void to_parent(const PlacementFrame<T>& f, std::size_t count, T* x, T* y, T* z, T* l, T* m, T* n) {
  if (f.tilt_first)
    to_parent_loop<true>(f, count, x, y, z, l, m, n);
  else
    to_parent_loop<false>(f, count, x, y, z, l, m, n);
}

// Whether every n[i] > 0 (none is <= 0 or NaN): for double a select into a double, which
// vectorizes at the baseline x86-64 level (the count of any_not_forward does not).
template <typename T>
bool all_forward(const T* n, std::size_t count) {
  if constexpr (std::is_same_v<T, double>) {
    double all = 1.0;
    for (std::size_t i = 0; i < count; ++i) all = n[i] > 0.0 ? all : 0.0;
    return all == 1.0;
  } else {
    return !any_not_forward(n, count);
  }
}

// Whether some n[i] == 0 (the placed path's image transfer: a ray along the image plane).
template <typename T>
bool any_zero(const T* n, std::size_t count) {
  if constexpr (std::is_same_v<T, double>) {
    double none = 1.0;
    for (std::size_t i = 0; i < count; ++i) none = n[i] == 0.0 ? 0.0 : none;
    return none == 0.0;
  } else {
    for (std::size_t i = 0; i < count; ++i)
      if (n[i] == K<T>(0.0)) return true;
    return false;
  }
}

// Turns positions and directions about z: (x, y) -> (c x + s y, -s x + c y), (l, m) likewise.
template <typename T>
void turn_about_z(double cos_a, double sin_a, std::size_t count, T* x, T* y, T* l, T* m) {
  const T c = K<T>(cos_a), s = K<T>(sin_a);
  for (std::size_t i = 0; i < count; ++i) {
    const T px = c * x[i] + s * y[i];
    const T py = c * y[i] - s * x[i];
    const T pl = c * l[i] + s * m[i];
    const T pm = c * m[i] - s * l[i];
    x[i] = px;
    y[i] = py;
    l[i] = pl;
    m[i] = pm;
  }
}

// The general path of trace_bundle for a lens with 3D placements (TraceGeometry::placed()); see
// the header. Rays are held in the frame of the last surface traced (its frame after placement,
// or the parent frame for a restore_frame surface).
// Before surface 0: a ray with n <= 0 (or NaN) cannot travel forwards; it is flagged
// kRayBackwards at surface 0 and its n set to 1 to keep it finite.
template <typename T>
void flag_backwards_at_start(std::size_t count, T* n, std::uint8_t* status,
                             std::int8_t* failed_at) {
  if (!any_not_forward(n, count)) return;
  const T zero = K<T>(0.0);
  const T one = K<T>(1.0);
  for (std::size_t i = 0; i < count; ++i) {
    if (!(n[i] > zero) && status[i] == kRayOk) {
      status[i] = kRayBackwards;
      failed_at[i] = 0;
      n[i] = one;
    }
  }
}

// After the last surface: the transfer to the image plane z = t_{K-1} (of the last frame), s =
// -(z - t) / n along the ray. Unplaced (`either_side` false): a ray with n <= 0 is flagged
// kRayBackwards at the last surface. Placed (`either_side` true): the plane is reached along the
// ray's line either way (a plane needs no side: after a tilted image frame a beam may arrive along
// -z), and only a ray with n = 0 (along the plane) is flagged. `opl`: the optical paths to extend
// by n_image s, or null.
template <typename T>
void transfer_to_image(const TraceLens<T>& lens, int w, RayBundle<T>& rays, RayRecord<T>* record,
                       T* opl, bool either_side = false) {
  const std::size_t count = rays.size();
  const T zero = K<T>(0.0);
  T* x = rays.x.data();
  T* y = rays.y.data();
  T* z = rays.z.data();
  T* l = rays.l.data();
  T* m = rays.m.data();
  T* n = rays.n.data();
  const int last = lens.surface_count() - 1;
  const T t = lens.thickness_mm[last];
  T* travel = record ? record->axial_travel_mm[last].data() : nullptr;
  if (!travel && !opl && !(either_side ? any_zero(n, count) : any_not_forward(n, count))) {
    // No ray to flag: the same transfer without the per-ray branch.
    for (std::size_t i = 0; i < count; ++i) {
      const T s = -(z[i] - t) / n[i];
      x[i] = x[i] + s * l[i];
      y[i] = y[i] + s * m[i];
      z[i] = zero;
    }
    return;
  }
  const T n_image = opl ? lens.index(last, w) : K<T>(1.0);
  std::uint8_t* status = rays.status.data();
  std::int8_t* failed_at = rays.failed_surface.data();
  for (std::size_t i = 0; i < count; ++i) {
    const T z_rel = z[i] - t;
    if (travel) travel[i] = -z_rel;
    if (either_side ? n[i] == zero : !(n[i] > zero)) {
      if (status[i] == kRayOk) {
        status[i] = kRayBackwards;
        failed_at[i] = static_cast<std::int8_t>(last);
      }
      continue;
    }
    const T s = -z_rel / n[i];
    if (opl) opl[i] = opl[i] + n_image * s;
    x[i] = x[i] + s * l[i];
    y[i] = y[i] + s * m[i];
    z[i] = zero;
  }
}

// The failures of surface k (trace_surface's codes, the aperture's, the obscuration's) into the
// rays' status: the first failure of a ray wins. A bundle without failures, the usual case, skips
// the per-ray loop after one reduction that vectorizes.
inline void record_failures(std::size_t count, const std::int32_t* failure, int k,
                            std::uint8_t* status, std::int8_t* failed_at) {
  std::int32_t any_failure = 0;
  for (std::size_t i = 0; i < count; ++i) any_failure |= failure[i];
  if (any_failure == 0) return;
  for (std::size_t i = 0; i < count; ++i) {
    if (failure[i] != kRayOk && status[i] == kRayOk) {
      status[i] = static_cast<std::uint8_t>(failure[i]);
      failed_at[i] = static_cast<std::int8_t>(k);
    }
  }
}

template <typename T>
void trace_bundle_placed(const TraceLens<T>& lens, int w, int end, bool to_image,
                         RayBundle<T>& rays, RayRecord<T>* record) {
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
  const bool path = record && record->optical_path_mm.size() == count;
  T* opl = path ? record->optical_path_mm.data() : nullptr;
  T* start_z = path ? record->path_start_z.data() : nullptr;
  T* start_n = path ? record->path_start_n.data() : nullptr;
  const TraceGeometry<T>& g = lens.geometry;
  // A field off the y axis: from its frame into the lens frame (RayBundle::frame_cos).
  if (rays.turned()) turn_about_z(rays.frame_cos, rays.frame_sin, count, x, y, l, m);
  // A ray that cannot reach surface k travelling forwards in its frame (n <= 0 or NaN) is
  // flagged kRayBackwards there and kept finite.
  auto check_forward = [&](int k) {
    if (all_forward(n, count)) return;
    for (std::size_t i = 0; i < count; ++i) {
      if (!(n[i] > zero)) {
        if (status[i] == kRayOk) {
          status[i] = kRayBackwards;
          failed_at[i] = static_cast<std::int8_t>(k);
        }
        l[i] = zero;
        m[i] = zero;
        n[i] = one;
      }
    }
  };

  for (int k = 0; k < end; ++k) {
    const std::uint8_t flags = g.flags[k];
    T shift = k > 0 ? lens.thickness_mm[k - 1] : zero;
    PlacementFrame<T> frame{};
    if (flags & kPlacementMoved) {
      for (std::size_t i = 0; i < count; ++i) z[i] = z[i] - shift;
      shift = zero;
      frame = placement_frame(g, k);
      to_local(frame, count, x, y, z, l, m, n);
    }
    if (flags & kPlacementCoordinateBreak) {
      // A dummy surface: the rays only change frame (its thickness then runs along the new z).
      for (std::size_t i = 0; i < count; ++i) z[i] = z[i] - shift;
      if (record) {
        if (k > 0)
          for (T& v : record->axial_travel_mm[k - 1]) v = lens.thickness_mm[k - 1];
        for (T& v : record->cos2_incidence[k]) v = one;
        for (T& v : record->cos2_refraction[k]) v = one;
      }
      continue;
    }
    check_forward(k);
    const T c = lens.curvature_per_mm[k];
    const T mu = lens.index(k - 1, w) / lens.index(k, w);
    if (path) {
      for (std::size_t i = 0; i < count; ++i) {
        start_z[i] = z[i] - shift;
        start_n[i] = n[i];
      }
    }
    intersect_surface(lens, k, c, shift, mu, count, x, y, z, l, m, n, failure, record);
    const double cx = g.aperture_center_mm[2 * k], cy = g.aperture_center_mm[2 * k + 1];
    if (!lens.semi_diameter_mm.empty() && lens.semi_diameter_mm[k] > 0.0) {
      const T limit = K<T>(lens.semi_diameter_mm[k] * lens.semi_diameter_mm[k]);
      const T ox = K<T>(cx), oy = K<T>(cy);
      for (std::size_t i = 0; i < count; ++i) {
        const T dx = x[i] - ox, dy = y[i] - oy;
        const bool outside = dx * dx + dy * dy > limit;
        failure[i] = (outside && failure[i] == kRayOk) ? std::int32_t{kRayVignetted} : failure[i];
      }
    }
    if (!g.obscuration_mm.empty() && g.obscuration_mm[k] > 0.0)
      obscure(g.obscuration_mm[k], cx, cy, count, x, y, failure);
    if (path) {
      const T n_before = lens.index(k - 1, w);
      for (std::size_t i = 0; i < count; ++i)
        opl[i] = opl[i] + n_before * (z[i] - start_z[i]) / start_n[i];
    }
    record_failures(count, failure, k, status, failed_at);
    if ((flags & kPlacementMoved) && (flags & kPlacementRestore))
      to_parent(frame, count, x, y, z, l, m, n);
  }

  // The image plane z = t_{K-1} of the last frame, reached along the ray's line either way.
  if (to_image) transfer_to_image(lens, w, rays, record, opl, true);
  // Back into the field's frame.
  if (rays.turned()) turn_about_z(rays.frame_cos, -rays.frame_sin, count, x, y, l, m);
}

}  // namespace detail

namespace detail {

// The Jet traces of the widths of core/jet_width.h, compiled once each for several x86-64 levels
// with every Jet operation inlined (src/trace/kernel_jet.cpp.in, one translation unit per width).
// Every entry of `record`'s travel and angle (zeta) records for the traced surfaces is left
// written or zero, so a reused record needs no zeroing (optimize/design_loss.h).
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
// `record` may be null. kCompiled: see detail::intersect_surface (only trace_bundle_jet sets it).
template <typename T, bool kCompiled = false>
void trace_bundle(const TraceLens<T>& lens, int w, int end, bool to_image, RayBundle<T>& rays,
                  RayRecord<T>* record) {
  if (lens.geometry.placed()) {
    detail::trace_bundle_placed(lens, w, end, to_image, rays, record);
    return;
  }
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

  // A ray must travel forwards. The checks first ask whether any ray needs the bookkeeping (a
  // reduction that vectorizes), so a bundle without failures, the usual case, skips the per-ray
  // status loops.
  detail::flag_backwards_at_start(count, n, status, failed_at);

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
    detail::intersect_surface<T, kCompiled>(lens, k, c, shift, mu, count, x, y, z, l, m, n, failure,
                                            record);
    // Step 5: the clear aperture of surface k, if it has one.
    if (!lens.semi_diameter_mm.empty() && lens.semi_diameter_mm[k] > 0.0) {
      const T limit = K<T>(lens.semi_diameter_mm[k] * lens.semi_diameter_mm[k]);
      for (std::size_t i = 0; i < count; ++i) {
        const bool outside = x[i] * x[i] + y[i] * y[i] > limit;
        failure[i] = (outside && failure[i] == kRayOk) ? std::int32_t{kRayVignetted} : failure[i];
      }
    }
    if (!lens.geometry.obscuration_mm.empty() && lens.geometry.obscuration_mm[k] > 0.0)
      detail::obscure(lens.geometry.obscuration_mm[k], 0.0, 0.0, count, x, y, failure);
    if (path) {
      const T n_before = lens.index(k - 1, w);
      for (std::size_t i = 0; i < count; ++i)
        opl[i] = opl[i] + n_before * (z[i] - start_z[i]) / start_n[i];
    }
    detail::record_failures(count, failure, k, status, failed_at);
  }

  if (to_image) detail::transfer_to_image(lens, w, rays, record, opl);
}

// trace_bundle on double (with its placed path) is compiled once, in src/trace/kernel_double.cpp,
// not in each of the 50-odd objects that trace (as the Jet widths above; BENCHMARKS.md "Build
// time, third round"). The same code at the same flags: the same bits.
extern template void trace_bundle<double>(const TraceLens<double>&, int, int, bool,
                                          RayBundle<double>&, RayRecord<double>*);

}  // namespace lensopt
