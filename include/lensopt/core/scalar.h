// Scalar helpers so one template serves double, ceres::Jet<double, N> and nested Jets
// (Jet<Jet<double, N>, 1>, used by ray aiming to differentiate the aiming step itself).
//
// Rule for templated numerics in lensopt: write constants as `K<T>(2.0)`, never `T(2.0)` or a
// bare double in an expression with T; call `sqrt` unqualified after `using std::sqrt`.
//
// Ceres' Jet is only declared here, not included: most of lensopt includes this header (through
// lens/lens.h) and most of it never computes on a Jet, so Ceres and Eigen (about 130k
// preprocessed lines) are parsed only where a Jet is built (the headers of the Jet code include
// <ceres/jet.h>: trace/profile.h, trace/system.h, analysis/gradient.h, ...).
#pragma once

#include <ceres/jet_fwd.h>

#include <cmath>

namespace lensopt {

template <typename T>
struct ScalarTraits {
  static T make(double value) { return T(value); }
  static double value(const T& x) { return static_cast<double>(x); }
};

template <typename T, int N>
struct ScalarTraits<ceres::Jet<T, N>> {
  static ceres::Jet<T, N> make(double value) {
    return ceres::Jet<T, N>(ScalarTraits<T>::make(value));
  }
  static double value(const ceres::Jet<T, N>& x) { return ScalarTraits<T>::value(x.a); }
};

// A constant of scalar type T.
template <typename T>
inline T K(double value) {
  return ScalarTraits<T>::make(value);
}

// The plain double value of any scalar (the innermost `.a` of a Jet).
template <typename T>
inline double value_of(const T& x) {
  return ScalarTraits<T>::value(x);
}

}  // namespace lensopt
