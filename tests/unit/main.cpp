#define DOCTEST_CONFIG_IMPLEMENT
#include <doctest/doctest.h>

#include "lensopt/core/passive_threads.h"

int main(int argc, char** argv) {
  lensopt::use_passive_omp_wait(argv);
  doctest::Context context(argc, argv);
  return context.run();
}
