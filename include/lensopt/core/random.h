// Reproducible pseudo-random numbers: the one generator and the one set of draws of lensopt.
//
// The engine is std::mt19937_64, whose output sequence the C++ standard fixes. The standard's
// distributions (std::uniform_real_distribution, std::uniform_int_distribution) are not fixed: each
// standard library maps the engine's bits to numbers its own way, so a seed would give different
// scenes, crops or tolerance trials with another compiler. The draws below are written out here,
// so a seed gives the same numbers everywhere:
//   unit_interval   top 53 bits:          u = (x >> 11) 2^-53                  in [0, 1)
//   uniform_real    one 64-bit output:    u = round(x) / 2^64, clamped below 1, a + (b - a) u
//                   (the same numbers as libstdc++'s std::uniform_real_distribution<double>
//                   on this engine, which earlier versions of lensopt used)
//   uniform_int     Lemire's multiply-shift with rejection (Lemire 2019, "Fast random integer
//                   generation in an interval"): m = x n (128 bit), reject while (m mod 2^64) <
//                   (2^64 - n) mod n, return lo + m / 2^64; unbiased, the same numbers as
//                   libstdc++ 12's std::uniform_int_distribution on this engine
//   splitmix64      Steele, Lea and Flood's 64-bit mixer, to derive independent seeds
//   stream_seed     splitmix64(seed ^ splitmix64(stream)): the seed of stream `stream` (a trial,
//                   an element, a worker) of a run seeded with `seed`
#pragma once

#include <cstdint>
#include <random>

namespace lensopt {

using Rng = std::mt19937_64;

constexpr std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

constexpr std::uint64_t stream_seed(std::uint64_t seed, std::uint64_t stream) {
  return splitmix64(seed ^ splitmix64(stream));
}

// [0, 1) from the top 53 bits of one output (every value a multiple of 2^-53).
inline double unit_interval(Rng& rng) {
  return static_cast<double>(rng() >> 11) * 0x1.0p-53;
}

// [a, b) from one output: the 64-bit integer rounded to double, scaled by 2^-64 and kept below 1.
inline double uniform_real(Rng& rng, double a, double b) {
  double u = static_cast<double>(rng()) * 0x1.0p-64;
  if (u >= 1.0) u = 0x1.fffffffffffffp-1;  // the largest double below 1
  return a + (b - a) * u;
}

// An integer in [lo, hi] (inclusive), unbiased.
std::int64_t uniform_int(Rng& rng, std::int64_t lo, std::int64_t hi);

// The draws as function objects, for code that passes a distribution around.
struct UniformReal {
  double a = 0.0, b = 1.0;
  double operator()(Rng& rng) const { return uniform_real(rng, a, b); }
};
struct UniformInt {
  int lo = 0, hi = 1;
  int operator()(Rng& rng) const { return static_cast<int>(uniform_int(rng, lo, hi)); }
};

}  // namespace lensopt
