// Fields by real image height (issue 29): the chief-ray angle is solved so that the real chief ray
// through the entrance pupil's centre reaches the written image height, whatever clear apertures
// do to that ray, or the lens is refused naming the file and the field.
#include <doctest/doctest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace test_trace_fields {

using namespace lensopt;

namespace {

// The real chief ray of field h of `sys` (entrance pupil centre, reference wavelength), traced
// with (`clip`) or without the lens's clear apertures: its image height and status.
double chief_height(const TraceSystem<double>& sys, int h, bool clip, int* status = nullptr) {
  TraceLens<double> lens = sys.lens;
  if (!clip) lens.semi_diameter_mm.clear();
  RayBundle<double> ray;
  ray.resize(1);
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  start_pupil_ray(ray, 0, 0.0, 0.0, sys.entrance_pupil_z_mm,
                  std::numeric_limits<double>::infinity(), std::sin(theta), std::cos(theta), 0.0);
  trace_bundle(lens, sys.wavelength_count, lens.surface_count(), true, ray,
               static_cast<RayRecord<double>*>(nullptr));
  if (status) *status = ray.status[0];
  return ray.y[0];
}

// A lens's fields replaced by real image heights `heights` (as written, no scaling).
Lens with_image_height_fields(Lens lens, const std::vector<double>& heights) {
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.field_type = FieldType::kRealImageHeight;
  lens.specs.fields.clear();
  for (double v : heights) lens.specs.fields.push_back({v, 1.0, {}});
  return lens;
}

// The Cooke triplet as written at F/2 with a field stop: a flat air surface 1 mm before the
// image whose clear semi-diameter `field_stop_mm` clips the chief rays of the outer field.
Lens cooke_with_field_stop(double field_stop_mm) {
  Lens lens = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kFNumber;
  Surface& last = lens.surfaces.back();
  REQUIRE(last.thickness_mm > 2.0);
  last.thickness_mm -= 1.0;
  Surface stop_plane;
  stop_plane.thickness_mm = 1.0;
  stop_plane.semi_diameter_mm = field_stop_mm;
  lens.surfaces.push_back(stop_plane);
  return lens;
}

}  // namespace

TEST_CASE("fields: a real image height whose chief ray a clear aperture clips is solved exactly") {
  // The 20 deg chief ray's real image height, without any aperture.
  Lens open = cooke_with_field_stop(0.0);
  open.specs.field_type = FieldType::kAngle;
  open.specs.fields = {{0.0, 1.0, {}}, {20.0, 1.0, {}}};
  const TraceSystem<double> angle_sys = prepare_lens_system(open, TraceOptions{});
  const double v = chief_height(angle_sys, 1, false);
  REQUIRE(v > 4.0);

  // A field stop at 0.8 v clips that chief ray; the on-axis bundle passes it.
  const Lens lens = with_image_height_fields(cooke_with_field_stop(0.8 * v), {0.0, 0.5 * v, v});
  const TraceSystem<double> sys = prepare_lens_system(lens, TraceOptions{});
  REQUIRE(sys.fields_deg.size() == 3);
  CHECK(sys.field_solve_failure.empty());
  int status = kRayOk;
  for (int h = 1; h < 3; ++h) {
    const double target = lens.specs.fields[h].value;
    const double y = chief_height(sys, h, false, &status);
    CAPTURE(h);
    CHECK(status == kRayOk);
    CHECK(std::abs(y - target) < 1e-9);
    MESSAGE("field ", h, ": solved ", sys.fields_deg[h], " deg, |y - v| = ", std::abs(y - target),
            " mm");
  }
  CHECK(sys.fields_deg[2] == doctest::Approx(20.0).epsilon(1e-10));
  // The outer chief ray is clipped by the field stop at the solution (so the solve had to trace
  // without the apertures) ...
  chief_height(sys, 2, true, &status);
  CHECK(status == kRayVignetted);
  // ... and already at the paraxial estimate the solve starts from: the old solve stopped there
  // (its first traced height was NaN) and kept that angle, whose real height is off by the
  // lens's distortion.
  TraceSystem<double> guess = sys;
  const double paraxial_per_tan =
      paraxial_image_height(sys.lens, sys.entrance_pupil_z_mm, 1.0, sys.lens.reference_nm());
  guess.fields_deg[2] = std::atan(v / paraxial_per_tan) * 180.0 / kPi;
  const double y_guess = chief_height(guess, 2, false);
  chief_height(guess, 2, true, &status);
  CHECK(status == kRayVignetted);
  MESSAGE("paraxial estimate ", guess.fields_deg[2], " deg: real height ", y_guess, " mm for ", v,
          " mm (", 100.0 * (y_guess - v) / v, " %)");
  CHECK(std::abs(y_guess - v) > 1e-3);
}

TEST_CASE("fields: image-height fields converge to 1e-9 mm on the shipped and real .zmx lenses") {
  // Every lens's own angle fields, turned into the real image heights of their chief rays and
  // solved back: the angles return and the heights hold to 1e-9 mm.
  const std::filesystem::path root = test::source_dir();
  const std::vector<std::filesystem::path> files = {
      root / "lenses/zmx/achromat_ac254_100.zmx", root / "lenses/zmx/cooke_triplet_50.zmx",
      root / "lenses/zmx/double_gauss_100.zmx", root / "tests/data/zmx-real/optiland_lens1.zmx",
      root / "tests/data/zmx-real/rayoptics_US00583336-2-scaled.zmx"};
  double worst = 0.0;
  for (const std::filesystem::path& file : files) {
    CAPTURE(file.string());
    const Lens lens = read_lens(file);
    const TraceSystem<double> angle_sys = prepare_lens_system(lens, TraceOptions{});
    std::vector<double> heights;
    for (int h = 0; h < static_cast<int>(angle_sys.fields_deg.size()); ++h)
      heights.push_back(chief_height(angle_sys, h, false));
    const Lens converted = with_image_height_fields(lens, heights);
    const TraceSystem<double> sys = prepare_lens_system(converted, TraceOptions{});
    REQUIRE(sys.fields_deg.size() == heights.size());
    for (int h = 0; h < static_cast<int>(heights.size()); ++h) {
      const double residual = std::abs(chief_height(sys, h, false) - heights[h]);
      CAPTURE(h);
      CHECK(residual < 1e-9);
      CHECK(sys.fields_deg[h] == doctest::Approx(angle_sys.fields_deg[h]).epsilon(1e-9));
      worst = std::max(worst, residual);
    }
  }
  MESSAGE("largest |y - v| over the converted fields: ", worst, " mm");
}

TEST_CASE("fields: an image height no chief ray reaches is refused, naming the file and field") {
  const std::filesystem::path file = test::temp_root() / "unreachable_field.toml";
  Lens lens = with_image_height_fields(cooke_with_field_stop(0.0), {0.0, 3.0, 5000.0});
  lens.source_path = file.string();
  try {
    (void)prepare_lens_system(lens, TraceOptions{});
    FAIL("a 5000 mm real image height was accepted");
  } catch (const Error& e) {
    const std::string what = e.what();
    CAPTURE(what);
    CHECK(what.find(file.string()) != std::string::npos);
    CHECK(what.find("field 3") != std::string::npos);
    CHECK(what.find("5000 mm") != std::string::npos);
  }
  // The kernel-level call does not throw: it reports the failure in the system.
  const SystemSetup setup = lens_setup(lens, TraceOptions{});
  const TraceSystem<double> sys = prepare_system(make_trace_lens(lens), setup, TraceOptions{});
  CHECK_FALSE(sys.field_solve_failure.empty());
  CHECK(sys.field_solve_failure.find("field 3") != std::string::npos);
}

}  // namespace test_trace_fields
