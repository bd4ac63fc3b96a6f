// The thread count of a parallel loop: every `threads` option of lensopt reads 0 (or a negative
// value) as "all cores", i.e. OpenMP's default team size (OMP_NUM_THREADS when set).
#pragma once

namespace lensopt {

// `threads` if > 0, else omp_get_max_threads().
int thread_count(int threads);

}  // namespace lensopt
