// The ray aiming of the Jet systems (prepare_system on ceres::Jet<double, N>, the LM Jacobian's
// setup) traces its rays on a nested Dual in place of ceres::Jet<Jet<double, N>, 1> where the
// lens allows (trace/aiming_jet.h, src/trace/system_jet.cpp.in): the stop coordinates and their
// derivatives must be the nested Jets' bit for bit. Lenses other than the Cooke the LM benchmark
// runs: a 1:1 relay (a finite object) and a double Gauss (object at infinity, 11 surfaces).
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "bit_compare.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/trace/aiming_jet.h"
#include "lensopt/trace/dual.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace test_trace_aiming_dual {

using namespace lensopt;

namespace {

using test::same_bits;

template <int N>
bool finite(const ceres::Jet<double, N>& a) {
  if (!std::isfinite(a.a)) return false;
  for (int j = 0; j < N; ++j)
    if (!std::isfinite(a.v[j])) return false;
  return true;
}

// Every field and wavelength of the lens's system on Jets of width N (its first N prescription
// variables seeded), under the identity pupil map and under the aimed one: the dual trace and
// the nested Jets' give the same bits.
template <int N>
void check_aiming(const std::filesystem::path& path, bool expect_finite_object) {
  using J = ceres::Jet<double, N>;
  using NJ = ceres::Jet<J, 1>;
  CAPTURE(path.string());
  CAPTURE(N);
  const Lens lens = read_lens(path);
  const TraceLens<double> plain = make_trace_lens(lens);
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  const int count = std::min<int>(N, static_cast<int>(variables.size()));
  REQUIRE(count > 0);
  const TraceLens<J> tl =
      convert_trace_lens<J>(plain, variables, 0, count, [](double v, int j) { return J(v, j); });
  TraceOptions options;
  options.threads = 1;
  const TraceSystem<J> sys = prepare_system(tl, lens.specs, options);
  CHECK(sys.object_at_infinity() == !expect_finite_object);
  const TraceLens<NJ> lens_a =
      convert_trace_lens<NJ>(sys.lens, {}, 0, 0, [](double v, int) { return K<NJ>(v); });
  const bool duals = detail::aiming_on_duals(lens_a, lens_a.stop + 1);
  if (detail::jet_trace_level() >= 3)
    REQUIRE(duals);  // a spherical, unplaced lens: the dual path runs
  else
    MESSAGE("this CPU is below x86-64-v3: both paths are the nested Jets");
  REQUIRE(lens_a.stop >= 1);  // at least two surfaces before the stop is reached
  const J r_ep = sys.epd_mm / K<J>(2.0);
  const PupilMap<J> identity{K<J>(1.0), K<J>(0.0), K<J>(1.0)};
  int compared = 0, with_derivatives = 0;
  RayBundle<NJ> scratch;
  for (int h = 0; h < static_cast<int>(sys.fields_deg.size()); ++h) {
    for (int w = 0; w <= sys.wavelength_count; ++w) {
      for (const PupilMap<J>* map : {&identity, &sys.pupil_map(h, w)}) {
        J coord_dual[3], deriv_dual[3], coord_jet[3], deriv_jet[3];
        detail::trace_aiming_rays_jet(lens_a, w, sys, h, r_ep, sys.entrance_pupil_z_mm, *map,
                                      coord_dual, deriv_dual, &scratch, true);
        detail::trace_aiming_rays_jet(lens_a, w, sys, h, r_ep, sys.entrance_pupil_z_mm, *map,
                                      coord_jet, deriv_jet, nullptr, false);
        for (int i = 0; i < 3; ++i) {
          CAPTURE(h);
          CAPTURE(w);
          CAPTURE(i);
          REQUIRE(finite(coord_jet[i]));
          REQUIRE(finite(deriv_jet[i]));
          CHECK(same_bits(coord_dual[i], coord_jet[i]));
          CHECK(same_bits(deriv_dual[i], deriv_jet[i]));
          ++compared;
          for (int j = 0; j < N; ++j) with_derivatives += deriv_jet[i].v[j] != 0.0;
        }
      }
    }
  }
  CHECK(compared > 0);
  CHECK(with_derivatives > 0);  // the inner Jets carry the prescription's derivatives
  // The system's own pupil maps (prepare_system on these Jets runs the dual path) equal those of
  // the nested Jets: top, bottom and side as prepare_system forms them from the stop coordinates.
  const J r_s = sys.stop_radius_mm;
  for (int h = 0; h < static_cast<int>(sys.fields_deg.size()); ++h) {
    if (sys.fields_deg[h] == 0.0) continue;  // the axial map is the identity
    for (int w = 0; w <= sys.wavelength_count; ++w) {
      J coord[3], deriv[3];
      detail::trace_aiming_rays_jet(lens_a, w, sys, h, r_ep, sys.entrance_pupil_z_mm, identity,
                                    coord, deriv, nullptr, false);
      const J top = K<J>(1.0) + (r_s - coord[0]) / deriv[0];
      const J bottom = K<J>(-1.0) + (-r_s - coord[1]) / deriv[1];
      const J side = K<J>(1.0) + (r_s - coord[2]) / deriv[2];
      CAPTURE(h);
      CAPTURE(w);
      CHECK(same_bits(sys.pupil_map(h, w).scale_x, side));
      CHECK(same_bits(sys.pupil_map(h, w).offset_y, (top + bottom) / K<J>(2.0)));
      CHECK(same_bits(sys.pupil_map(h, w).scale_y, (top - bottom) / K<J>(2.0)));
    }
  }
}

}  // namespace

TEST_CASE("aiming on nested duals: the nested Jets' bits on a finite-object relay") {
  const auto path = test::source_dir() / "tests" / "data" / "relay_ac254_100_1to1.zmx";
  check_aiming<12>(path, true);
  check_aiming<8>(path, true);
}

TEST_CASE("aiming on nested duals: the nested Jets' bits on a double Gauss") {
  const auto path =
      test::source_dir() / "tests" / "data" / "independent" / "optiland_double_gauss.toml";
  check_aiming<12>(path, false);
  check_aiming<16>(path, false);
}

}  // namespace test_trace_aiming_dual
