// The x86-64 level of the compiled Jet sphere loop (trace/dual.h, src/trace/kernel_jet.cpp.in).
#include "lensopt/trace/dual.h"

namespace lensopt::detail {

int jet_trace_level() {
  __builtin_cpu_init();
#if defined(__clang__)
  // clang 14 (the ThreadSanitizer builds, tools/tsan.sh) knows no level names and not every
  // feature of a level: the vector and arithmetic features that the copies' loops use decide
  // (x86-64-v4 adds AVX-512 F, BW, CD, DQ and VL to x86-64-v3's AVX2, FMA, BMI1 and BMI2).
  const bool v3 = __builtin_cpu_supports("avx") && __builtin_cpu_supports("avx2") &&
                  __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi") &&
                  __builtin_cpu_supports("bmi2");
  const bool v4 = v3 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                  __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512dq") &&
                  __builtin_cpu_supports("avx512vl");
  return v4 ? 4 : v3 ? 3 : 0;
#else
  if (__builtin_cpu_supports("x86-64-v4")) return 4;
  if (__builtin_cpu_supports("x86-64-v3")) return 3;
  return 0;
#endif
}

}  // namespace lensopt::detail
