// lensopt's coordinate breaks and tilt handedness against optiland (issue 32): real rays through
// tests/data/independent/geometry3d_cb.zmx (two singlets behind OpticStudio coordinate breaks,
// decentred and tilted about x and about y), traced by optiland from its own reading of the same
// .zmx (generate_optiland_geometry3d.py, optiland_run_geometry3d.json; sources in README.md), agree
// with lensopt's trace within 1e-9 of the focal length. And the file's x field imports and traces.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace test_reference_geometry3d {

using namespace lensopt;

TEST_CASE("reference geometry3d: coordinate breaks and tilts match optiland's trace") {
  const std::filesystem::path dir = test::source_dir() / "tests" / "data" / "independent";
  std::ifstream in(dir / "optiland_run_geometry3d.json");
  REQUIRE(in.good());
  const nlohmann::json ref = nlohmann::json::parse(in);
  const Lens lens = read_lens(dir / "geometry3d_cb.zmx");
  REQUIRE(lens.breaks_symmetry());
  const TraceLens<double> tl = make_trace_lens(lens);
  const int w = static_cast<int>(tl.wavelengths_nm.size()) - 1;
  // The indices optiland was given (its IdealMaterial): lensopt's model glass at 587.5618 nm.
  CHECK(tl.index(2, w) == doctest::Approx(1.5168).epsilon(1e-15));
  CHECK(tl.index(5, w) == doctest::Approx(1.6).epsilon(1e-15));
  const double efl = std::abs(paraxial_data(tl, tl.wavelengths_nm[w]).efl_mm);
  REQUIRE(efl > 10.0);
  const double bound = 1e-9 * efl;
  double worst = 0.0, worst_direction = 0.0;
  int count = 0;
  for (const nlohmann::json& r : ref["rays"]) {
    RayBundle<double> rays;
    rays.resize(1);
    rays.x[0] = r["start"][0].get<double>();
    rays.y[0] = r["start"][1].get<double>();
    rays.z[0] = r["start"][2].get<double>();
    rays.l[0] = r["direction"][0].get<double>();
    rays.m[0] = r["direction"][1].get<double>();
    rays.n[0] = r["direction"][2].get<double>();
    trace_bundle(tl, w, tl.surface_count(), true, rays, static_cast<RayRecord<double>*>(nullptr));
    REQUIRE(rays.status[0] == kRayOk);
    const double dx = rays.x[0] - r["image_xy"][0].get<double>();
    const double dy = rays.y[0] - r["image_xy"][1].get<double>();
    const double dl = rays.l[0] - r["image_LMN"][0].get<double>();
    const double dm = rays.m[0] - r["image_LMN"][1].get<double>();
    const double dn = rays.n[0] - r["image_LMN"][2].get<double>();
    CAPTURE(r["field"].get<std::string>());
    CAPTURE(r["stop_point"].dump());
    CHECK(std::hypot(dx, dy) < bound);
    CHECK(std::abs(dl) + std::abs(dm) + std::abs(dn) < 1e-9);
    worst = std::max(worst, std::hypot(dx, dy));
    worst_direction = std::max(worst_direction, std::abs(dl) + std::abs(dm) + std::abs(dn));
    ++count;
  }
  CHECK(count == 18);
  MESSAGE(
      fmt::format("{} rays: largest image difference {:.3e} mm (bound {:.3e} = 1e-9 EFL, EFL "
                  "{:.6f} mm), direction {:.3e}",
                  count, worst, bound, efl, worst_direction));
  // The file's field on x (XFLN 2) imports on this lens without rotational symmetry, and
  // lensopt's own rays of that field (start_rays in the field's frame, turned by the kernel,
  // image turned back to the lens frame) are optiland's: the stop is surface 1, so the entrance
  // pupil is the stop (z = 0, radius 5) and without ray aiming a pupil point is a stop point.
  REQUIRE(lens.specs.fields.size() == 3);
  CHECK(lens.specs.fields[2].x == 2.0);
  CHECK(lens.specs.fields[2].value == 0.0);
  TraceOptions options;
  options.ray_aiming = false;
  const TraceSystem<double> sys = prepare_lens_system(lens, options);
  int hx = -1;
  for (int h = 0; h < static_cast<int>(sys.fields_deg.size()); ++h)
    if (sys.field_azimuth(h) != 0.0) hx = h;
  REQUIRE(hx >= 0);
  CHECK(sys.field_azimuth(hx) == 90.0);
  CHECK(sys.entrance_pupil_z_mm == 0.0);
  CHECK(sys.epd_mm == 10.0);
  // Lens-frame stop points (0, 0), (4, 0), (0, 4) are field-frame (u, v) = (-y, x) / 5.
  PupilSamples pupil;
  pupil.x = {0.0, 0.0, -0.8};
  pupil.y = {0.0, 0.8, 0.0};
  const double stop_points[3][2] = {{0.0, 0.0}, {4.0, 0.0}, {0.0, 4.0}};
  RayBundle<double> rays;
  start_rays(sys, hx, 0, rays, &pupil);
  trace_bundle(sys.lens, 0, sys.lens.surface_count(), true, rays,
               static_cast<RayRecord<double>*>(nullptr));
  int matched = 0;
  double worst_field = 0.0;
  for (int i = 0; i < 3; ++i) {
    REQUIRE(rays.status[i] == kRayOk);
    double x = 0, y = 0;
    sys.field_to_lens(hx, rays.x[i], rays.y[i], x, y);
    for (const nlohmann::json& r : ref["rays"]) {
      if (r["field"].get<std::string>() != "x 2 deg" ||
          r["stop_point"][0].get<double>() != stop_points[i][0] ||
          r["stop_point"][1].get<double>() != stop_points[i][1])
        continue;
      ++matched;
      const double d =
          std::hypot(x - r["image_xy"][0].get<double>(), y - r["image_xy"][1].get<double>());
      CAPTURE(i);
      CHECK(d < bound);
      worst_field = std::max(worst_field, d);
    }
  }
  CHECK(matched == 3);
  MESSAGE(
      fmt::format("field (2, 0) deg through lensopt's field frame: largest difference "
                  "{:.3e} mm",
                  worst_field));
}

}  // namespace test_reference_geometry3d
