// Bit-for-bit comparison of doubles and Jets, for the tests that check that two code paths (a
// compiled copy and the template, a fast path and the general one) give the same bits.
#pragma once

#include <ceres/jet.h>

#include <cmath>
#include <cstring>

namespace lensopt::test {

// a and b have the same bits.
inline bool same_bits(double a, double b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

// The same bits, or both NaN (whatever their payloads).
inline bool same_bits_or_nan(double a, double b) {
  return same_bits(a, b) || (std::isnan(a) && std::isnan(b));
}

// The value and every derivative of a and b have the same bits.
template <int N>
bool same_bits(const ceres::Jet<double, N>& a, const ceres::Jet<double, N>& b) {
  if (!same_bits(a.a, b.a)) return false;
  for (int j = 0; j < N; ++j)
    if (!same_bits(a.v[j], b.v[j])) return false;
  return true;
}

// The value and every derivative of a and b have the same bits or are both NaN.
template <int N>
bool same_bits_or_nan(const ceres::Jet<double, N>& a, const ceres::Jet<double, N>& b) {
  if (!same_bits_or_nan(a.a, b.a)) return false;
  for (int j = 0; j < N; ++j)
    if (!same_bits_or_nan(a.v[j], b.v[j])) return false;
  return true;
}

}  // namespace lensopt::test
