// thread_count (core/threads.h).
#include "lensopt/core/threads.h"

#include <omp.h>

namespace lensopt {

int thread_count(int threads) {
  return threads > 0 ? threads : omp_get_max_threads();
}

}  // namespace lensopt
