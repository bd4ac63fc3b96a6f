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
// safeguarded: a step that leaves the domain is halved until it does not; g' <= 0 (grazing or
// from behind) or no convergence in kNewtonIterations steps is a miss. For a Jet type the
// converged s is then refined by Newton steps in the Jet type itself (one per level of Jet
// nesting): from an exact value one step makes first derivatives exact (implicit
// differentiation, ds/dp = -(dg/dp) / g'), a second step second derivatives.
//
// Refraction at the unit normal N, mu = n_before / n_after, d the unit direction:
//   cos I = d . N,  zeta = cos^2 I,  zeta' = 1 - mu^2 (1 - zeta),  d' = mu d + (sqrt(zeta') -
//   mu cos I) N;  zeta' < 0 is total internal reflection; cos I <= 0 (hit from behind) a miss.
#pragma once

#include <ceres/jet.h>

#include <cmath>
#include <cstdint>

#include "lensopt/core/scalar.h"

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

inline constexpr int kNewtonIterations = 40;

// S(rho) and S'(rho) of an even asphere with terms a[0..7] = a2..a16; q2 = 1 - (1+k) c^2 rho must
// be > 0 (the caller has checked the domain).
template <typename T>
inline void asphere_sag(const T& c, const T& one_plus_k, const T* a, const T& rho, T& sag,
                        T& slope) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T q = sqrt(one - one_plus_k * c * c * rho);
  T p = a[7];
  T dp = K<T>(8.0) * a[7];
  for (int j = 6; j >= 0; --j) {
    p = a[j] + rho * p;
    dp = K<T>(static_cast<double>(j + 1)) * a[j] + rho * dp;
  }
  sag = c * rho / (one + q) + rho * p;
  slope = c / (K<T>(2.0) * q) + dp;
}

// Refraction at unit normal (nx, ny, nz); writes the new direction, returns the failure code.
template <typename T, bool kRecord>
inline std::int32_t refract_at_normal(const T& nx, const T& ny, const T& nz, const T& mu, bool miss,
                                      T& l, T& m, T& n, T* zeta_out, T* zeta_prime_out) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  const T cos_raw = l * nx + m * ny + n * nz;
  const bool behind = !(cos_raw > zero);
  const bool failed = miss || behind;
  const T cos_i = failed ? one : cos_raw;
  const T zeta = cos_i * cos_i;
  const T zeta_prime_raw = one - mu * mu * (one - zeta);
  const bool tir = zeta_prime_raw < zero;
  const T zeta_prime = tir ? zeta : zeta_prime_raw;
  if constexpr (kRecord) {
    *zeta_out = failed ? -one : zeta;  // a miss shows as zeta < 0
    *zeta_prime_out = zeta_prime_raw;
  }
  const T gamma = sqrt(zeta_prime) - mu * cos_i;
  l = mu * l + gamma * nx;
  m = mu * m + gamma * ny;
  n = mu * n + gamma * nz;
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
  const bool bad = no_root || !(denom_raw > zero);
  const T s = f / (bad ? one : denom_raw);
  const T z = s * n;
  miss = bad || one - c * one_plus_k * z < zero;
  return s;
}

// One surface of conic profile (kernel.h step 3-4 with the conic): positions relative to the
// previous vertex in, relative to this vertex out.
template <typename T, bool kRecord>
void trace_surface_conic(const T& c, const T& conic, const T& shift, const T& mu, std::size_t count,
                         T* __restrict x, T* __restrict y, T* __restrict z, T* __restrict l,
                         T* __restrict m, T* __restrict n, std::int32_t* __restrict failure,
                         T* __restrict travel, T* __restrict zeta_out,
                         T* __restrict zeta_prime_out) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T one_plus_k = one + conic;
  for (std::size_t i = 0; i < count; ++i) {
    // Shift to the vertex and transfer to its tangent plane.
    const T z_rel = z[i] - shift;
    const T s0 = -z_rel / n[i];
    const T x1 = x[i] + s0 * l[i];
    const T y1 = y[i] + s0 * m[i];
    // Intersect the conic in closed form.
    bool miss = false;
    const T s1 = conic_intersection(c, one_plus_k, x1, y1, l[i], m[i], n[i], miss);
    const T x2 = x1 + s1 * l[i];
    const T y2 = y1 + s1 * m[i];
    const T z2 = s1 * n[i];
    // Unit normal (-c x, -c y, 1 - c (1 + k) z) / |.|.
    const T nz_raw = one - c * one_plus_k * z2;
    const T inv = one / sqrt(c * c * (x2 * x2 + y2 * y2) + nz_raw * nz_raw);
    if constexpr (kRecord) {
      if (travel) travel[i] = z2 - z_rel;
    }
    failure[i] = refract_at_normal<T, kRecord>(-c * x2 * inv, -c * y2 * inv, nz_raw * inv, mu, miss,
                                               l[i], m[i], n[i], zeta_out + (kRecord ? i : 0),
                                               zeta_prime_out + (kRecord ? i : 0));
    x[i] = x2;
    y[i] = y2;
    z[i] = z2;
  }
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
    const double xs = x1 + s * l, ys = y1 + s * m;
    const double rho = xs * xs + ys * ys;
    double sag = 0, slope = 0;
    asphere_sag(c, one_plus_k, a, rho, sag, slope);
    const double g = s * n - sag;
    const double dg = n - 2.0 * slope * (xs * l + ys * m);
    if (!(dg > 0.0)) return false;
    double ds = g / dg;
    if (!std::isfinite(ds)) return false;
    int halvings = 0;
    while (!inside(s - ds)) {
      ds *= 0.5;
      if (++halvings > 60) return false;
    }
    s -= ds;
    if (std::abs(ds) <= 1e-15 * (1.0 + std::abs(s) + std::sqrt(rho))) return true;
  }
  return false;
}

// One surface of even-asphere profile; a = the surface's a2..a16.
template <typename T, bool kRecord>
void trace_surface_asphere(const T& c, const T& conic, const T* a, const T& shift, const T& mu,
                           std::size_t count, T* __restrict x, T* __restrict y, T* __restrict z,
                           T* __restrict l, T* __restrict m, T* __restrict n,
                           std::int32_t* __restrict failure, T* __restrict travel,
                           T* __restrict zeta_out, T* __restrict zeta_prime_out) {
  using std::sqrt;
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  const T one_plus_k = one + conic;
  double a_value[8];
  for (int j = 0; j < 8; ++j) a_value[j] = value_of(a[j]);
  const double c_value = value_of(c);
  const double one_plus_k_value = value_of(one_plus_k);
  for (std::size_t i = 0; i < count; ++i) {
    // Shift to the vertex and transfer to its tangent plane.
    const T z_rel = z[i] - shift;
    const T s0 = -z_rel / n[i];
    const T x1 = x[i] + s0 * l[i];
    const T y1 = y[i] + s0 * m[i];
    // Newton in double from the conic intersection.
    double s_value = 0.0;
    bool miss = !asphere_newton(c_value, one_plus_k_value, a_value, value_of(x1), value_of(y1),
                                value_of(l[i]), value_of(m[i]), value_of(n[i]), s_value);
    if (miss) s_value = 0.0;
    T s = K<T>(s_value);
    // Newton steps in T carry the derivatives (none needed for double).
    for (int step = 0; step < JetDepth<T>::value && !miss; ++step) {
      const T xs = x1 + s * l[i];
      const T ys = y1 + s * m[i];
      T sag, slope;
      asphere_sag(c, one_plus_k, a, xs * xs + ys * ys, sag, slope);
      const T g = s * n[i] - sag;
      const T dg = n[i] - K<T>(2.0) * slope * (xs * l[i] + ys * m[i]);
      s = s - g / dg;
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
    if constexpr (kRecord) {
      if (travel) travel[i] = z2 - z_rel;
    }
    failure[i] = refract_at_normal<T, kRecord>(px * inv, py * inv, inv, mu, miss, l[i], m[i], n[i],
                                               zeta_out + (kRecord ? i : 0),
                                               zeta_prime_out + (kRecord ? i : 0));
    x[i] = x2;
    y[i] = y2;
    z[i] = z2;
  }
}

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
