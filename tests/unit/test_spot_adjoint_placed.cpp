// The adjoint (reverse-mode) gradient beyond rotational symmetry (issue 32): 3D placements
// (decenters and tilts, both orders, restore_frame), coordinate breaks, fold mirrors, mirrors on
// the symmetric path, obscurations, clipping clear apertures (centred and decentred) and fields
// off the y axis. On each lens the adjoint must be taken (adjoint_supported: before the placed
// backward pass these lenses fell back to the Jet path), equal the Jet gradient within 1e-9
// relative and central finite differences within 1e-6; the design loss's adjoint equals its
// Jets on the decentred Tessar.
#include <doctest/doctest.h>

#include <cmath>

#include "lensopt/analysis/apertures.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/analysis/spot_adjoint.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "test_support.h"
#include "trace_checks.h"

namespace test_spot_adjoint_placed {

using namespace lensopt;

namespace {

using test::mean_spot;
using test::worst_relative;

Lens decentred_tessar() {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "bench" / "tessar-decentred.toml");
  REQUIRE(lens.breaks_symmetry());
  return lens;
}

FieldPoint field_at(double x, double y) {
  FieldPoint f;
  f.x = x;
  f.value = y;
  return f;
}

TraceOptions small_sampling() {
  TraceOptions options;
  options.rings = 6;
  options.fields = 3;
  return options;
}

// The prescription variables of a lens's optical surfaces (a coordinate break has no curvature).
std::vector<PrescriptionVariable> optical_variables(const Lens& lens) {
  std::vector<PrescriptionVariable> out;
  for (const PrescriptionVariable& v : all_prescription_variables(lens))
    if (v.kind != PrescriptionVariable::Kind::kCurvature ||
        !lens.surfaces[v.surface].coordinate_break)
      out.push_back(v);
  return out;
}

// The adjoint is taken, equals the Jets within 1e-9 relative and (if `fd`) central differences
// within 1e-6; returns the number of rays that fail or are vignetted in the traced system.
int check_spot(const Lens& lens, const TraceOptions& options, bool fd = true) {
  const std::vector<PrescriptionVariable> variables = optical_variables(lens);
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  CHECK(adjoint_supported(trace_lens));
  const SpotGradient jets = mean_spot_gradient_auto(trace_lens, lens.specs, variables, options);
  const SpotGradient adjoint =
      mean_spot_gradient_adjoint<8>(trace_lens, lens.specs, variables, options);
  REQUIRE(adjoint.gradient.size() == variables.size());
  const double value = mean_spot(lens, options);
  CHECK(value > 0.0);
  CHECK(adjoint.mean_rms_spot_mm == doctest::Approx(value).epsilon(1e-12));
  for (std::size_t i = 0; i < variables.size(); ++i)
    INFO(variables[i].name(), ": adjoint ", adjoint.gradient[i], " jets ", jets.gradient[i]);
  const double worst = worst_relative(adjoint.gradient, jets.gradient);
  MESSAGE(lens.name, ": worst relative difference to the Jets ", worst);
  CHECK(worst < 1e-9);
  // mean_spot_gradient_fast takes the adjoint: the same numbers.
  const SpotGradient fast = mean_spot_gradient_fast(trace_lens, lens.specs, variables, options);
  CHECK(worst_relative(fast.gradient, jets.gradient) < 1e-9);
  if (fd) {
    const std::vector<double> differences =
        test::mean_spot_central_differences(lens, variables, options, 0.05);
    for (std::size_t i = 0; i < variables.size(); ++i)
      INFO(variables[i].name(), ": adjoint ", adjoint.gradient[i], " differences ", differences[i]);
    const double worst_fd = worst_relative(adjoint.gradient, differences);
    MESSAGE(lens.name, ": worst relative difference to central differences ", worst_fd);
    CHECK(worst_fd < 1e-6);
  }
  const TraceSystem<double> sys = prepare_system(trace_lens, lens.specs, options);
  const SpotResult<double> spots = evaluate_spots(sys);
  int removed = spots.total_failed;
  for (int v : spots.vignetted_rays) removed += v;
  return removed;
}

// A singlet, then a 45-degree fold mirror (between two coordinate breaks) on the way to the
// image, a central obscuration on the stop and a decentred clear aperture on the mirror.
Lens folded_singlet() {
  Lens lens;
  lens.name = "folded";
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 10.0;
  lens.specs.fields = {field_at(0.0, 0.0), field_at(0.0, 2.0), field_at(1.5, -2.5)};
  Surface stop;
  stop.is_stop = true;
  stop.thickness_mm = 5.0;
  stop.obscuration_mm = 1.2;
  Surface front, back, mirror, before, after;
  front.curvature_per_mm = 1.0 / 60.0;
  front.thickness_mm = 5.0;
  front.material = Material::model(1.6, 40.0);
  back.curvature_per_mm = -1.0 / 80.0;
  back.thickness_mm = 40.0;
  before.coordinate_break = true;
  before.placement.tilt_x_deg = 45.0;
  before.placement.decenter_y_mm = 0.05;
  mirror.mirror = true;
  mirror.curvature_per_mm = 1.0 / 900.0;
  mirror.semi_diameter_mm = 5.2;
  mirror.aperture_decenter_x_mm = 0.3;
  after.coordinate_break = true;
  after.placement.tilt_x_deg = 45.0;
  after.placement.tilt_first = true;
  after.placement.decenter_x_mm = -0.02;
  after.thickness_mm = -47.0;
  lens.surfaces = {stop, front, back, before, mirror, after};
  return lens;
}

}  // namespace

TEST_CASE("placed adjoint: the decentred Tessar equals the Jets and central differences") {
  // The front element decentred 0.02 mm and tilted 1 arcmin (surface placement on its first
  // face, restored after the second), spec scaling on: the decenters scale with the lens.
  const Lens lens = decentred_tessar();
  check_spot(lens, small_sampling());
  // Without ray aiming, and unscaled (the decenters then constants).
  TraceOptions options = small_sampling();
  options.ray_aiming = false;
  check_spot(lens, options, false);
  options.ray_aiming = true;
  options.scale_to_spec = false;
  check_spot(lens, options, false);
  // Tilt first (OpticStudio's order flag 1), a decenter in x and a tilt about y and z.
  Lens other = lens;
  for (int k : {0, 1}) {
    Placement& p = other.surfaces[k].placement;
    p.tilt_first = true;
    p.decenter_x_mm = -0.03;
    p.tilt_y_deg = 0.05;
    p.tilt_z_deg = 2.0;
  }
  check_spot(other, small_sampling());
}

TEST_CASE("placed adjoint: fields off the y axis (the field frame's turn)") {
  Lens lens = decentred_tessar();
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 8.0;
  lens.specs.fields = {field_at(0.0, 0.0), field_at(12.0, 0.0), field_at(-9.0, 14.0)};
  TraceOptions options = small_sampling();
  check_spot(lens, options);
}

TEST_CASE("placed adjoint: a fold mirror between coordinate breaks, obscured and clipped") {
  const Lens lens = folded_singlet();
  REQUIRE(make_trace_lens(lens).geometry.placed());
  const int failed = check_spot(lens, small_sampling());
  // The obscuration and the decentred aperture remove rays.
  MESSAGE("folded singlet: ", failed, " rays obscured or clipped");
  CHECK(failed > 0);
}

TEST_CASE("placed adjoint: clipping semi-diameters on the symmetric and the placed path") {
  // The Tessar's front surface clipped to 95 % of the height its beams reach: the outer fields
  // lose the rim of their pupils.
  for (const std::string name : {"tessar.toml", "bench/tessar-decentred.toml"}) {
    Lens lens = read_lens(test::source_dir() / "lenses" / name);
    lens.surfaces[0].semi_diameter_mm = 0.95 * automatic_semi_diameters(lens)[0];
    const int failed = check_spot(lens, small_sampling());
    MESSAGE(name, ": ", failed, " rays clipped, semi-diameter ", lens.surfaces[0].semi_diameter_mm);
    CHECK(failed > 0);
  }
}

TEST_CASE("placed adjoint: a Cassegrain-like mirror pair on the symmetric path") {
  // A paraboloid primary with a central obscuration and a convex secondary: mirrors (negative
  // indices after each reflection, negative thicknesses) on the rotationally symmetric path.
  Lens lens;
  lens.name = "cassegrain";
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 40.0;
  lens.specs.fields = {field_at(0.0, 0.0), field_at(0.0, 0.3), field_at(0.0, 0.5)};
  Surface stop, primary, secondary;
  stop.is_stop = true;
  stop.thickness_mm = 60.0;
  stop.obscuration_mm = 8.0;
  primary.mirror = true;
  primary.curvature_per_mm = -1.0 / 200.0;
  primary.conic = -1.0;
  primary.thickness_mm = -70.0;
  secondary.mirror = true;
  secondary.curvature_per_mm = -1.0 / 90.0;
  secondary.thickness_mm = 110.0;
  lens.surfaces = {stop, primary, secondary};
  REQUIRE(!make_trace_lens(lens).geometry.placed());
  check_spot(lens, small_sampling());
}

TEST_CASE("placed adjoint: the design loss's adjoint equals its Jets on the decentred Tessar") {
  const Lens lens = decentred_tessar();
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions sampling = small_sampling();
  DesignLossOptions loss;
  loss.min_image_clearance_mm = 14.0;  // the ray-path hinge active
  loss.max_ray_angle_deg = 20.0;       // the ray-angle hinge active
  loss.max_glass_mm = 2.0;
  CHECK(adjoint_supported(make_trace_lens(lens)));
  for (GlassMode mode : {GlassMode::kQuantized, GlassMode::kContinuous}) {
    const DesignValueGradient adjoint = design_loss_gradient(param, x, mode, {}, sampling, loss);
    const DesignValueGradient jets = design_loss_gradient_jets(param, x, mode, {}, sampling, loss);
    CHECK(adjoint.finite == jets.finite);
    CHECK(adjoint.loss.total == doctest::Approx(jets.loss.total).epsilon(1e-12));
    CHECK(adjoint.loss.spot_mm == doctest::Approx(jets.loss.spot_mm).epsilon(1e-12));
    CHECK(adjoint.loss.ray_path_mm == doctest::Approx(jets.loss.ray_path_mm).epsilon(1e-12));
    CHECK(adjoint.loss.ray_angle == doctest::Approx(jets.loss.ray_angle).epsilon(1e-12));
    CHECK(jets.loss.ray_path_mm > 0.0);
    CHECK(jets.loss.ray_angle > 0.0);
    const double worst = worst_relative(adjoint.gradient, jets.gradient);
    for (int i = 0; i < param.size(); ++i)
      INFO(param.variables()[i].name, ": adjoint ", adjoint.gradient[i], " jets ",
           jets.gradient[i]);
    INFO("worst relative difference ", worst);
    CHECK(worst < 1e-9);
  }
}

TEST_CASE("spot adjoint: a finite object's ray directions follow their start points") {
  // The AC254-100 at a 300 mm object with a weak meniscus and an air gap before its stop: the
  // aimed pupil and the entrance pupil's z depend on the variables, and every ray's direction
  // (from the object point through its start point) with them. Before chain_start_direction the
  // adjoint left that dependence out (3.1 relative from the Jets).
  Lens lens = read_lens(test::source_dir() / "tests" / "data" / "achromat_ac254_100_300mm.toml");
  REQUIRE(!lens.specs.object_at_infinity());
  Surface front, gap;
  front.curvature_per_mm = 1.0 / 120.0;
  front.thickness_mm = 3.0;
  front.material = Material::zemax_model(1.5168, 64.17);
  gap.thickness_mm = 4.0;
  lens.surfaces.insert(lens.surfaces.begin(), {front, gap});
  check_spot(lens, small_sampling());
  // The same lens decentred (the placed path's start directions, turned for an x field).
  lens.surfaces[0].placement.decenter_x_mm = 0.05;
  lens.surfaces[0].placement.tilt_y_deg = 0.1;
  lens.specs.fields = {field_at(0.0, 0.0), field_at(4.0, 6.0), field_at(-8.0, 0.0)};
  check_spot(lens, small_sampling());
}

}  // namespace test_spot_adjoint_placed
