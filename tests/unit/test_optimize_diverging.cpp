// Diverging and afocal lenses in optimize and render (issue 31, item 3): efl_mm < 0 is a valid
// target; what optimize cannot do with it yet (a diverging lens, an afocal one) is refused,
// saying why, and render refuses an afocal lens (its image is at infinity).
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <string>

#include "error_checks.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/optimize/variables.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace lensopt {
namespace {

using test::check_contains;
using test::error_of;

// The Thorlabs LD1464-A bi-concave lens (EFL about -50 mm) with off-axis fields.
Lens diverging() {
  Lens lens =
      read_zmx(test::source_dir() / "tests" / "data" / "zmx-real" / "thorlabs_LD1464-A.zmx").lens;
  lens.specs.fields = {{0.0, 1.0, {}}, {2.0, 1.0, {}}, {4.0, 1.0, {}}};
  lens.specs.half_field_deg = 4.0;
  return lens;
}

TEST_CASE("optimize diverging: efl_mm = -50 is a valid target, refused with the reason") {
  const SourceLocation where{"cli"};
  const DesignTarget t = parse_target("efl_mm=-50", where);
  CHECK(t.quantity == TargetQuantity::kEflMm);
  CHECK(t.value == -50.0);
  // On the diverging lens: optimize says what it cannot do yet, and why.
  const Lens lens = diverging();
  const std::string solve = error_of([&] { apply_target_solves(lens, {t}); });
  check_contains(solve, "cannot yet optimize a diverging lens");
  check_contains(solve, "virtual");
  const std::string param =
      error_of([&] { LensParameterization(lens, GlassSpace(*load_catalog("schott"))); });
  check_contains(param, "-49.8");
  check_contains(param, "cannot yet optimize a diverging lens");
  // On a converging lens a negative focal length would carry the power through zero.
  const Lens doublet = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  check_contains(error_of([&] { apply_target_solves(doublet, {t}); }), "through zero");
}

TEST_CASE("optimize and render: an afocal lens is refused, naming what measures it") {
  const double n = 1.5168;
  const Lens lens = parse_lens_toml(
      fmt::format("[lens]\nname = \"keplerian\"\n[system]\nmode = \"as-written\"\nafocal = true\n"
                  "aperture = \"epd\"\naperture_value = 20\nprimary_wavelength_nm = 587.5618\n"
                  "fields = [0, 1]\n[specs]\nwavelengths_nm = [587.5618]\n"
                  "[[surfaces]]\nradius_mm = inf\nthickness_mm = 0\nstop = true\n"
                  "[[surfaces]]\ncurvature_per_mm = {:.17g}\nthickness_mm = 4\n"
                  "material = {{ nd = 1.5168, vd = 64.17, model = \"opticstudio\" }}\n"
                  "[[surfaces]]\nradius_mm = inf\nthickness_mm = {:.17g}\n"
                  "[[surfaces]]\nradius_mm = inf\nthickness_mm = 4\n"
                  "material = {{ nd = 1.5168, vd = 64.17, model = \"opticstudio\" }}\n"
                  "[[surfaces]]\ncurvature_per_mm = {:.17g}\nthickness_mm = 40\n",
                  1.0 / ((n - 1.0) * 100.0), 125.0 - 8.0 / n, -1.0 / ((n - 1.0) * 25.0)),
      "keplerian.toml");
  const std::string param =
      error_of([&] { LensParameterization(lens, GlassSpace(*load_catalog("schott"))); });
  check_contains(param, "keplerian.toml");
  check_contains(param, "cannot optimize an afocal lens");
  const std::string render = error_of([&] { build_imaging_model(lens, TraceOptions{}, {}); });
  check_contains(render, "cannot render an afocal lens");
  check_contains(render, "plot --kind spot");
}

}  // namespace
}  // namespace lensopt
