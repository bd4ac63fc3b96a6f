// core/: the reproducible random draws (core/random.h).
#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <random>

#include "lensopt/core/error.h"
#include "lensopt/core/random.h"

namespace test_core {

using namespace lensopt;

TEST_CASE("random: splitmix64 gives the published SplitMix64 outputs") {
  // SplitMix64 seeded with 0: its first outputs are mix(k * 0x9E3779B97F4A7C15), k = 1, 2, 3,
  // i.e. splitmix64((k - 1) * golden) here (published reference values).
  constexpr std::uint64_t golden = 0x9E3779B97F4A7C15ull;
  CHECK(splitmix64(0) == 0xE220A8397B1DCDAFull);
  CHECK(splitmix64(golden) == 0x6E789E6AA1B965F4ull);
  CHECK(splitmix64(2 * golden) == 0x06C45D188009454Full);
  CHECK(stream_seed(7, 3) == splitmix64(7 ^ splitmix64(3)));
}

#if defined(__GLIBCXX__)
TEST_CASE("random: uniform_real and uniform_int draw the numbers libstdc++'s distributions drew") {
  // Earlier versions used std::uniform_*_distribution; on this library the written-out draws
  // must give the same sequences, so seeds keep their scenes and crops.
  Rng a(12345), b(12345);
  for (int i = 0; i < 20000; ++i) {
    const double lo = -1.0 + 0.001 * (i % 7), hi = 0.05 + 0.9 * ((i % 5) + 1) / 5.0;
    std::uniform_real_distribution<double> ur(lo, hi);
    REQUIRE(uniform_real(a, lo, hi) == ur(b));
    const int ilo = (i % 11) - 3, ihi = ilo + (i % 97);
    std::uniform_int_distribution<int> ui(ilo, ihi);
    REQUIRE(uniform_int(a, ilo, ihi) == ui(b));
  }
  // A wide range with a large rejection threshold: n = 2^62 + 1 rejects about a quarter.
  std::uniform_int_distribution<std::int64_t> wide(0, std::int64_t{1} << 62);
  for (int i = 0; i < 1000; ++i) REQUIRE(uniform_int(a, 0, std::int64_t{1} << 62) == wide(b));
}
#endif

TEST_CASE("random: draws stay in range and are uniform (chi-square)") {
  Rng rng(stream_seed(99, 1));
  constexpr int kBins = 16, kDraws = 160000;
  std::array<int, kBins> real_bins{}, int_bins{}, unit_bins{};
  for (int i = 0; i < kDraws; ++i) {
    const double u = uniform_real(rng, 2.0, 3.0);
    REQUIRE(u >= 2.0);
    REQUIRE(u < 3.0);
    ++real_bins[static_cast<int>((u - 2.0) * kBins)];
    const double v = unit_interval(rng);
    REQUIRE(v >= 0.0);
    REQUIRE(v < 1.0);
    ++unit_bins[static_cast<int>(v * kBins)];
    const std::int64_t k = uniform_int(rng, -5, 10);
    REQUIRE(k >= -5);
    REQUIRE(k <= 10);
    ++int_bins[static_cast<std::size_t>(k + 5)];
  }
  // 15 degrees of freedom: P(chi2 > 37.7) = 0.001.
  for (const auto* bins : {&real_bins, &int_bins, &unit_bins}) {
    double chi2 = 0.0;
    const double expected = double(kDraws) / kBins;
    for (int c : *bins) chi2 += (c - expected) * (c - expected) / expected;
    CHECK(chi2 < 37.7);
  }
  CHECK(uniform_int(rng, 4, 4) == 4);
  CHECK_THROWS_AS(uniform_int(rng, 5, 4), Error);
}

}  // namespace test_core
