// Draws of core/random.h that are more than one line.
#include "lensopt/core/random.h"

#include "lensopt/core/error.h"

namespace lensopt {

std::int64_t uniform_int(Rng& rng, std::int64_t lo, std::int64_t hi) {
  if (hi < lo) throw Error("uniform_int: empty interval");
  // n = hi - lo + 1 values; n = 0 here means all 2^64 of them.
  const std::uint64_t n = static_cast<std::uint64_t>(hi) - static_cast<std::uint64_t>(lo) + 1u;
  if (n == 0) return static_cast<std::int64_t>(rng());
  // m = x n in 128 bits; its high word is uniform on [0, n) once the low words below
  // (2^64 - n) mod n are rejected (each high value then has exactly floor(2^64 / n) low words).
  unsigned __int128 m = static_cast<unsigned __int128>(rng()) * n;
  std::uint64_t low = static_cast<std::uint64_t>(m);
  if (low < n) {
    const std::uint64_t threshold = (0u - n) % n;
    while (low < threshold) {
      m = static_cast<unsigned __int128>(rng()) * n;
      low = static_cast<std::uint64_t>(m);
    }
  }
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(lo) +
                                   static_cast<std::uint64_t>(m >> 64));
}

}  // namespace lensopt
