// Solves and variables in the lens model (issue 31 item 2; lens.h VaryFlags, Pickup,
// ThicknessSolve; paraxial/solves.h): TOML reading and writing with file:line errors, and the
// marginal-ray-height solve against closed forms (a thin singlet's 1/(1/f - 1/s), an independent
// y-nu trace of the achromat at 300 mm), evaluated by analyze on a lens edited after reading.
#include <doctest/doctest.h>

#include <cmath>
#include <string>

#include "lensopt/analysis/analyze.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/paraxial/solves.h"
#include "test_support.h"

namespace test_lens_solves {

using namespace lensopt;

namespace {

// A thin singlet (0 mm centre thickness) of a model glass behind a stop at its vertex, object
// at `object` mm (inf: at infinity), the last thickness a marginal-ray-height solve.
std::string thin_singlet_toml(const std::string& object, const std::string& height = "0") {
  return R"([lens]
name = "thin singlet"
[specs]
f_number = 8.0
wavelengths_nm = [587.5618]
[system]
mode = "as-written"
primary_wavelength_nm = 587.5618
aperture = "epd"
aperture_value = 10.0
field_type = ")" +
         std::string(object == "inf" ? "angle" : "object-height") + R"("
fields = [0.0, 1.0]
object_distance_mm = )" +
         object + R"(
[[surfaces]]
radius_mm = inf
thickness_mm = 0.0
stop = true
[[surfaces]]
radius_mm = 80.0
thickness_mm = 0.0
material = { nd = 1.5, vd = 60.0, model = "opticstudio" }
[[surfaces]]
radius_mm = -120.0
thickness_mm = 55.0
solve = { thickness = "marginal_height", height_mm = )" +
         height + R"( }
)";
}

}  // namespace

TEST_CASE("lens solves: TOML vary, pickups and solve read, write and read back") {
  const std::string text = R"([lens]
name = "t"
[specs]
f_number = 4.0
[[surfaces]]
radius_mm = 40.0
thickness_mm = 3.0
material = { nd = 1.6, vd = 50.0 }
vary = ["radius", "thickness", "glass"]
[[surfaces]]
radius_mm = -200.0
thickness_mm = 2.0
pickup_curvature = { surface = 1, scale = -1 }
[[surfaces]]
radius_mm = inf
thickness_mm = 1.5
stop = true
pickup_thickness = { surface = 1, scale = 0.5, offset_mm = 0.25 }
[[surfaces]]
radius_mm = 30.0
thickness_mm = 3.0
material = { nd = 1.6, vd = 50.0 }
vary = ["conic"]
[[surfaces]]
radius_mm = -60.0
thickness_mm = 40.0
solve = { thickness = "marginal_height", height_mm = 0 }
)";
  const Lens lens = parse_lens_toml(text, "t.toml");
  REQUIRE(lens.surfaces.size() == 5);
  CHECK(lens.surfaces[0].vary.radius);
  CHECK(lens.surfaces[0].vary.thickness);
  CHECK(lens.surfaces[0].vary.glass);
  CHECK_FALSE(lens.surfaces[0].vary.conic);
  CHECK(lens.surfaces[3].vary.conic);
  CHECK(lens.surfaces[1].curvature_pickup.source == 0);
  CHECK(lens.surfaces[1].curvature_pickup.scale == -1.0);
  CHECK(lens.surfaces[2].thickness_pickup.source == 0);
  CHECK(lens.surfaces[2].thickness_pickup.scale == 0.5);
  CHECK(lens.surfaces[2].thickness_pickup.offset_mm == 0.25);
  CHECK(lens.surfaces[4].thickness_solve.kind == ThicknessSolve::Kind::kMarginalHeight);
  CHECK(lens.has_vary_flags());
  CHECK(lens.has_solves());
  // Evaluated: c2 = -c1, t3 = 0.5 t1 + 0.25, t5 the paraxial focus (the BFL: object at infinity).
  const Lens solved = with_solves(lens);
  CHECK(solved.surfaces[1].curvature_per_mm == -solved.surfaces[0].curvature_per_mm);
  CHECK(solved.surfaces[2].thickness_mm == 0.5 * 3.0 + 0.25);
  const TraceLens<double> t = make_trace_lens(solved);
  CHECK(solved.surfaces[4].thickness_mm ==
        doctest::Approx(paraxial_data(t, t.reference_nm()).bfl_mm).epsilon(1e-13));
  // Written and read back: the same flags, pickups and solve.
  const Lens back = parse_lens_toml(format_lens_toml(lens), "back.toml");
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
    INFO("surface ", k + 1);
    const Surface &a = lens.surfaces[k], &b = back.surfaces[k];
    CHECK(a.vary.radius == b.vary.radius);
    CHECK(a.vary.thickness == b.vary.thickness);
    CHECK(a.vary.conic == b.vary.conic);
    CHECK(a.vary.glass == b.vary.glass);
    CHECK(a.curvature_pickup.source == b.curvature_pickup.source);
    CHECK(a.curvature_pickup.scale == b.curvature_pickup.scale);
    CHECK(a.thickness_pickup.source == b.thickness_pickup.source);
    CHECK(a.thickness_pickup.scale == b.thickness_pickup.scale);
    CHECK(a.thickness_pickup.offset_mm == b.thickness_pickup.offset_mm);
    CHECK(a.thickness_solve.kind == b.thickness_solve.kind);
    CHECK(a.thickness_solve.height_mm == b.thickness_solve.height_mm);
  }
}

TEST_CASE("lens solves: bad TOML solves are errors at file:line") {
  const std::string head = R"([lens]
name = "t"
[[surfaces]]
radius_mm = inf
thickness_mm = 1.0
stop = true
[[surfaces]]
radius_mm = 40.0
thickness_mm = 3.0
material = { nd = 1.6, vd = 50.0 }
[[surfaces]]
radius_mm = -60.0
thickness_mm = 40.0
)";
  auto error_of = [&](const std::string& extra) -> std::string {
    try {
      parse_lens_toml(head + extra, "bad.toml");
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  const std::string unknown = error_of("vary = [\"radious\"]\n");
  CHECK(unknown.find("bad.toml:14") != std::string::npos);
  CHECK(unknown.find("unknown vary entry \"radious\"") != std::string::npos);
  const std::string later = error_of("pickup_curvature = { surface = 3, scale = -1 }\n");
  CHECK(later.find("bad.toml:14") != std::string::npos);
  CHECK(later.find("earlier surface") != std::string::npos);
  const std::string kind = error_of("solve = { thickness = \"chief_height\" }\n");
  CHECK(kind.find("unknown thickness solve \"chief_height\"") != std::string::npos);
  const std::string offset = error_of("pickup_curvature = { surface = 2, offset_mm = 1 }\n");
  CHECK(offset.find("a curvature pickup has no offset") != std::string::npos);
}

TEST_CASE(
    "lens solves: the marginal-height solve of a thin singlet is the paraxial image 1/(1/f-1/s)") {
  // f of a thin lens in air: 1/f = (n - 1)(c1 - c2); n = 1.5 at 587.5618 nm exactly
  // (OpticStudio's model glass is nd at that wavelength).
  const double n = 1.5;
  const double f = 1.0 / ((n - 1.0) * (1.0 / 80.0 - 1.0 / -120.0));
  SUBCASE("object at infinity: the focal length") {
    const Lens lens = with_solves(parse_lens_toml(thin_singlet_toml("inf"), "s.toml"));
    CHECK(std::abs(lens.surfaces.back().thickness_mm - f) <= 1e-9);
  }
  SUBCASE("finite objects") {
    for (const double s : {150.0, 300.0, 1000.0}) {
      CAPTURE(s);
      const Lens lens =
          with_solves(parse_lens_toml(thin_singlet_toml(std::to_string(s)), "s.toml"));
      const double v = 1.0 / (1.0 / f - 1.0 / s);
      MESSAGE("thin singlet f = ", f, " mm, object ", s, " mm: solved ",
              lens.surfaces.back().thickness_mm, " mm, 1/(1/f - 1/s) = ", v, " mm");
      CHECK(std::abs(lens.surfaces.back().thickness_mm - v) <= 1e-9);
    }
  }
  SUBCASE("a nonzero height: the marginal ray's height h below the focus, h / u' behind it") {
    // Object at 300 mm, EPD 10 mm at the lens: the marginal ray leaves at u' = -(5 / v); it is
    // at height -0.1 mm a distance 0.1 / (5 / v) beyond the image.
    const double s = 300.0, v = 1.0 / (1.0 / f - 1.0 / s);
    const Lens lens = with_solves(parse_lens_toml(thin_singlet_toml("300", "-0.1"), "s.toml"));
    CHECK(std::abs(lens.surfaces.back().thickness_mm - (v + 0.1 * v / 5.0)) <= 1e-9);
  }
}

TEST_CASE("lens solves: the marginal-height solve of the achromat at 300 mm against a y-nu trace") {
  Lens lens = read_lens(test::source_dir() / "tests" / "data" / "achromat_ac254_100_300mm.toml");
  lens.surfaces.back().thickness_solve.kind = ThicknessSolve::Kind::kMarginalHeight;
  const Lens solved = with_solves(lens);
  // Independent: a y-nu trace of a ray from the axial object point (y = 0 at the object,
  // u = 1), refract w' = w - y c (n' - n), transfer y += t w / n', then y + t w / n = 0.
  const TraceLens<double> t = make_trace_lens(lens);
  const double nm = t.reference_nm();
  double y = 300.0, w = 1.0, n_before = 1.0;
  const int k_count = static_cast<int>(lens.surfaces.size());
  for (int k = 0; k < k_count; ++k) {
    const double n_after = t.index_at_nm(k, nm);
    w = w - y * lens.surfaces[k].curvature_per_mm * (n_after - n_before);
    if (k + 1 < k_count) y = y + lens.surfaces[k].thickness_mm * w / n_after;
    n_before = n_after;
  }
  const double image = -y * n_before / w;
  MESSAGE("achromat at 300 mm: solved image distance ", solved.surfaces.back().thickness_mm,
          " mm, y-nu ", image, " mm (written ", lens.surfaces.back().thickness_mm, ")");
  CHECK(std::abs(solved.surfaces.back().thickness_mm - image) <= 1e-9 * image);
  CHECK(image > lens.surfaces.back().thickness_mm + 20.0);
  // analyze evaluates the solve on a lens edited after reading (the written 97.1 mm is ~50 mm
  // short of focus).
  const AnalysisReport at_focus = analyze_lens(lens, AnalyzeOptions{});
  Lens unsolved = lens;
  unsolved.surfaces.back().thickness_solve = {};
  const AnalysisReport as_written = analyze_lens(unsolved, AnalyzeOptions{});
  MESSAGE("achromat at 300 mm: mean RMS spot with the solve ", *at_focus.mean_rms_spot_um,
          " um, as written ", *as_written.mean_rms_spot_um, " um");
  CHECK(*at_focus.mean_rms_spot_um < 0.2 * *as_written.mean_rms_spot_um);
}

}  // namespace test_lens_solves
