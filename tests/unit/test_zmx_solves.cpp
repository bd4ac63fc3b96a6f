// .zmx variables, pickups and solves (issue 31 item 2): "CURV c 1 ..." a curvature variable,
// "CURV c 4 source scale column" a curvature pickup (the scale on the curvature), "PZUP source
// scale offset column" a thickness pickup, "MAZH height zone" a marginal-ray-height solve; what
// lensopt cannot represent is a warning naming file and line, and a round trip keeps them.
#include <doctest/doctest.h>

#include <string>

#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/paraxial/solves.h"
#include "test_support.h"

namespace test_zmx_solves {

using namespace lensopt;

namespace {

bool has_warning(const std::vector<std::string>& warnings, const std::string& text) {
  for (const std::string& w : warnings)
    if (w.find(text) != std::string::npos) return true;
  return false;
}

std::string warnings_text(const std::vector<std::string>& warnings) {
  std::string out;
  for (const std::string& w : warnings) out += w + "\n";
  return out;
}

}  // namespace

TEST_CASE("zmx solves: a real file's curvature and thickness pickups are read") {
  // A symmetric double Gauss (rayoptics' US 583336): surfaces 8..12 mirror 6..2 about the stop
  // (CURV ... 4 src -1: c = -1 x c_src; PZUP src 1 0 0: t = t_src), and a marginal-ray-height
  // solve on a real ray (MAZH 0 0.7), which lensopt does not model.
  const std::filesystem::path path =
      test::source_dir() / "tests" / "data" / "zmx-real" / "rayoptics_US00583336-2-scaled.zmx";
  const ZmxImport imported = read_zmx(path);
  const Lens& lens = imported.lens;
  INFO(warnings_text(imported.warnings));
  REQUIRE(lens.surfaces.size() == 12);
  // .zmx surface n is lens surface n - 1 (0-based).
  for (const auto& [target, source] : {std::pair{8, 6}, {9, 5}, {10, 4}, {11, 3}, {12, 2}}) {
    INFO(".zmx surface ", target);
    const Surface& s = lens.surfaces[target - 1];
    CHECK(s.curvature_pickup.source == source - 1);
    CHECK(s.curvature_pickup.scale == -1.0);
    CHECK(s.curvature_per_mm == -lens.surfaces[source - 1].curvature_per_mm);
  }
  for (const auto& [target, source] : {std::pair{7, 6}, {8, 5}, {9, 4}, {10, 3}, {11, 2}}) {
    INFO(".zmx surface ", target);
    const Surface& s = lens.surfaces[target - 1];
    CHECK(s.thickness_pickup.source == source - 1);
    CHECK(s.thickness_pickup.scale == 1.0);
    CHECK(s.thickness_pickup.offset_mm == 0.0);
    CHECK(s.thickness_mm == lens.surfaces[source - 1].thickness_mm);
  }
  CHECK_FALSE(lens.surfaces.back().thickness_solve.active());
  CHECK(has_warning(imported.warnings,
                    "rayoptics_US00583336-2-scaled.zmx:193: surface 12: a "
                    "marginal-ray-height solve on a real ray (pupil zone 0.7)"));
  // Evaluating the pickups changes nothing: the file's values meet them.
  const Lens solved = with_solves(lens);
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
    CHECK(solved.surfaces[k].curvature_per_mm == lens.surfaces[k].curvature_per_mm);
    CHECK(solved.surfaces[k].thickness_mm == lens.surfaces[k].thickness_mm);
  }
}

TEST_CASE("zmx solves: unsupported solve types are warnings naming file and line") {
  const std::string text = R"(VERS 190513 80 123457 L123457
MODE SEQ
UNIT MM X W X CM MR CPMM
ENPD 10
FTYP 0 0 1 1 0 0 0
YFLN 0
WAVM 1 0.5875618 1
PWAV 1
SURF 0
  CURV 0
  DISZ INFINITY
SURF 1
  STOP
  CURV 0
  DISZ 2
SURF 2
  CURV 0.02 2 0.1 0 0 ""
  DISZ 4
  GLAS ___BLANK 1 0 1.5 60 0 0 0 0 0 0
SURF 3
  CURV -0.01 4 2 -1 3 ""
  DISZ 90
  PZUP 0 1 0 0
SURF 4
  CURV 0
  DISZ 0
)";
  const ZmxImport imported = parse_zmx(text, "s.zmx");
  INFO(warnings_text(imported.warnings));
  CHECK(has_warning(imported.warnings,
                    "s.zmx:17: surface 2: curvature solve type 2 is not "
                    "supported"));
  CHECK(has_warning(imported.warnings,
                    "s.zmx:21: surface 3: a curvature pickup from column 3 "
                    "of surface 2 is not supported"));
  CHECK(has_warning(imported.warnings,
                    "s.zmx:23: surface 3: the thickness pickup's source, "
                    "surface 0, is the object"));
  for (const Surface& s : imported.lens.surfaces) {
    CHECK_FALSE(s.curvature_pickup.active());
    CHECK_FALSE(s.thickness_pickup.active());
  }
  CHECK(imported.lens.surfaces[2].curvature_per_mm == -0.01);
}

TEST_CASE("zmx solves: variables, pickups and the focus solve survive a .zmx round trip") {
  Lens lens = read_lens(test::source_dir() / "tests" / "data" / "achromat_ac254_100_300mm.toml");
  lens.surfaces[1].vary.radius = true;
  lens.surfaces[1].vary.glass = true;
  lens.surfaces[2].vary.thickness = true;
  lens.surfaces[2].vary.conic = true;
  lens.surfaces[3].curvature_pickup = {1, -0.5, 0.0};
  lens.surfaces[2].thickness_pickup = {1, 0.5, 0.5};
  lens.surfaces[3].thickness_solve.kind = ThicknessSolve::Kind::kMarginalHeight;
  lens = with_solves(lens);
  const std::string text = format_zmx(lens);
  CHECK(text.find(" 1 0 0 0 \"\"\r\n") != std::string::npos);
  CHECK(text.find("NOTE 0 lensopt vary 3 thickness conic") != std::string::npos);
  CHECK(text.find("  PZUP 2 0.5 0.5 0") != std::string::npos);
  CHECK(text.find("  MAZH 0 0") != std::string::npos);
  CHECK(text.find(" 4 2 -0.5 0 \"\"") != std::string::npos);
  const ZmxImport back = parse_zmx(text, "back.zmx");
  INFO(warnings_text(back.warnings));
  REQUIRE(back.lens.surfaces.size() == lens.surfaces.size());
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
    INFO("surface ", k + 1);
    const Surface &a = lens.surfaces[k], &b = back.lens.surfaces[k];
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
    CHECK(b.curvature_per_mm == doctest::Approx(a.curvature_per_mm).epsilon(1e-14));
    CHECK(b.thickness_mm == doctest::Approx(a.thickness_mm).epsilon(1e-14));
  }
  // Read back through read_lens (which evaluates the solves): the same figures.
  const std::filesystem::path path = test::temp_root() / "solves_round_trip.zmx";
  write_lens(lens, path);
  const Lens reread = read_lens(path);
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k)
    CHECK(reread.surfaces[k].thickness_mm ==
          doctest::Approx(lens.surfaces[k].thickness_mm).epsilon(1e-12));
}

}  // namespace test_zmx_solves
