// The compiled Jet trace (trace_bundle_jet, src/trace/kernel_jet.cpp.in) leaves every entry of a
// record's travel and zeta arrays written by the trace or zero, whatever the record held before:
// evaluate_design (optimize/design_loss.h, detail::size_record) reuses its records between
// evaluations without zeroing them. A record full of a filler value must come out as a zeroed
// one, bit for bit, on the pack path (a lens of spheres) and on the template's path (an asphere),
// traced to the image and to a surface before it, with rays that miss or are vignetted.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "bit_compare.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/trace/kernel.h"
#include "test_support.h"

namespace test_trace_jet_records {

using namespace lensopt;

namespace {

template <int N>
int differing(const std::vector<std::vector<ceres::Jet<double, N>>>& a,
              const std::vector<std::vector<ceres::Jet<double, N>>>& b) {
  if (a.size() != b.size()) return -1;
  int count = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    if (a[k].size() != b[k].size()) return -1;
    for (std::size_t i = 0; i < a[k].size(); ++i)
      count += !test::same_bits_or_nan(a[k][i], b[k][i]);
  }
  return count;
}

template <int N>
void check_records(const std::string& file) {
  using J = ceres::Jet<double, N>;
  const Lens lens = read_lens(test::source_dir() / "lenses" / file);
  const TraceLens<double> plain = make_trace_lens(lens);
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  const int count = std::min<int>(N, static_cast<int>(variables.size()));
  TraceLens<J> tl =
      convert_trace_lens<J>(plain, variables, 0, count, [](double v, int j) { return J(v, j); });
  const int k_count = tl.surface_count();
  const double entrance = std::abs(lens.surfaces[0].semi_diameter_mm) > 0
                              ? std::abs(lens.surfaces[0].semi_diameter_mm)
                              : 10.0;
  // A clear aperture at the first surface: some rays vignetted (their later records unwritten by
  // the template's loops), and a grid 1.5x the entrance wide: some rays miss.
  tl.semi_diameter_mm.assign(k_count, 0.0);
  tl.semi_diameter_mm[0] = 0.9 * entrance;
  const int side = 13;  // 169 rays: one past a multiple of 8 and of 4 (the pack widths)
  RayBundle<J> start;
  start.resize(side * side);
  for (int i = 0; i < side; ++i)
    for (int k = 0; k < side; ++k) {
      const int r = i * side + k;
      start.x[r] = J(1.5 * entrance * (2.0 * k / (side - 1) - 1.0), r % N);
      start.y[r] = J(1.5 * entrance * (2.0 * i / (side - 1) - 1.0), (r + 1) % N);
      start.z[r] = J(-5.0);
      start.l[r] = J(0.0);
      start.m[r] = J(std::sin(0.2));
      start.n[r] = J(std::cos(0.2));
    }
  J filler(12345.0);
  for (int j = 0; j < N; ++j) filler.v[j] = -678.0;
  for (const bool to_image : {true, false}) {
    const int end = to_image ? k_count : k_count - 1;
    RayBundle<J> a = start, b = start;
    RayRecord<J> zeroed, filled;
    zeroed.resize(k_count, start.size());
    filled.resize(k_count, start.size());
    for (auto* arrays : {&filled.axial_travel_mm, &filled.cos2_incidence, &filled.cos2_refraction})
      for (std::vector<J>& v : *arrays) std::fill(v.begin(), v.end(), filler);
    trace_bundle(tl, 0, end, to_image, a, &zeroed);
    trace_bundle(tl, 0, end, to_image, b, &filled);
    CAPTURE(file);
    CAPTURE(N);
    CAPTURE(to_image);
    int failed = 0;
    for (std::size_t i = 0; i < a.size(); ++i) failed += a.status[i] != kRayOk;
    CHECK(failed > 0);
    CHECK(failed < static_cast<int>(a.size()));
    CHECK(differing(zeroed.axial_travel_mm, filled.axial_travel_mm) == 0);
    CHECK(differing(zeroed.cos2_incidence, filled.cos2_incidence) == 0);
    CHECK(differing(zeroed.cos2_refraction, filled.cos2_refraction) == 0);
  }
}

}  // namespace

TEST_CASE("compiled Jet trace: records written or zero (packs: a lens of spheres)") {
  check_records<12>("tessar.toml");
  check_records<8>("cooke.toml");
}

TEST_CASE("compiled Jet trace: records written or zero (the template: an asphere)") {
  check_records<12>("doublet-asphere.toml");
}

}  // namespace test_trace_jet_records
