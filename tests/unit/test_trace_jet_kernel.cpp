// The Jet trace of the listed widths (core/jet_width.h) runs a copy compiled for the CPU's x86-64
// level with every Jet operation inlined (src/trace/kernel_jet.cpp.in); it must give the bits of
// the plain template, which this file compiles for baseline x86-64 (SSE2).
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "bit_compare.h"
#include "lensopt/core/jet_width.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/trace/dual.h"
#include "lensopt/trace/kernel.h"
#include "test_support.h"

namespace test_trace_jet_kernel {

using namespace lensopt;

namespace {

// Every value and derivative of the traced rays (status kRayOk) finite.
template <int N>
bool all_finite_where_traced(const RayBundle<ceres::Jet<double, N>>& b) {
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (b.status[i] != kRayOk) continue;
    for (const auto* a : {&b.x, &b.y, &b.z, &b.l, &b.m, &b.n}) {
      if (!std::isfinite((*a)[i].a)) return false;
      for (int j = 0; j < N; ++j)
        if (!std::isfinite((*a)[i].v[j])) return false;
    }
  }
  return true;
}

// Every value and derivative of two vectors of Jets equal bit for bit, or both NaN: x86 gives an
// operation on two NaNs the first operand's NaN, and the compiler may order the operands of a
// commutative operation either way, so a NaN's sign and payload are not part of the result. NaN
// appears only in the coordinates of a failed ray (after a miss; checked by
// all_finite_where_traced), which no loss reads.
template <int N>
int differing(const std::vector<ceres::Jet<double, N>>& a,
              const std::vector<ceres::Jet<double, N>>& b) {
  if (a.size() != b.size()) return -1;
  int count = 0;
  for (std::size_t i = 0; i < a.size(); ++i) count += !test::same_bits_or_nan(a[i], b[i]);
  return count;
}

// A lens with every prescription variable seeded (directions cycling through the N of the
// Jet) and a fan of rays over the pupil whose start points carry derivatives too.
template <int N>
void check_lens_width(const std::string& file) {
  using J = ceres::Jet<double, N>;
  const Lens lens = read_lens(test::source_dir() / "lenses" / file);
  const TraceLens<double> plain = make_trace_lens(lens);
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  const int count = std::min<int>(N, static_cast<int>(variables.size()));
  TraceLens<J> tl =
      convert_trace_lens<J>(plain, variables, 0, count, [](double v, int j) { return J(v, j); });
  // A clear aperture at the first surface, 0.9x its semi-diameter, so that step 5 vignettes
  // some rays of the grid below.
  tl.semi_diameter_mm.assign(tl.surface_count(), 0.0);
  tl.semi_diameter_mm[0] = 0.9 * (std::abs(lens.surfaces[0].semi_diameter_mm) > 0
                                      ? std::abs(lens.surfaces[0].semi_diameter_mm)
                                      : 10.0);
  const int k_count = tl.surface_count();
  for (int w = 0; w < static_cast<int>(tl.wavelengths_nm.size()); ++w) {
    RayBundle<J> rays;
    const int side = 21;
    rays.resize(side * side);
    const double entrance =
        std::abs(lens.surfaces[0].semi_diameter_mm) > 0 ? lens.surfaces[0].semi_diameter_mm : 10.0;
    for (int i = 0; i < side; ++i) {
      for (int k = 0; k < side; ++k) {
        const int r = i * side + k;
        // A grid 1.3x the first surface's semi-diameter (some rays vignetted or missing) and a
        // field angle of 0.15 rad in y.
        rays.x[r] = J(1.3 * entrance * (2.0 * k / (side - 1) - 1.0), r % N);
        rays.y[r] = J(1.3 * entrance * (2.0 * i / (side - 1) - 1.0), (r + 1) % N);
        rays.z[r] = J(-5.0);
        rays.l[r] = J(0.0);
        rays.m[r] = J(std::sin(0.15));
        rays.n[r] = J(std::cos(0.15));
      }
    }
    // The whole grid (441 rays: one past a multiple of 8) and subsets below, at and past the
    // pack widths (src/trace/kernel_jet.cpp.in packs 8 rays on x86-64-v4, 4 on v3); records off,
    // on (the packs), on with the optical path (the template's loops).
    for (const int size : {441, 0, 1, 3, 4, 7, 8, 9, 17})
      for (const int record_mode : {0, 1, 2}) {
        const bool record_on = record_mode > 0;
        RayBundle<J> subset;
        subset.resize(size);
        for (int r = 0; r < size; ++r) {
          const int from = size == 441 ? r : (r * 37 + 110) % 441;
          subset.x[r] = rays.x[from];
          subset.y[r] = rays.y[from];
          subset.z[r] = rays.z[from];
          subset.l[r] = rays.l[from];
          subset.m[r] = rays.m[from];
          subset.n[r] = rays.n[from];
        }
        RayBundle<J> compiled = subset, generic = subset;
        RayRecord<J> record_c, record_g;
        record_c.resize(k_count, subset.size(), record_mode == 2);
        record_g.resize(k_count, subset.size(), record_mode == 2);
        // The overload for listed widths: the compiled copy.
        trace_bundle(tl, w, k_count, true, compiled, record_on ? &record_c : nullptr);
        // The plain template (explicit argument), compiled in this file.
        trace_bundle<J>(tl, w, k_count, true, generic, record_on ? &record_g : nullptr);
        CAPTURE(file);
        CAPTURE(N);
        CAPTURE(w);
        CAPTURE(size);
        CAPTURE(record_mode);
        CHECK(differing(compiled.x, generic.x) == 0);
        CHECK(differing(compiled.y, generic.y) == 0);
        CHECK(differing(compiled.z, generic.z) == 0);
        CHECK(differing(compiled.l, generic.l) == 0);
        CHECK(differing(compiled.m, generic.m) == 0);
        CHECK(differing(compiled.n, generic.n) == 0);
        CHECK(compiled.status == generic.status);
        CHECK(all_finite_where_traced(compiled));
        CHECK(compiled.failed_surface == generic.failed_surface);
        int ok = 0;
        for (std::uint8_t s : compiled.status) ok += s == kRayOk;
        if (size == 441) {
          CHECK(ok > 0);                              // the grid traces some rays
          CHECK(ok < static_cast<int>(rays.size()));  // and fails some
          int vignetted = 0;
          for (std::uint8_t s : compiled.status) vignetted += s == kRayVignetted;
          CHECK(vignetted > 0);  // at a clear aperture
        }
        if (record_on) {
          for (int k = 0; k < k_count; ++k) {
            CHECK(differing(record_c.axial_travel_mm[k], record_g.axial_travel_mm[k]) == 0);
            CHECK(differing(record_c.cos2_incidence[k], record_g.cos2_incidence[k]) == 0);
            CHECK(differing(record_c.cos2_refraction[k], record_g.cos2_refraction[k]) == 0);
          }
          CHECK(differing(record_c.optical_path_mm, record_g.optical_path_mm) == 0);
        }
      }
  }
}

}  // namespace

TEST_CASE("jet widths: one increasing list, dispatch to the narrowest width that holds n") {
  for (int i = 1; i < kJetWidthCount; ++i) CHECK(kJetWidths[i - 1] < kJetWidths[i]);
  CHECK(kJetWidthCap == kJetWidths[kJetWidthCount - 1]);
  auto width_for = [](int n) {
    return with_jet_width(n, [](auto w) { return decltype(w)::value; });
  };
  for (int n = 0; n <= kJetWidthCap + 5; ++n) {
    const int w = width_for(n);
    CAPTURE(n);
    CHECK(is_jet_width(w));
    if (n > kJetWidthCap) {
      CHECK(w == kJetWidthCap);  // blocks of the last width above it
    } else {
      CHECK(w >= n);
      for (int i = 0; i < kJetWidthCount && kJetWidths[i] < w; ++i) CHECK(kJetWidths[i] < n);
    }
  }
  CHECK_FALSE(is_jet_width(kJetWidthCap + 1));
}

TEST_CASE("trace: the compiled Jet trace of every listed width gives the template's bits") {
  // A spherical lens (the sphere loop) and one with an even asphere (trace/profile.h's loops).
#define LENSOPT_CHECK_WIDTH(N)       \
  check_lens_width<N>("cooke.toml"); \
  check_lens_width<N>("doublet-asphere.toml");
  LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_CHECK_WIDTH)
#undef LENSOPT_CHECK_WIDTH
}

namespace {

// The compiled sphere loop (detail::trace_surface_jet_at, trace/kernel.h) at x86-64 level `level`
// against the template on Jets (Eigen's arithmetic) at one surface: rays with derivatives in
// every direction, some missing the sphere, some totally reflected, with and without records.
// `count` rays out of a pool of 997: counts below, at and between multiples of the vector widths
// (8 doubles for AVX-512, 4 for AVX2), and 0, so that a copy working on several rays at once
// (the pack experiment of BENCHMARKS.md "LM, fourth round") is checked on its remainders too.
template <int N>
void check_surface_level(int level, int count) {
  using J = ceres::Jet<double, N>;
  CHECK(detail::dual_matches_jet<N, J>());
  const int pool = 997;  // not a multiple of any vector width
  auto seeded = [](double value, int i, double scale) {
    J j(value);
    for (int d = 0; d < N; ++d) j.v[d] = scale * std::sin(0.37 * (i + 1) * (d + 2) + scale);
    return j;
  };
  // A strongly curved surface leaving glass (mu = n / n' = 1.6): the outer rays miss it or are
  // totally reflected.
  const J c = seeded(0.08, 1, 0.01), shift = seeded(2.5, 2, 0.3), mu = seeded(1.6, 3, 0.02);
  std::vector<J> x(count), y(count), z(count), l(count), m(count), n(count);
  for (int k = 0; k < count; ++k) {
    // The whole pool in order; a smaller count takes rays spread over the pool.
    const int i = count == pool ? k : (k * 131) % pool;
    const double t = static_cast<double>(i) / (pool - 1);
    const double angle = 0.6 * (t - 0.5);
    x[k] = seeded(14.0 * std::cos(7.0 * t) * t, i, 0.5);
    y[k] = seeded(14.0 * std::sin(9.0 * t) * t, i + 5, 0.5);
    z[k] = seeded(0.3 * t, i + 9, 0.1);
    l[k] = seeded(0.1 * std::sin(angle), i + 11, 0.05);
    m[k] = seeded(std::sin(angle), i + 13, 0.05);
    n[k] =
        seeded(std::sqrt(1.0 - std::pow(std::sin(angle), 2) - 0.01 * std::pow(std::sin(angle), 2)),
               i + 17, 0.05);
  }
  // 0: no record; 1: the records; 2: the zeta records without the axial travel.
  for (const int mode : {0, 1, 2}) {
    const bool record = mode > 0, with_travel = mode == 1;
    std::vector<J> xc = x, yc = y, zc = z, lc = l, mc = m, nc = n;
    std::vector<J> xg = x, yg = y, zg = z, lg = l, mg = m, ng = n;
    std::vector<std::int32_t> fc(count, -7), fg(count, -7);
    std::vector<J> travel_c(count, J(-3.0)), zeta_c(count), zeta_prime_c(count);
    std::vector<J> travel_g(count, J(-3.0)), zeta_g(count), zeta_prime_g(count);
    detail::trace_surface_jet_at(
        level, c, shift, mu, count, xc.data(), yc.data(), zc.data(), lc.data(), mc.data(),
        nc.data(), fc.data(), with_travel ? travel_c.data() : nullptr,
        record ? zeta_c.data() : nullptr, record ? zeta_prime_c.data() : nullptr, record);
    if (record)
      detail::trace_surface<J, true>(
          c, shift, mu, count, xg.data(), yg.data(), zg.data(), lg.data(), mg.data(), ng.data(),
          fg.data(), with_travel ? travel_g.data() : nullptr, zeta_g.data(), zeta_prime_g.data());
    else
      detail::trace_surface<J, false>(c, shift, mu, count, xg.data(), yg.data(), zg.data(),
                                      lg.data(), mg.data(), ng.data(), fg.data(), nullptr, nullptr,
                                      nullptr);
    CAPTURE(N);
    CAPTURE(level);
    CAPTURE(count);
    CAPTURE(mode);
    CHECK(differing(xc, xg) == 0);
    CHECK(differing(yc, yg) == 0);
    CHECK(differing(zc, zg) == 0);
    CHECK(differing(lc, lg) == 0);
    CHECK(differing(mc, mg) == 0);
    CHECK(differing(nc, ng) == 0);
    CHECK(fc == fg);
    int missed = 0, reflected = 0, traced = 0;
    for (std::int32_t f : fc) {
      missed += f == kRayMissedSurface;
      reflected += f == kRayTotalInternalReflection;
      traced += f == kRayOk;
    }
    CHECK(missed + reflected + traced == count);  // every ray's code written
    if (count == pool) {
      CHECK(missed > 0);  // the sample reaches both failure paths of the loop
      CHECK(reflected > 0);
      CHECK(traced > count / 4);
    }
    // The travel record untouched without its array, written with it.
    CHECK(differing(travel_c, travel_g) == 0);
    if (record) {
      CHECK(differing(zeta_c, zeta_g) == 0);
      CHECK(differing(zeta_prime_c, zeta_prime_g) == 0);
    }
  }
}

}  // namespace

TEST_CASE(
    "trace: the Jet sphere loop of every x86-64 level this CPU runs gives the template's bits") {
  // Level 0 (baseline) always; 3 and 4 where the CPU has them (the copy the trace uses is
  // detail::jet_trace_level()'s).
  std::vector<int> levels{0};
  const int cpu = detail::jet_trace_level();
  if (cpu >= 3) levels.push_back(3);
  if (cpu >= 4) levels.push_back(4);
  if (cpu < 4) MESSAGE("this CPU has no x86-64-v4: its AVX-512 copy is not checked here");
  for (int level : levels) {
    // Counts below, at and between multiples of the vector widths, none, and the pool.
    for (int count : {0, 1, 3, 4, 5, 7, 8, 9, 12, 15, 16, 17, 997}) {
#define LENSOPT_CHECK_SURFACE(N) check_surface_level<N>(level, count);
      LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_CHECK_SURFACE)
#undef LENSOPT_CHECK_SURFACE
    }
  }
}

}  // namespace test_trace_jet_kernel
