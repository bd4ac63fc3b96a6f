// The double ray-trace kernel, built for several x86-64 levels; the loader picks the best one
// the CPU supports (GCC target_clones), so one binary runs everywhere and vectorizes where it can.
#include <vector>

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

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#endif
void asphere_intersect_double(double c, double one_plus_k, const double* a, std::size_t count,
                              const double* x1, const double* y1, const double* l, const double* m,
                              const double* n, double* s, std::int32_t* failure) {
  asphere_intersect_chunk(c, one_plus_k, a, count, x1, y1, l, m, n, s, failure);
}

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#endif
void trace_surface_profile_double(std::uint8_t profile, double c, double conic, const double* a,
                                  double shift, double mu, std::size_t count, double* x, double* y,
                                  double* z, double* l, double* m, double* n,
                                  std::int32_t* failure, double* travel, double* zeta_out,
                                  double* zeta_prime_out, bool record, double* path_out) {
  // As for the sphere: travel is null at the first surface, a constant in each instantiation.
  // The taped trace (path_out set) records, into scratch records if it has none.
  thread_local std::vector<double> scratch;
  if (path_out && !record) {
    scratch.resize(2 * count);
    zeta_out = scratch.data();
    zeta_prime_out = scratch.data() + count;
    travel = nullptr;
    record = true;
  }
  if (profile == kProfileConic) {
    if (record && travel)
      trace_surface_conic<double, true>(c, conic, shift, mu, count, x, y, z, l, m, n, failure,
                                        travel, zeta_out, zeta_prime_out, path_out);
    else if (record)
      trace_surface_conic<double, true>(c, conic, shift, mu, count, x, y, z, l, m, n, failure,
                                        nullptr, zeta_out, zeta_prime_out, path_out);
    else
      trace_surface_conic<double, false>(c, conic, shift, mu, count, x, y, z, l, m, n, failure,
                                         nullptr, nullptr, nullptr);
  } else if (record && travel) {
    trace_surface_asphere_chunked<double, true>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                                failure, travel, zeta_out, zeta_prime_out,
                                                path_out);
  } else if (record) {
    trace_surface_asphere_chunked<double, true>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                                failure, nullptr, zeta_out, zeta_prime_out,
                                                path_out);
  } else {
    trace_surface_asphere_chunked<double, false>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                                 failure, nullptr, nullptr, nullptr);
  }
}

}  // namespace lensopt::detail

namespace lensopt {

// trace_bundle on double, declared extern in trace/kernel.h: compiled here only.
template void trace_bundle<double>(const TraceLens<double>&, int, int, bool, RayBundle<double>&,
                                   RayRecord<double>*);

}  // namespace lensopt
