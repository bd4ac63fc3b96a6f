// The one list of Jet widths (ceres::Jet<double, N> carries N derivatives) and the one dispatch
// from a run-time variable count n to a compile-time width: the smallest listed width that holds n.
//
//   with_jet_width(n, [&](auto width) { return f<decltype(width)::value>(...); })
//
// calls the lambda with std::integral_constant<int, N>. Above the last width it is called with
// the last one (kJetWidthCap): callers that work in blocks of N variables (gradients, Ceres'
// dynamic cost functions) take any n; a caller that cannot checks n against kJetWidthCap first.
//
// Every Jet computation of lensopt runs at one of these widths, so each heavy Jet template (the
// trace kernel, the design loss) is compiled once per width in a translation unit of its own and
// declared `extern template` (LENSOPT_FOR_EACH_JET_WIDTH) where it is used; a new width goes here
// and nowhere else. Derivative direction j of a Jet is computed by the same arithmetic whatever
// the width, so the width a count maps to changes no result.
#pragma once

#include <type_traits>

namespace lensopt {

// X(N) for every Jet width, in increasing order.
#define LENSOPT_FOR_EACH_JET_WIDTH(X) X(8) X(12) X(16) X(24) X(32)

#define LENSOPT_JET_WIDTH_ELEMENT(N) N,
inline constexpr int kJetWidths[] = {LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_JET_WIDTH_ELEMENT)};
#undef LENSOPT_JET_WIDTH_ELEMENT
inline constexpr int kJetWidthCount = static_cast<int>(sizeof(kJetWidths) / sizeof(int));
inline constexpr int kJetWidthCap = kJetWidths[kJetWidthCount - 1];  // the last (largest) width

// Whether N is one of the widths.
constexpr bool is_jet_width(int n) {
  for (int w : kJetWidths)
    if (w == n) return true;
  return false;
}

template <int I = 0, typename F>
auto with_jet_width(int n, F&& f) {
  constexpr int kWidth = kJetWidths[I];
  if constexpr (I + 1 == kJetWidthCount) {
    return f(std::integral_constant<int, kWidth>{});
  } else {
    static_assert(kWidth < kJetWidths[I + 1], "Jet widths are listed in increasing order");
    if (n <= kWidth) return f(std::integral_constant<int, kWidth>{});
    return with_jet_width<I + 1>(n, static_cast<F&&>(f));
  }
}

}  // namespace lensopt
