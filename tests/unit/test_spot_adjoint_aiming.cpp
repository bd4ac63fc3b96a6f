// The ray aiming's reverse mode (trace/aiming_adjoint.h, issue 33): the adjoint gradients prepare
// the lens on Jets without the aiming and take the aimed pupil maps and their derivatives from a
// taped trace. The maps must equal those of prepare_system's Jets bit for bit (so the adjoint's
// values are those of the forward-mode preparation), and the gradients the Jets' within 1e-9
// relative: on the 24-surface Tessar with plates (71 variables, 9 chunks of 8), an asphere
// (two Newton steps in the aiming), a decentred lens (the axial field aimed on both sides) and a
// finite object given by object heights, with its stop behind a meniscus.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>

#include "lensopt/analysis/spot_adjoint.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/trace/aiming_adjoint.h"
#include "test_support.h"
#include "trace_checks.h"

namespace test_spot_adjoint_aiming {

using namespace lensopt;

namespace {

using test::mean_spot;
using test::worst_relative;

Lens lens_file(const std::string& relative) {
  return read_lens(test::source_dir() / relative);
}

// The AC254-100 at a 300 mm object (object-height fields) with a meniscus and an air gap before
// its stop: the aiming rays cross the meniscus, and the aimed pupil moves with the variables.
Lens finite_object_lens() {
  Lens lens = lens_file("tests/data/achromat_ac254_100_300mm.toml");
  REQUIRE(!lens.specs.object_at_infinity());
  REQUIRE(lens.specs.field_type == FieldType::kObjectHeight);
  Surface front, gap;
  front.curvature_per_mm = 1.0 / 120.0;
  front.thickness_mm = 3.0;
  front.material = Material::zemax_model(1.5168, 64.17);
  gap.thickness_mm = 4.0;
  lens.surfaces.insert(lens.surfaces.begin(), {front, gap});
  return lens;
}

// The doublet with two even aspheres, the first before the stop: the aiming traces it.
Lens asphere_doublet() {
  return lens_file("lenses/doublet-asphere.toml");
}

TraceOptions small_sampling() {
  TraceOptions options;
  options.rings = 6;
  options.fields = 4;
  return options;
}

// aim_pupil_maps on the values of a system prepared without aiming gives the maps of
// prepare_system's Jets (aiming on), bit for bit.
void check_maps(const Lens& lens, const TraceOptions& options) {
  using J = ceres::Jet<double, 8>;
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  const int chunk = std::min<int>(8, static_cast<int>(variables.size()));
  const TraceLens<J> lens_j = convert_trace_lens<J>(trace_lens, variables, 0, chunk,
                                                    [](double v, int j) { return J(v, j); });
  const SystemSetup setup = specs_setup(lens.specs, options, !trace_lens.geometry.placed());
  const TraceSystem<double> aimed = system_values(prepare_system(lens_j, setup, options));
  TraceOptions unaimed = options;
  unaimed.ray_aiming = false;
  TraceSystem<double> values = system_values(prepare_system(lens_j, setup, unaimed));
  // The maps of the plain pass and those of the taped one (the backward pass's forward trace).
  TraceSystem<double> taped = values;
  aim_pupil_maps(values, setup);
  const std::vector<double> start(values.fields_deg.size() * values.wavelength_count * 4, 1.0);
  aim_pupil_maps_adjoint(taped, setup, start);
  REQUIRE(values.pupil_maps.size() == aimed.pupil_maps.size());
  REQUIRE(taped.pupil_maps.size() == aimed.pupil_maps.size());
  int differing = 0, aimed_maps = 0;
  for (std::size_t i = 0; i < aimed.pupil_maps.size(); ++i) {
    const PupilMap<double>& a = aimed.pupil_maps[i];
    for (const PupilMap<double>& b : {values.pupil_maps[i], taped.pupil_maps[i]})
      differing += a.scale_x != b.scale_x || a.offset_y != b.offset_y || a.scale_y != b.scale_y;
    aimed_maps += a.scale_x != 1.0 || a.offset_y != 0.0 || a.scale_y != 1.0;
  }
  INFO(lens.name, ": ", differing, " of ", aimed.pupil_maps.size(), " maps differ");
  CHECK(differing == 0);
  CHECK(aimed_maps > 0);  // the aiming did something
}

// The spot adjoint (Jet chunks of 8) equals the Jet gradient within 1e-9 relative, and its value
// is bit for bit the one of the forward-mode preparation's system.
void check_spot(const Lens& lens, const TraceOptions& options) {
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  const SpotGradient jets = mean_spot_gradient_auto(trace_lens, lens.specs, variables, options);
  const SpotGradient adjoint =
      mean_spot_gradient_adjoint<8>(trace_lens, lens.specs, variables, options);
  REQUIRE(adjoint.gradient.size() == variables.size());
  using J = ceres::Jet<double, 8>;
  const TraceLens<J> lens_j =
      convert_trace_lens<J>(trace_lens, variables, 0, 0, [](double v, int j) { return J(v, j); });
  const TraceSystem<double> values = system_values(prepare_system(lens_j, lens.specs, options));
  CHECK(adjoint.mean_rms_spot_mm == mean_spot_adjoint(values, 1).value);
  CHECK(adjoint.mean_rms_spot_mm == doctest::Approx(mean_spot(lens, options)).epsilon(1e-12));
  const double worst = worst_relative(adjoint.gradient, jets.gradient);
  for (std::size_t i = 0; i < variables.size(); ++i)
    INFO(variables[i].name(), ": adjoint ", adjoint.gradient[i], " jets ", jets.gradient[i]);
  INFO(lens.name, ": ", variables.size(), " variables, worst relative difference ", worst);
  CHECK(worst < 1e-9);
}

}  // namespace

TEST_CASE("aiming adjoint: the aimed maps equal prepare_system's Jet maps bit for bit") {
  const TraceOptions options = small_sampling();
  check_maps(lens_file("lenses/tessar.toml"), options);
  check_maps(lens_file("lenses/bench/tessar-plates.toml"), options);
  check_maps(lens_file("lenses/bench/tessar-decentred.toml"), options);
  check_maps(asphere_doublet(), options);
  check_maps(finite_object_lens(), options);
  TraceOptions unscaled = options;
  unscaled.scale_to_spec = false;
  check_maps(lens_file("lenses/cooke.toml"), unscaled);
}

TEST_CASE("aiming adjoint: 24 surfaces, 71 variables in 9 Jet chunks (Jets agree)") {
  const Lens lens = lens_file("lenses/bench/tessar-plates.toml");
  REQUIRE(lens.surfaces.size() == 24);
  check_spot(lens, small_sampling());
}

TEST_CASE("aiming adjoint: an asphere before the stop, a decentred lens, a finite object") {
  check_spot(asphere_doublet(), small_sampling());
  check_spot(lens_file("lenses/bench/tessar-decentred.toml"), small_sampling());
  check_spot(finite_object_lens(), small_sampling());
  TraceOptions no_aiming = small_sampling();
  no_aiming.ray_aiming = false;
  check_spot(finite_object_lens(), no_aiming);
}

TEST_CASE("aiming adjoint: the design loss on the 24-surface lens (Jets agree)") {
  const GlassSpace glasses(*load_catalog("ohara"));
  const Lens lens = lens_file("lenses/bench/tessar-plates.toml");
  LensParameterization param(lens, glasses);
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions sampling;
  sampling.rings = 6;
  sampling.fields = 3;
  // The defaults: the plates' 0.4 mm air gaps keep the ray-path hinge active. (The ray-angle
  // hinge at 20 deg, exactly at a constraint field's angle on the plates: the next test.)
  const DesignLossOptions loss;
  for (GlassMode mode : {GlassMode::kQuantized, GlassMode::kContinuous}) {
    const DesignValueGradient adjoint = design_loss_gradient(param, x, mode, {}, sampling, loss);
    const DesignValueGradient jets = design_loss_gradient_jets(param, x, mode, {}, sampling, loss);
    REQUIRE(adjoint.gradient.size() == jets.gradient.size());
    CHECK(adjoint.loss.total == doctest::Approx(jets.loss.total).epsilon(1e-12));
    CHECK(jets.loss.ray_path_mm > 0.0);
    const double worst = worst_relative(adjoint.gradient, jets.gradient);
    INFO(param.size(), " variables, worst relative difference ", worst);
    CHECK(worst < 1e-9);
  }
}

// The ray-angle hinge at 20 deg on the Tessar with plane plates before it (and on the doublet
// with one plate): the 21 constraint fields include 20 deg exactly, whose collimated beam meets
// every front plate surface at the limit (incidence in air on a plate's first face, refraction
// into air at its second), each ray on the hinge's kink to within round-off: a tie. The adjoint
// and the Jets took the slope 0 or 1 per ray as round-off had it (their arithmetic rounds
// differently), 1.1e-4 apart on the plates' curvatures and neither the loss's one-sided
// nor its central derivative (6 % off on the doublet's plate). Both now take the central slope of
// a tie (detail::tied_hinge): equal to each other and to central differences of the loss.
TEST_CASE("design loss: the ray-angle hinge exactly at its bound on plane plates (a tie)") {
  const GlassSpace glasses(*load_catalog("ohara"));
  const Lens plates = lens_file("lenses/bench/tessar-plates.toml");
  Lens doublet = lens_file("lenses/doublet.toml");
  Surface plate = plates.surfaces[0], gap = plates.surfaces[1];  // 0.4 mm S-BSL7, 0.4 mm air
  REQUIRE(plate.curvature_per_mm == 0.0);
  doublet.surfaces.insert(doublet.surfaces.begin(), {plate, gap});
  for (const Lens& lens : {plates, doublet}) {
    LensParameterization param(lens, glasses);
    const std::vector<double> x = param.from_lens(lens);
    TraceOptions sampling;
    sampling.rings = 6;
    sampling.fields = 3;
    DesignLossOptions loss;
    loss.max_ray_angle_deg = 20.0;
    const GlassMode mode = GlassMode::kQuantized;
    const DesignValueGradient adjoint = design_loss_gradient(param, x, mode, {}, sampling, loss);
    const DesignValueGradient jets = design_loss_gradient_jets(param, x, mode, {}, sampling, loss);
    REQUIRE(adjoint.gradient.size() == jets.gradient.size());
    CHECK(jets.loss.ray_angle > 0.0);
    const double worst = worst_relative(adjoint.gradient, jets.gradient);
    INFO(lens.name, ": ", param.size(), " variables, worst relative difference ", worst);
    CHECK(worst < 1e-9);
    // Central differences of the double loss (h = 1e-6; 1e-5 and 1e-7 agree to 1e-8) on the
    // plates' curvatures and the first curved surfaces after them.
    auto total = [&](const std::vector<double>& at) {
      DesignLoss<double> terms;
      REQUIRE(evaluate_design<double>(param, at.data(), mode, {}, sampling, loss, nullptr, nullptr,
                                      &terms));
      return terms.total;
    };
    int checked = 0;
    for (int i = 0; i < param.size() && checked < 11; ++i) {
      if (param.variables()[i].name[0] != 'c') continue;
      ++checked;
      const double h = 1e-6;
      std::vector<double> plus = x, minus = x;
      plus[i] += h;
      minus[i] -= h;
      const double difference = (total(plus) - total(minus)) / (2.0 * h);
      INFO(lens.name, " ", param.variables()[i].name, ": adjoint ", adjoint.gradient[i], ", Jets ",
           jets.gradient[i], ", central difference ", difference);
      CHECK(std::abs(adjoint.gradient[i] - difference) <= 1e-6 * std::abs(difference));
      CHECK(std::abs(jets.gradient[i] - difference) <= 1e-6 * std::abs(difference));
    }
  }
}

}  // namespace test_spot_adjoint_aiming
