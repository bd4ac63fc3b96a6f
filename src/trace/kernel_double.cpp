// The double ray-trace kernel, built for several x86-64 levels; the loader picks the best one
// the CPU supports (GCC target_clones), so one binary runs everywhere and vectorizes where it can.
#include "lensopt/trace/kernel.h"

namespace lensopt::detail {

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#endif
void trace_surface_double(double c, double shift, double mu, std::size_t count, double* x,
                          double* y, double* z, double* l, double* m, double* n,
                          std::int32_t* failure, double* travel, double* zeta_out,
                          double* zeta_prime_out, bool record) {
  if (record) {
    // travel is null at the first surface (no space before it is a lens space).
    if (travel) {
      trace_surface<double, true>(c, shift, mu, count, x, y, z, l, m, n, failure, travel, zeta_out,
                                  zeta_prime_out);
    } else {
      trace_surface<double, true>(c, shift, mu, count, x, y, z, l, m, n, failure, nullptr, zeta_out,
                                  zeta_prime_out);
    }
  } else {
    trace_surface<double, false>(c, shift, mu, count, x, y, z, l, m, n, failure, nullptr, nullptr,
                                 nullptr);
  }
}

}  // namespace lensopt::detail
