// The x86-64 level of the compiled Jet sphere loop (trace/dual.h, src/trace/kernel_jet.cpp.in).
#include "lensopt/trace/dual.h"

namespace lensopt::detail {

int jet_trace_level() {
  __builtin_cpu_init();
  if (__builtin_cpu_supports("x86-64-v4")) return 4;
  if (__builtin_cpu_supports("x86-64-v3")) return 3;
  return 0;
}

}  // namespace lensopt::detail
