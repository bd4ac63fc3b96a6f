// A forward-mode dual number with the memory layout and the arithmetic of ceres::Jet<double, N>,
// written as plain loops over the N derivatives, for the Jet trace's sphere loop
// (src/trace/kernel_jet.cpp.in).
//
// Why: a Jet's derivative vector is an Eigen::Matrix<double, N, 1>, whose arithmetic Eigen
// vectorizes with the packets chosen when the file is compiled (SSE2, two doubles, at the
// baseline x86-64 level the program is built for); a function compiled for x86-64-v3/v4 by GCC's
// target_clones keeps those 128-bit packets. These loops carry no intrinsics, so GCC vectorizes
// them at the width of each clone (256 or 512 bits). Every operation is the one of ceres/jet.h
// (Ceres 2.1) element by element, in the same order, so without FMA contraction
// (-ffp-contract=off) every value and derivative is the Jet's bit for bit
// (tests/unit/test_trace_jet_kernel.cpp).
//
// Only the operations of detail::trace_surface (kernel.h) are defined. Arrays of
// ceres::Jet<double, N> are read and written through Dual<N> pointers (same size, alignment and
// member offsets, checked by dual_matches_jet below and in the test); the type is may_alias so
// that such access is defined for GCC.
#pragma once

#include <ceres/jet_fwd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>

#include "lensopt/core/jet_width.h"

namespace lensopt::detail {

template <int N>
struct [[gnu::may_alias]] alignas(16) Dual {
  double a;
  alignas(16) double v[N];

  Dual() = default;
  // The constant `value` (ceres::Jet(const T&)): derivatives zero.
  explicit Dual(double value) : a(value) {
    for (int j = 0; j < N; ++j) v[j] = 0.0;
  }
};

#define LENSOPT_DUAL_INLINE inline __attribute__((always_inline))

template <int N>
LENSOPT_DUAL_INLINE Dual<N> operator-(const Dual<N>& f) {
  Dual<N> r;
  r.a = -f.a;
  for (int j = 0; j < N; ++j) r.v[j] = -f.v[j];
  return r;
}

template <int N>
LENSOPT_DUAL_INLINE Dual<N> operator+(const Dual<N>& f, const Dual<N>& g) {
  Dual<N> r;
  r.a = f.a + g.a;
  for (int j = 0; j < N; ++j) r.v[j] = f.v[j] + g.v[j];
  return r;
}

template <int N>
LENSOPT_DUAL_INLINE Dual<N> operator-(const Dual<N>& f, const Dual<N>& g) {
  Dual<N> r;
  r.a = f.a - g.a;
  for (int j = 0; j < N; ++j) r.v[j] = f.v[j] - g.v[j];
  return r;
}

// Jet: (f.a g.a, f.a g.v + f.v g.a).
template <int N>
LENSOPT_DUAL_INLINE Dual<N> operator*(const Dual<N>& f, const Dual<N>& g) {
  Dual<N> r;
  r.a = f.a * g.a;
  for (int j = 0; j < N; ++j) r.v[j] = f.a * g.v[j] + f.v[j] * g.a;
  return r;
}

// Jet: g_a_inverse = 1 / g.a, f_a_by_g_a = f.a g_a_inverse,
// (f_a_by_g_a, (f.v - f_a_by_g_a g.v) g_a_inverse).
template <int N>
LENSOPT_DUAL_INLINE Dual<N> operator/(const Dual<N>& f, const Dual<N>& g) {
  const double g_a_inverse = 1.0 / g.a;
  const double f_a_by_g_a = f.a * g_a_inverse;
  Dual<N> r;
  r.a = f_a_by_g_a;
  for (int j = 0; j < N; ++j) r.v[j] = (f.v[j] - f_a_by_g_a * g.v[j]) * g_a_inverse;
  return r;
}

// Jet: tmp = sqrt(f.a), two_a_inverse = 1 / (2 tmp), (tmp, f.v two_a_inverse).
template <int N>
LENSOPT_DUAL_INLINE Dual<N> sqrt(const Dual<N>& f) {
  const double tmp = std::sqrt(f.a);
  const double two_a_inverse = 1.0 / (2.0 * tmp);
  Dual<N> r;
  r.a = tmp;
  for (int j = 0; j < N; ++j) r.v[j] = f.v[j] * two_a_inverse;
  return r;
}

// Jet comparisons compare the values.
template <int N>
LENSOPT_DUAL_INLINE bool operator<(const Dual<N>& f, const Dual<N>& g) {
  return f.a < g.a;
}

#undef LENSOPT_DUAL_INLINE

// Whether Dual<N> can stand for Jet (ceres::Jet<double, N>): size, alignment and the offsets of
// the value and of the derivative vector's first element.
template <int N, typename Jet>
bool dual_matches_jet() {
  static_assert(sizeof(Dual<N>) == sizeof(Jet), "Dual<N> and the Jet differ in size");
  static_assert(alignof(Dual<N>) == alignof(Jet), "Dual<N> and the Jet differ in alignment");
  const Jet jet(0.0);
  const char* base = reinterpret_cast<const char*>(&jet);
  return reinterpret_cast<const char*>(&jet.a) - base ==
             static_cast<std::ptrdiff_t>(offsetof(Dual<N>, a)) &&
         reinterpret_cast<const char*>(jet.v.data()) - base ==
             static_cast<std::ptrdiff_t>(offsetof(Dual<N>, v));
}

// The x86-64 level of the compiled Jet sphere loop on this CPU: 4 (x86-64-v4, AVX-512), 3
// (x86-64-v3, AVX2) or 0 (the baseline level, SSE2: there the loop is the Jet template itself,
// Eigen's 128-bit packets being faster than these loops at that width).
int jet_trace_level();

}  // namespace lensopt::detail
