// Passive OpenMP waiting for an executable: include in exactly one source file of a program
// (its main), never in a library.
//
// libgomp's threads spin (GOMP_SPINCOUNT, 300,000 iterations) after each parallel region before
// they sleep. lensopt's parallel regions are short and frequent (one per loss evaluation, per
// render tile row), so a spinning thread burns a core between regions: with another process on
// the second core, `optimize lenses/cooke.toml` took 4.4-5.4 s wall spinning against 2.9 s
// passive, and on an idle machine the same 2.2 s wall at 4.3 against 2.9 CPU-s (BENCHMARKS.md,
// "OpenMP wait policy"). libgomp reads OMP_WAIT_POLICY once, in its initializer, which runs
// before main; an executable's .preinit_array runs before every shared library's initializer,
// so this sets OMP_WAIT_POLICY=PASSIVE there unless the user has set it.
#pragma once

#include <cstdlib>

namespace lensopt::detail {

inline void set_passive_omp_wait_policy(int, char**, char**) {
  setenv("OMP_WAIT_POLICY", "PASSIVE", /*overwrite=*/0);
}

// The ELF pre-initialization hook (static: one per executable that includes this).
using PreinitFunction = void (*)(int, char**, char**);
[[maybe_unused]] __attribute__((section(".preinit_array"),
                                used)) static const PreinitFunction kPassiveOmpWaitPolicy =
    &set_passive_omp_wait_policy;

}  // namespace lensopt::detail
