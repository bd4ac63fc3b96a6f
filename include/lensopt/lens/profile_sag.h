// The sag of a surface profile (lens.h: sphere, conic, even asphere a2..a16): the one
// implementation of the formula, templated on the scalar (double, ceres::Jet, nested Jets), for
// every module (the tracer's kernels in trace/profile.h, Surface::sag_mm, the plot's layout, the
// tolerance edge gaps, the optimizer's profile bounds).
//
// With rho = r^2 (mm^2), c the curvature (1/mm), k the conic constant, a[0..7] = a2..a16:
//   q^2     = 1 - (1 + k) c^2 rho                       (profile_q2; the domain is q^2 >= 0),
//   P(rho)  = a2 + a4 rho + ... + a16 rho^7             (asphere_poly),
//   (rho P)' = a2 + 2 a4 rho + ... + 8 a16 rho^7        (asphere_poly_slope),
//   S(rho)  = c rho / (1 + q) + rho P(rho)              (profile_sag_at_q),
//   S'(rho) = dS/drho = c / (2 q) + (rho P)'(rho)        (profile_slope_at_q; dz/dr = 2 r S').
// The caller takes q from q^2 and decides what happens outside the domain (q^2 < 0): NaN
// (Surface::sag_mm), q clamped at 0 (the tolerance edge gap, the plot), q^2 held at a floor (the
// profile bounds), or nothing because it has checked the domain (the tracer). Each of them says
// so where it computes q.
#pragma once

#include "lensopt/core/scalar.h"

namespace lensopt {

// q^2 = 1 - (1 + k) c^2 rho (one_plus_k = 1 + k).
template <typename T>
inline __attribute__((always_inline)) T profile_q2(const T& c, const T& one_plus_k, const T& rho) {
  return K<T>(1.0) - one_plus_k * c * c * rho;
}

// P(rho) = a2 + a4 rho + ... + a16 rho^7 (a[0..7] = a2..a16), Horner written out (no inner loop,
// so a ray loop around it vectorizes).
template <typename T>
inline __attribute__((always_inline)) T asphere_poly(const T* a, const T& rho) {
  return a[0] +
         rho * (a[1] +
                rho * (a[2] +
                       rho * (a[3] + rho * (a[4] + rho * (a[5] + rho * (a[6] + rho * a[7]))))));
}

// (rho P)'(rho) = a2 + 2 a4 rho + 3 a6 rho^2 + ... + 8 a16 rho^7.
template <typename T>
inline __attribute__((always_inline)) T asphere_poly_slope(const T* a, const T& rho) {
  return a[0] +
         rho *
             (K<T>(2.0) * a[1] +
              rho * (K<T>(3.0) * a[2] +
                     rho * (K<T>(4.0) * a[3] +
                            rho * (K<T>(5.0) * a[4] +
                                   rho * (K<T>(6.0) * a[5] +
                                          rho * (K<T>(7.0) * a[6] + rho * (K<T>(8.0) * a[7])))))));
}

// S(rho) = c rho / (1 + q) + rho P(rho), q >= 0 given by the caller (see header).
template <typename T>
inline __attribute__((always_inline)) T profile_sag_at_q(const T& c, const T* a, const T& rho,
                                                         const T& q) {
  return c * rho / (K<T>(1.0) + q) + rho * asphere_poly(a, rho);
}

// S'(rho) = c / (2 q) + (rho P)'(rho), q > 0 given by the caller (see header).
template <typename T>
inline __attribute__((always_inline)) T profile_slope_at_q(const T& c, const T* a, const T& rho,
                                                           const T& q) {
  return c / (K<T>(2.0) * q) + asphere_poly_slope(a, rho);
}

}  // namespace lensopt
