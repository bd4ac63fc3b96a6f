// The ray slopes of analysis/spot.h's through-focus moments, built for several x86-64 levels
// (GCC target_clones, as the trace kernel): a division loop, so every level gives the same bits.
#include "lensopt/analysis/spot.h"

namespace lensopt::detail {

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#endif
void ray_slopes(const double* __restrict l, const double* __restrict m, const double* __restrict n,
                std::size_t count, double* __restrict sx, double* __restrict sy) {
  for (std::size_t i = 0; i < count; ++i) {
    sx[i] = l[i] / n[i];
    sy[i] = m[i] / n[i];
  }
}

}  // namespace lensopt::detail
