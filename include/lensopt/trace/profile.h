// Surface profiles under the ray-trace kernel: sag, intersection and normal of the conic and the
// even asphere, one template for double, ceres::Jet and nested Jets (the sphere keeps its own
// loop in kernel.h, unchanged).
//
// Profile (lens/lens.h), rho = r^2 = x^2 + y^2:
//   S(rho)   = c rho / (1 + q) + P(rho),  q = sqrt(1 - (1 + k) c^2 rho),
//   P(rho)   = a2 rho + a4 rho^2 + ... + a16 rho^8,
//   S'(rho)  = dS/drho = c / (2 q) + P'(rho)      (dz/dr = 2 r S': finite on axis),
//   normal   N = (-2 x S', -2 y S', 1) / |.|  (towards +z, as the sphere's (-c x, -c y, 1 - c z)).
// The profile is defined where q^2 >= 0; a ray that lands outside that domain is flagged
// kRayMissedSurface, like a ray that misses a sphere.
//
// Conic (P = 0). Its implicit form c (x^2 + y^2) + c (1 + k) z^2 - 2 z = 0 along the ray
// (x1, y1, 0) + s (l, m, n) from the vertex plane gives
//   A s^2 - 2 G s + F = 0,  F = c (x1^2 + y1^2),  G = n - c (x1 l + y1 m),  A = c (1 + k n^2),
//   s = F / (G + sqrt(G^2 - A F))   (the root nearest the vertex plane; k = 0 is the sphere),
// a miss when G^2 - A F < 0 or G + sqrt(.) <= 0, and off the profile's sheet (the other half of
// a hyperboloid or the far side of an ellipsoid) when 1 - c (1 + k) z < 0 (there q < 0).
//
// Even asphere. g(s) = s n - S(rho(s)) = 0 solved by Newton's method in double from the conic
// intersection (from the vertex plane if the conic is missed):
//   g'(s) = n - 2 S'(rho) (x l + y m),   s <- s - g / g',
// converged when |ds| <= tol = 1e-15 (1 + |s| + |x| + |y|), or when Newton's error estimate after
// the step, |g'' / (2 g')| ds^2, is below tol / 10 (asphere_newton_step). Two stages, same steps
// and the same test:
//   (a) the bundle, in chunks of kAsphereChunk rays (structure of arrays, branch-free so the
//       double loop vectorizes): up to kVectorNewtonSteps plain Newton steps for every ray; a
//       converged ray keeps its s (a select), a ray whose step would have g' <= 0, a non-finite
//       ds or leave the domain is set aside; the chunk stops early once no ray is running;
//   (b) the rays not converged in (a) (rare: steep or far-from-conic rays) run the safeguarded
//       scalar Newton from the start: a step that leaves the domain is halved until it does not;
//       g' <= 0 (grazing or from behind) or no convergence in kNewtonIterations steps is a miss.
//   Measured (test "asphere intersection finds every steep ray ..."): on a strongly aspheric
//   R = 60 mm surface, every ray that meets it at an incidence below 80 deg is found by both
//   stages; nearer grazing g has a near-double root (g' -> 0 at the hit), Newton converges
//   linearly or crosses g' = 0, and about 0.3 % of such rays are reported as misses.
// For a Jet type the
// converged s is then refined by Newton steps in the Jet type itself (one per level of Jet
// nesting): from an exact value one step makes first derivatives exact (implicit
// differentiation, ds/dp = -(dg/dp) / g'), a second step second derivatives.
//
// Refraction at the unit normal N, mu = n_before / n_after, d the unit direction:
//   cos I = d . N,  zeta = cos^2 I,  zeta' = 1 - mu^2 (1 - zeta),  d' = mu d + (sqrt(zeta') -
//   mu cos I) N;  zeta' < 0 is total internal reflection; cos I <= 0 (hit from behind) a miss.
#pragma once

#include <ceres/jet.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "lensopt/core/scalar.h"
#include "lensopt/lens/profile_sag.h"

namespace lensopt {

namespace detail {

// Levels of Jet nesting: 0 for double, 1 for Jet<double, N>, 2 for Jet<Jet<double, N>, M>.
template <typename T>
struct JetDepth {
  static constexpr int value = 0;
};
template <typename T, int N>
struct JetDepth<ceres::Jet<T, N>> {
  static constexpr int value = 1 + JetDepth<T>::value;
};

inline constexpr int kNewtonIterations = 40;       // safeguarded scalar Newton (stage b)
inline constexpr int kVectorNewtonSteps = 8;       // branch-free Newton on a chunk (stage a)
inline constexpr std::size_t kAsphereChunk = 256;  // rays per chunk (stack scratch)

// S(rho) and S'(rho) of an even asphere with terms a[0..7] = a2..a16 (lens/profile_sag.h); q^2 =
// 1 - (1+k) c^2 rho must be > 0 (the caller has checked the domain).
template <typename T>
inline void asphere_sag(const T& c, const T& one_plus_k, const T* a, const T& rho, T& sag,
                        T& slope) {
  using std::sqrt;
  const T q = sqrt(profile_q2(c, one_plus_k, rho));
  sag = profile_sag_at_q(c, a, rho, q);
  slope = profile_slope_at_q(c, a, rho, q);
}

// Refraction at unit normal (nx, ny, nz) of the direction (l, m, n): the new direction
// (l2, m2, n2), zeta (-1 for a miss) and the raw zeta' for the records; returns the failure code.
template <typename T>
inline std::int32_t refract_at_normal(const T& nx, const T& ny, const T& nz, const T& mu, bool miss,
                                      const T& l, const T& m, const T& n, T& l2, T& m2, T& n2,
                                      T& zeta_record, T& zeta_prime_record) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  // A miss counts as a hit from behind (one comparison: a mask, so the ray loop vectorizes).
  const T cos_raw = miss ? zero : l * nx + m * ny + n * nz;
  const bool failed = !(cos_raw > zero);
  const T cos_i = failed ? one : cos_raw;
  const T zeta = cos_i * cos_i;
  const T zeta_prime_raw = one - mu * mu * (one - zeta);
  const bool tir = zeta_prime_raw < zero;
  const T zeta_prime = tir ? zeta : zeta_prime_raw;
  zeta_record = failed ? -one : zeta;  // a miss shows as zeta < 0
  zeta_prime_record = zeta_prime_raw;
  const T gamma = sqrt(zeta_prime) - mu * cos_i;
  l2 = mu * l + gamma * nx;
  m2 = mu * m + gamma * ny;
  n2 = mu * n + gamma * nz;
  return failed ? kRayMissedSurface : (tir ? kRayTotalInternalReflection : kRayOk);
}

// Conic intersection from the vertex plane point (x1, y1, 0): the path length s (mm) and
// whether the ray misses (see header).
template <typename T>
inline T conic_intersection(const T& c, const T& one_plus_k, const T& x1, const T& y1, const T& l,
                            const T& m, const T& n, bool& miss) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  const T f = c * (x1 * x1 + y1 * y1);
  const T g = n - c * (x1 * l + y1 * m);
  const T a = c * (one + (one_plus_k - one) * n * n);
  const T disc = g * g - a * f;
  const bool no_root = disc < zero;
  const T denom_raw = g + sqrt(no_root ? one : disc);
  const bool bad = no_root | !(denom_raw > zero);
  const T s = f / (bad ? one : denom_raw);
  const T z = s * n;
  miss = bad | (one - c * one_plus_k * z < zero);
  return s;
}

// One surface of conic profile (kernel.h step 3-4 with the conic): positions relative to the
// previous vertex in, relative to this vertex out.
template <typename T, bool kRecord>
inline __attribute__((always_inline)) void trace_surface_conic(
    const T& c, const T& conic, const T& shift, const T& mu, std::size_t count, T* __restrict x,
    T* __restrict y, T* __restrict z, T* __restrict l, T* __restrict m, T* __restrict n,
    std::int32_t* __restrict failure, T* __restrict travel, T* __restrict zeta_out,
    T* __restrict zeta_prime_out, double* __restrict path_out = nullptr) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  const T one_plus_k = one + conic;
  for (std::size_t i = 0; i < count; ++i) {
    // Shift to the vertex and transfer to its tangent plane.
    const T z_rel = z[i] - shift;
    const T s0 = -z_rel / n[i];
    const T x1 = x[i] + s0 * l[i];
    const T y1 = y[i] + s0 * m[i];
    // Intersect the conic in closed form; a miss stays on the vertex plane (s = 0, a constant,
    // as the asphere's).
    bool miss = false;
    const T s_raw = conic_intersection(c, one_plus_k, x1, y1, l[i], m[i], n[i], miss);
    const T s1 = miss ? zero : s_raw;
    if constexpr (kRecord) {
      if (path_out) path_out[i] = miss ? std::numeric_limits<double>::quiet_NaN() : value_of(s1);
    }
    const T x2 = x1 + s1 * l[i];
    const T y2 = y1 + s1 * m[i];
    const T z2 = s1 * n[i];
    // Unit normal (-c x, -c y, 1 - c (1 + k) z) / |.|.
    const T nz_raw = one - c * one_plus_k * z2;
    const T inv = one / sqrt(c * c * (x2 * x2 + y2 * y2) + nz_raw * nz_raw);
    if constexpr (kRecord) {
      if (travel) travel[i] = z2 - z_rel;
    }
    T l2, m2, n2, zeta, zeta_prime;
    failure[i] = refract_at_normal(-c * x2 * inv, -c * y2 * inv, nz_raw * inv, mu, miss, l[i], m[i],
                                   n[i], l2, m2, n2, zeta, zeta_prime);
    if constexpr (kRecord) {
      zeta_out[i] = zeta;
      zeta_prime_out[i] = zeta_prime;
    }
    l[i] = l2;
    m[i] = m2;
    n[i] = n2;
    x[i] = x2;
    y[i] = y2;
    z[i] = z2;
  }
}

// One Newton step of the header for the asphere in double at path s from (x1, y1, 0): the step
// ds = g / g', g' and whether the step converges. S and S' (lens/profile_sag.h) share one division
// here, for speed (so their last bits may differ from profile_sag_at_q's):
//   u = 1 / (q (1 + q)),  c rho / (1 + q) = c rho q u,  c / (2 q) = c (1 + q) u / 2,
// and the test is the header's: |ds| <= tol, or Newton's own error estimate after the step,
// |g'' / (2 g')| ds^2 <= tol / 10 (quadratic convergence: one step fewer than waiting for a
// step below tol), with tol = 1e-15 (1 + |s - ds| + |x| + |y|),
//   g'' = -(S'' rho'^2 + S' rho''),  rho' = 2 (x l + y m),  rho'' = 2 (l^2 + m^2),
//   S''  = (1 + k) c^3 / (4 q^3) + P''(rho).
// The caller has checked the domain (q^2 = 1 - (1 + k) c^2 rho > 0 at s).
inline __attribute__((always_inline)) void asphere_newton_step(double c, double domain,
                                                               const double* a, double x1,
                                                               double y1, double l, double m,
                                                               double n, double s, double& ds,
                                                               double& dg, bool& converged) {
  const double xs = x1 + s * l, ys = y1 + s * m;
  const double rho = xs * xs + ys * ys;
  const double q = std::sqrt(1.0 - domain * rho);
  const double one_q = 1.0 + q;
  const double u = 1.0 / (q * one_q);
  // rho P = sum a_i rho^(i+1): p = P, d1 = (rho P)', d2 = (rho P)'' (lens/profile_sag.h).
  const double p = asphere_poly(a, rho);
  const double d1 = asphere_poly_slope(a, rho);
  const double d2 =
      2.0 * a[1] +
      rho * (6.0 * a[2] +
             rho * (12.0 * a[3] +
                    rho * (20.0 * a[4] +
                           rho * (30.0 * a[5] + rho * (42.0 * a[6] + rho * (56.0 * a[7]))))));
  const double sag = c * rho * q * u + rho * p;
  const double inv_q = one_q * u;
  const double slope = 0.5 * c * inv_q + d1;
  const double g = s * n - sag;
  const double rho_1 = 2.0 * (xs * l + ys * m);
  dg = n - slope * rho_1;
  ds = g / dg;
  const double curvature = 0.25 * domain * c * inv_q * inv_q * inv_q + d2;  // S''
  const double g2 = curvature * rho_1 * rho_1 + 2.0 * slope * (l * l + m * m);
  const double tol = 1e-15 * (1.0 + std::abs(s - ds) + std::abs(xs) + std::abs(ys));
  converged = (std::abs(ds) <= tol) | (std::abs(g2) * ds * ds <= 0.2 * tol * std::abs(dg));
}

// Newton's method for the asphere in double (see header): the path s from the vertex plane point
// (x1, y1, 0), false when it fails.
inline bool asphere_newton(double c, double one_plus_k, const double* a, double x1, double y1,
                           double l, double m, double n, double& s) {
  bool conic_miss = false;
  s = conic_intersection(c, one_plus_k, x1, y1, l, m, n, conic_miss);
  if (conic_miss) s = 0.0;
  const double domain = one_plus_k * c * c;  // q^2 = 1 - domain * rho
  auto inside = [&](double t) {
    const double xs = x1 + t * l, ys = y1 + t * m;
    return 1.0 - domain * (xs * xs + ys * ys) > 0.0;
  };
  if (!inside(s)) {
    s = 0.0;
    if (!inside(s)) return false;
  }
  for (int it = 0; it < kNewtonIterations; ++it) {
    double ds = 0, dg = 0;
    bool converged = false;
    asphere_newton_step(c, domain, a, x1, y1, l, m, n, s, ds, dg, converged);
    if (!(dg > 0.0)) return false;
    if (!std::isfinite(ds)) return false;
    int halvings = 0;
    while (!inside(s - ds)) {
      ds *= 0.5;
      converged = false;
      if (++halvings > 60) return false;
    }
    s -= ds;
    if (converged) return true;
  }
  return false;
}

// Stage (a) then (b) of the header for `count` <= kAsphereChunk rays from the vertex plane points
// (x1, y1, 0) with directions (l, m, n): the path s (mm) and, in failure, kRayMissedSurface for a
// ray that misses the profile or leaves its domain (0 otherwise).
inline __attribute__((always_inline)) void asphere_intersect_chunk(
    double c, double one_plus_k, const double* a, std::size_t count, const double* __restrict x1,
    const double* __restrict y1, const double* __restrict l, const double* __restrict m,
    const double* __restrict n, double* __restrict s, std::int32_t* __restrict failure) {
  // Ray state: 0 running, 1 converged, 2 left for the scalar Newton.
  std::int64_t state[kAsphereChunk];
  const double domain = one_plus_k * c * c;  // q^2 = 1 - domain * rho
  double coefficients[8];                    // a local copy: no aliasing with s
  for (int j = 0; j < 8; ++j) coefficients[j] = a[j];
  // Start: the conic intersection, or the vertex plane if the conic is missed or lies outside
  // the domain; outside the domain at both: the scalar Newton decides (a miss).
  for (std::size_t i = 0; i < count; ++i) {
    bool conic_miss = false;
    const double s_conic =
        conic_intersection(c, one_plus_k, x1[i], y1[i], l[i], m[i], n[i], conic_miss);
    const double xs = x1[i] + s_conic * l[i], ys = y1[i] + s_conic * m[i];
    const bool inside_conic = !conic_miss & (1.0 - domain * (xs * xs + ys * ys) > 0.0);
    const bool inside_vertex = 1.0 - domain * (x1[i] * x1[i] + y1[i] * y1[i]) > 0.0;
    s[i] = inside_conic ? s_conic : 0.0;
    state[i] = (inside_conic | inside_vertex) ? 0 : 2;
    failure[i] = kRayOk;
  }
  // Stage (a): plain Newton steps; selects instead of jumps.
  std::int64_t pending = 0;  // rays not converged after stage (a)
  for (int step = 0; step < kVectorNewtonSteps; ++step) {
    std::int64_t running = 0;
    for (std::size_t i = 0; i < count; ++i) {
      const bool run = state[i] == 0;
      // A ray set aside may sit outside the domain (a NaN step, not used).
      double ds = 0, dg = 0;
      bool converged = false;
      asphere_newton_step(c, domain, coefficients, x1[i], y1[i], l[i], m[i], n[i], s[i], ds, dg,
                          converged);
      const double s_new = s[i] - ds;
      const double xn = x1[i] + s_new * l[i], yn = y1[i] + s_new * m[i];
      const bool ok = (dg > 0.0) & (std::abs(ds) <= std::numeric_limits<double>::max()) &
                      (1.0 - domain * (xn * xn + yn * yn) > 0.0);
      s[i] = (run & ok) ? s_new : s[i];
      state[i] = run ? (ok ? (converged ? 1 : 0) : 2) : state[i];
      running += state[i] == 0 ? 1 : 0;
    }
    if (running == 0) break;
  }
  for (std::size_t i = 0; i < count; ++i) pending += state[i] != 1 ? 1 : 0;
  if (pending == 0) return;
  // Stage (b): the rest through the safeguarded scalar Newton from the start.
  for (std::size_t i = 0; i < count; ++i) {
    if (state[i] == 1) continue;
    double s_scalar = 0.0;
    const bool hit =
        asphere_newton(c, one_plus_k, coefficients, x1[i], y1[i], l[i], m[i], n[i], s_scalar);
    s[i] = hit ? s_scalar : 0.0;
    failure[i] = hit ? kRayOk : kRayMissedSurface;
  }
}

// asphere_intersect_chunk built for several x86-64 levels (src/trace/kernel_double.cpp), for the
// Jet instantiations of trace_surface_asphere.
void asphere_intersect_double(double c, double one_plus_k, const double* a, std::size_t count,
                              const double* x1, const double* y1, const double* l, const double* m,
                              const double* n, double* s, std::int32_t* failure);

// Step (3) of trace_surface_asphere for `count` rays: from the vertex plane points (x1, y1) = (x,
// y), z = z - shift and the double paths s, the Newton steps in T, the point on the surface, the
// normal and the refraction (failure holds the intersection's misses on entry).
template <typename T, bool kRecord>
inline __attribute__((always_inline)) void asphere_refract(
    const T& c, const T& one_plus_k, const T* __restrict a, const T& mu, std::size_t count,
    const double* __restrict s_value, T* __restrict x, T* __restrict y, T* __restrict z,
    T* __restrict l, T* __restrict m, T* __restrict n, std::int32_t* __restrict failure,
    T* __restrict travel, T* __restrict zeta_out, T* __restrict zeta_prime_out) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  for (std::size_t i = 0; i < count; ++i) {
    const T x1 = x[i];
    const T y1 = y[i];
    const T z_rel = z[i];
    const bool miss = failure[i] != kRayOk;
    T s = K<T>(s_value[i]);
    // Newton steps in T carry the derivatives (none for double).
    if constexpr (JetDepth<T>::value > 0) {
      for (int step = 0; step < JetDepth<T>::value && !miss; ++step) {
        const T xs = x1 + s * l[i];
        const T ys = y1 + s * m[i];
        T sag, slope;
        asphere_sag(c, one_plus_k, a, xs * xs + ys * ys, sag, slope);
        const T g = s * n[i] - sag;
        const T dg = n[i] - K<T>(2.0) * slope * (xs * l[i] + ys * m[i]);
        s = s - g / dg;
      }
    }
    const T x2 = x1 + s * l[i];
    const T y2 = y1 + s * m[i];
    const T z2 = s * n[i];
    // Unit normal (-2 x S', -2 y S', 1) / |.|.
    T sag, slope;
    asphere_sag(c, one_plus_k, a, miss ? zero : x2 * x2 + y2 * y2, sag, slope);
    const T px = K<T>(-2.0) * slope * x2;
    const T py = K<T>(-2.0) * slope * y2;
    const T inv = one / sqrt(px * px + py * py + one);
    T l2, m2, n2, zeta, zeta_prime;
    failure[i] = refract_at_normal(px * inv, py * inv, inv, mu, miss, l[i], m[i], n[i], l2, m2, n2,
                                   zeta, zeta_prime);
    if constexpr (kRecord) {
      if (travel) travel[i] = z2 - z_rel;
      zeta_out[i] = zeta;
      zeta_prime_out[i] = zeta_prime;
    }
    l[i] = l2;
    m[i] = m2;
    n[i] = n2;
    x[i] = x2;
    y[i] = y2;
    z[i] = z2;
  }
}

// One surface of even-asphere profile; a = the surface's a2..a16. Rays go in chunks of
// kAsphereChunk: (1) shift and transfer to the vertex plane (x, y hold x1, y1 and z holds z - shift
// meanwhile), (2) the intersection in double (stages a, b), (3) the Jet Newton steps, the normal
// and the refraction.
template <typename T, bool kRecord>
inline __attribute__((always_inline)) void trace_surface_asphere_chunked(
    const T& c, const T& conic, const T* a, const T& shift, const T& mu, std::size_t count,
    T* __restrict x, T* __restrict y, T* __restrict z, T* __restrict l, T* __restrict m,
    T* __restrict n, std::int32_t* __restrict failure, T* __restrict travel, T* __restrict zeta_out,
    T* __restrict zeta_prime_out, double* __restrict path_out = nullptr) {
  constexpr bool kDouble = std::is_same_v<T, double>;
  const T one_plus_k = K<T>(1.0) + conic;
  double a_value[8];
  for (int j = 0; j < 8; ++j) a_value[j] = value_of(a[j]);
  const double c_value = value_of(c);
  const double one_plus_k_value = value_of(one_plus_k);
  // double: the local copy (no aliasing with the rays); Jets: the lens's terms.
  const T* a_local = nullptr;
  if constexpr (kDouble) {
    a_local = a_value;
  } else {
    a_local = a;
  }
  double s_value[kAsphereChunk];
  // Values of the Jets' x1, y1, l, m, n (double rays use their own arrays).
  double x1_value[kDouble ? 1 : kAsphereChunk], y1_value[kDouble ? 1 : kAsphereChunk];
  double l_value[kDouble ? 1 : kAsphereChunk], m_value[kDouble ? 1 : kAsphereChunk];
  double n_value[kDouble ? 1 : kAsphereChunk];
  for (std::size_t begin = 0; begin < count; begin += kAsphereChunk) {
    const std::size_t size = std::min(kAsphereChunk, count - begin);
    T* __restrict xc = x + begin;
    T* __restrict yc = y + begin;
    T* __restrict zc = z + begin;
    T* __restrict lc = l + begin;
    T* __restrict mc = m + begin;
    T* __restrict nc = n + begin;
    std::int32_t* __restrict fc = failure + begin;
    // Shift to the vertex and transfer to its tangent plane.
    for (std::size_t i = 0; i < size; ++i) {
      const T z_rel = zc[i] - shift;
      const T s0 = -z_rel / nc[i];
      xc[i] = xc[i] + s0 * lc[i];
      yc[i] = yc[i] + s0 * mc[i];
      zc[i] = z_rel;
    }
    // Newton in double from the conic intersection.
    if constexpr (kDouble) {
      asphere_intersect_chunk(c_value, one_plus_k_value, a_value, size, xc, yc, lc, mc, nc, s_value,
                              fc);
    } else {
      for (std::size_t i = 0; i < size; ++i) {
        x1_value[i] = value_of(xc[i]);
        y1_value[i] = value_of(yc[i]);
        l_value[i] = value_of(lc[i]);
        m_value[i] = value_of(mc[i]);
        n_value[i] = value_of(nc[i]);
      }
      asphere_intersect_double(c_value, one_plus_k_value, a_value, size, x1_value, y1_value,
                               l_value, m_value, n_value, s_value, fc);
    }
    if constexpr (kRecord) {
      if (path_out) {
        for (std::size_t i = 0; i < size; ++i)
          path_out[begin + i] =
              fc[i] == kRayOk ? s_value[i] : std::numeric_limits<double>::quiet_NaN();
      }
    }
    asphere_refract<T, kRecord>(c, one_plus_k, a_local, mu, size, s_value, xc, yc, zc, lc, mc, nc,
                                fc, kRecord && travel ? travel + begin : nullptr,
                                kRecord ? zeta_out + begin : nullptr,
                                kRecord ? zeta_prime_out + begin : nullptr);
  }
}

// The Jet instantiations (double goes through trace_surface_profile_double).
template <typename T, bool kRecord>
void trace_surface_asphere(const T& c, const T& conic, const T* a, const T& shift, const T& mu,
                           std::size_t count, T* __restrict x, T* __restrict y, T* __restrict z,
                           T* __restrict l, T* __restrict m, T* __restrict n,
                           std::int32_t* __restrict failure, T* __restrict travel,
                           T* __restrict zeta_out, T* __restrict zeta_prime_out) {
  trace_surface_asphere_chunked<T, kRecord>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                            failure, travel, zeta_out, zeta_prime_out);
}

// The double loops of the conic and the even asphere (profile kind kProfileConic or
// kProfileAsphere), built for several x86-64 levels like the sphere's
// (src/trace/kernel_double.cpp).
void trace_surface_profile_double(std::uint8_t profile, double c, double conic, const double* a,
                                  double shift, double mu, std::size_t count, double* x, double* y,
                                  double* z, double* l, double* m, double* n, std::int32_t* failure,
                                  double* travel, double* zeta_out, double* zeta_prime_out,
                                  bool record, double* path_out = nullptr);

}  // namespace detail

// Sag z(r) (mm) of a profile at height r (mm) on scalar type T (surfaces outside the domain:
// the caller checks 1 - (1 + k) c^2 r^2 >= 0). a = a2..a16 (8 terms), may be null (a conic).
template <typename T>
T profile_sag(const T& c, const T& conic, const T* a, const T& r) {
  const T zero = K<T>(0.0);
  const T zeros[8] = {zero, zero, zero, zero, zero, zero, zero, zero};
  T sag, slope;
  detail::asphere_sag(c, K<T>(1.0) + conic, a ? a : zeros, r * r, sag, slope);
  return sag;
}

}  // namespace lensopt
