// Passive OpenMP waiting for an executable (its main calls use_passive_omp_wait first thing).
//
// libgomp's threads spin (GOMP_SPINCOUNT, 300,000 iterations) after each parallel region before
// they sleep. lensopt's parallel regions are short and frequent (one per loss evaluation, per
// tile row), so a spinning thread burns a core between regions: `optimize lenses/cooke.toml`
// takes the same 2.3 s wall either way on an idle machine but 4.5 CPU-s spinning against 3.1
// passive, and with another process on the second core 4.4-5.4 s wall spinning against 2.9 s
// (BENCHMARKS.md, "OpenMP wait policy"). libgomp reads OMP_WAIT_POLICY once, in its
// initializer, before main; glibc resets the environment after an executable's .preinit_array
// runs, so the only way to set it for this process is to set it and exec the program again.
#pragma once

#include <unistd.h>

#include <cstdlib>

namespace lensopt {

// If OMP_WAIT_POLICY is unset: sets it to PASSIVE and re-executes /proc/self/exe with `argv`
// (a few milliseconds; the process keeps its pid, descriptors and signal dispositions). Returns
// when the variable was already set (the user's choice wins) or the exec failed (then threads
// spin, which costs CPU, not results).
inline void use_passive_omp_wait(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") != nullptr) return;
  if (setenv("OMP_WAIT_POLICY", "PASSIVE", /*overwrite=*/0) != 0) return;
  execv("/proc/self/exe", argv);
}

}  // namespace lensopt
