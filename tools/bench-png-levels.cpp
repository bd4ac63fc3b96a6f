// PNG encoding time and size per zlib level (src/core/png_io.h), for BENCHMARKS.md.
// Build and run (no CMake target; it links only png_io.cpp and text.cpp):
//   g++ -O3 -std=c++20 -Iinclude -Isrc tools/bench-png-levels.cpp src/core/png_io.cpp \
//       src/core/text.cpp -lpng -lfmt -o /tmp/bench-png-levels
//   /tmp/bench-png-levels IMAGE.png [REPEATS]
// Decodes IMAGE.png, then encodes it REPEATS times (default 5) at each level 1..9 and prints the
// best CPU time of one encode (ms) and the file size; "9" is level 9 with every row filter tried
// (what LENSOPT_PNG_LEVEL=9 asks for).
#include <time.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/png_io.h"

namespace {
double cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s IMAGE.png [REPEATS]\n", argv[0]);
    return 2;
  }
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 5;
  lensopt::PngPixels in;
  std::string error;
  if (!lensopt::read_png(argv[1], in, error)) {
    std::fprintf(stderr, "%s: %s\n", argv[1], error.c_str());
    return 1;
  }
  std::printf(
      "%d x %d x %d, %d-bit\n| zlib level | encode CPU, best of %d (ms) | size (bytes) "
      "|\n|---|---|---|\n",
      in.width, in.height, in.channels, in.bit_depth, repeats);
  for (int level = 1; level <= 9; ++level) {
    lensopt::set_png_compression_level(level);
    double best = 1e30;
    std::vector<unsigned char> bytes;
    for (int r = 0; r < repeats; ++r) {
      const double t0 = cpu_ms();
      if (!lensopt::encode_png_bytes(in.width, in.height, in.channels, in.bit_depth,
                                     in.pixels.data(), bytes, error)) {
        std::fprintf(stderr, "encode: %s\n", error.c_str());
        return 1;
      }
      best = std::min(best, cpu_ms() - t0);
    }
    std::printf("| %d%s | %.1f | %zu |\n", level, level == 9 ? " (all filters)" : " (up)", best,
                bytes.size());
  }
  return 0;
}
