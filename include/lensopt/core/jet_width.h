// The one dispatch from a run-time variable count n to a compile-time Jet width N
// (ceres::Jet<double, N> carries N derivatives): the smallest of the listed widths that holds n.
//
//   with_jet_width<8, 16, 24>(n, [&](auto width) { return f<decltype(width)::value>(...); })
//
// calls the lambda with std::integral_constant<int, N>. Above the last width it is called with
// the last one: callers that work in blocks of N variables (gradients, Ceres' dynamic cost
// functions) take any n; a caller that cannot checks n against jet_width_cap first.
#pragma once

#include <type_traits>

namespace lensopt {

template <int... Widths>
inline constexpr int jet_width_cap = (Widths, ...);  // the last (largest) width

template <int W, int... Rest, typename F>
auto with_jet_width(int n, F&& f) {
  if constexpr (sizeof...(Rest) == 0) {
    return f(std::integral_constant<int, W>{});
  } else {
    static_assert(((W < Rest) && ...), "Jet widths are listed in increasing order");
    if (n <= W) return f(std::integral_constant<int, W>{});
    return with_jet_width<Rest...>(n, static_cast<F&&>(f));
  }
}

}  // namespace lensopt
