// Tolerancing by surface decenter and tilt (TSDX, TSDY, TSTX, TSTY; issue 32) and inverse
// sensitivity: the parameters and their keys, a wedge's exact deviation, the first-order image
// shift of a decentred surface, and an inverse limit that reproduces its drop when applied.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <string>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens.h"
#include "lensopt/tolerance/tolerance.h"
#include "lensopt/trace/kernel.h"
#include "test_support.h"

namespace test_tolerance_surface {

using namespace lensopt;

namespace {

// A singlet (or a plate: c = 0) behind its stop, on axis and at 5 deg, traced as written.
Lens singlet(double c_front, double c_back, double image_mm) {
  Lens lens;
  lens.name = "singlet";
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 4.0;
  lens.specs.fields = {FieldPoint{0.0}, FieldPoint{5.0}};
  lens.specs.wavelengths_nm = {587.6};
  lens.specs.wavelength_channels = {1};
  Surface stop, front, back;
  stop.is_stop = true;
  stop.thickness_mm = 0.5;
  front.curvature_per_mm = c_front;
  front.thickness_mm = 2.0;
  front.material = Material::model(1.5, 60.0);
  back.curvature_per_mm = c_back;
  back.thickness_mm = image_mm;
  lens.surfaces = {stop, front, back};
  return lens;
}

ToleranceOptions surface_options(double decenter_mm, double tilt_arcmin) {
  ToleranceOptions o;
  o.tolerances = Tolerances::zero();
  o.tolerances.surface_decenter_mm = decenter_mm;
  o.tolerances.surface_tilt_arcmin = tilt_arcmin;
  o.compensator = FocusCompensator::kNone;
  o.rings = 8;
  o.jobs = 1;
  return o;
}

int parameter_index(const ToleranceModel& model, const std::string& name) {
  const std::vector<ToleranceParameter>& params = model.parameters();
  for (std::size_t i = 0; i < params.size(); ++i)
    if (params[i].name == name) return static_cast<int>(i);
  return -1;
}

// The axial ray (x, y) = (0, 0) along +z traced through a perturbed lens to its image plane.
RayBundle<double> axial_ray(const TraceLens<double>& tl) {
  RayBundle<double> rays;
  rays.resize(1);
  rays.x[0] = rays.y[0] = rays.z[0] = 0.0;
  rays.l[0] = rays.m[0] = 0.0;
  rays.n[0] = 1.0;
  trace_bundle(tl, static_cast<int>(tl.wavelengths_nm.size()) - 1, tl.surface_count(), true, rays,
               static_cast<RayRecord<double>*>(nullptr));
  return rays;
}

}  // namespace

TEST_CASE(
    "tolerance surface: TSDX/TSDY/TSTX/TSTY per surface, tilt on by default, [tolerance] "
    "keys") {
  const Lens tessar = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  // The defaults (docs/tolerance.md): each surface's tilt (its wedge) on at 1 arcmin, its
  // decenter off (a sphere decentred by d is the sphere tilted by d / R).
  const Tolerances defaults;
  CHECK(defaults.surface_decenter_mm == 0.0);
  CHECK(defaults.surface_tilt_arcmin == 1.0);
  int default_tilts = 0;
  for (const ToleranceParameter& p : tolerance_parameters(tessar, defaults)) {
    CHECK(p.kind != ToleranceParameter::Kind::kSurfaceDecenterX);
    CHECK(p.kind != ToleranceParameter::Kind::kSurfaceDecenterY);
    if (p.kind == ToleranceParameter::Kind::kSurfaceTiltX) ++default_tilts;
  }
  CHECK(default_tilts == 7);
  // With both at 0 the parameter list is the one of before (no surface rows), and the draws of
  // the parameters before the surface rows do not change with them (each trial draws in order).
  Tolerances off = defaults;
  off.surface_tilt_arcmin = 0.0;
  const std::vector<ToleranceParameter> before = tolerance_parameters(tessar, off);
  for (const ToleranceParameter& p : before)
    CHECK(p.kind < ToleranceParameter::Kind::kSurfaceDecenterX);
  {
    ToleranceOptions a, b;
    a.tolerances = off;
    a.trials = 1;
    b.trials = 1;
    const ToleranceModel model_off(tessar, a), model_on(tessar, b);
    REQUIRE(model_on.parameters().size() == before.size() + 14);
    for (int trial : {0, 7, 123}) {
      const std::vector<double> d_off = model_off.draw(trial), d_on = model_on.draw(trial);
      CHECK(std::vector<double>(d_on.begin(), d_on.begin() + static_cast<long>(d_off.size())) ==
            d_off);
    }
  }
  Tolerances t = defaults;
  t.surface_decenter_mm = 0.01;
  t.surface_tilt_arcmin = 1.0;
  int decenters = 0, tilts = 0;
  for (const ToleranceParameter& p : tolerance_parameters(tessar, t)) {
    if (p.kind == ToleranceParameter::Kind::kSurfaceDecenterX) ++decenters;
    if (p.kind == ToleranceParameter::Kind::kSurfaceTiltY) ++tilts;
    if (p.kind == ToleranceParameter::Kind::kSurfaceTiltX && p.surface == 0) {
      CHECK(p.name == "tstx1");
      CHECK(p.limit_text == "1 arcmin");
      CHECK(p.description == "surface 1 tilt (wedge) about x");
    }
    // Never the stop.
    if (p.kind >= ToleranceParameter::Kind::kSurfaceDecenterX)
      CHECK(!tessar.surfaces[static_cast<std::size_t>(p.surface)].is_stop);
  }
  // The Tessar: 7 curved surfaces and its flat stop.
  CHECK(decenters == 7);
  CHECK(tilts == 7);
  const ToleranceSettings s = parse_tolerance_table(
      "[tolerance]\nsurface_decenter_mm = 0.005\nsurface_tilt_arcmin = 0.5\ninverse_drop_um = 2\n",
      "x.toml");
  REQUIRE(s.surface_decenter_mm);
  CHECK(*s.surface_decenter_mm == 0.005);
  REQUIRE(s.surface_tilt_arcmin);
  CHECK(*s.surface_tilt_arcmin == 0.5);
  REQUIRE(s.inverse_drop_um);
  CHECK(*s.inverse_drop_um == 2.0);
  CHECK_THROWS_AS(parse_tolerance_table("[tolerance]\nsurface_tilt_arcmin = -1\n", "x.toml"),
                  Error);
  CHECK_THROWS_AS(parse_tolerance_table("[tolerance]\ninverse_drop_um = 0\n", "x.toml"), Error);
}

TEST_CASE("tolerance surface: a wedge (a tilted flat back face) deviates by the exact angle") {
  // A plano-convex singlet whose flat back face is tilted by theta about x: the axial ray meets
  // the front vertex along its normal, crosses the glass undeviated, meets the back face at
  // incidence theta and leaves at asin(n sin theta): deviation asin(n sin theta) - theta,
  // exactly (Snell's law at one plane).
  const Lens plate = singlet(1.0 / 100.0, 0.0, 50.0);
  const ToleranceModel model(plate, surface_options(0.01, 30.0));
  // A flat face gets no decenter (a plane decentred in itself is the same plane).
  CHECK(parameter_index(model, "tsdx3") < 0);
  CHECK(parameter_index(model, "tsdx2") >= 0);
  const int tstx3 = parameter_index(model, "tstx3");
  REQUIRE(tstx3 >= 0);
  std::vector<double> d(model.parameters().size(), 0.0);
  d[static_cast<std::size_t>(tstx3)] = 30.0;  // arcmin
  const TraceLens<double> tl = model.perturbed_trace_lens(d);
  const RayBundle<double> ray = axial_ray(tl);
  REQUIRE(ray.status[0] == kRayOk);
  const double theta = 0.5 * kPi / 180.0;
  const double n = tl.index(1, static_cast<int>(tl.wavelengths_nm.size()) - 1);
  const double deviation = std::asin(n * std::sin(theta)) - theta;
  MESSAGE(fmt::format("wedge 30': n {:.9f}, deviation {:.12e} rad, traced |m| {:.12e}", n,
                      deviation, std::abs(ray.m[0])));
  CHECK(std::abs(std::asin(std::abs(ray.m[0])) - deviation) < 1e-13);
  CHECK(std::abs(ray.x[0]) < 1e-15);
  // The image 50 mm behind moves by 50 tan(deviation) (the plate's own 2 mm shift is O(theta^2)).
  CHECK(std::abs(std::abs(ray.y[0]) - 50.0 * std::tan(deviation)) < 2.0 * 0.5 * theta * theta);
}

TEST_CASE("tolerance surface: a decentred surface shifts the image by the first-order amount") {
  // Decentring the back surface (power phi = (1 - n) c) by delta moves its axis to +delta: the
  // axial ray meets it at height -delta and leaves at slope phi delta (n' u' = n u - y phi), so
  // the image L behind it moves by L phi delta, up to the sphere's O((c delta)^2) terms.
  const double c_back = -1.0 / 100.0, image = 95.0;
  const Lens lens = singlet(1.0 / 100.0, c_back, image);
  const ToleranceModel model(lens, surface_options(0.01, 0.0));
  const int tsdy3 = parameter_index(model, "tsdy3");
  const int tsdx3 = parameter_index(model, "tsdx3");
  REQUIRE(tsdy3 >= 0);
  REQUIRE(tsdx3 >= 0);
  const double delta = 1e-3;
  const TraceLens<double> nominal =
      model.perturbed_trace_lens(std::vector<double>(model.parameters().size(), 0.0));
  const double n = nominal.index(1, static_cast<int>(nominal.wavelengths_nm.size()) - 1);
  const double expected = image * (1.0 - n) * c_back * delta;
  for (const int which : {tsdy3, tsdx3}) {
    std::vector<double> d(model.parameters().size(), 0.0);
    d[static_cast<std::size_t>(which)] = delta;
    const RayBundle<double> ray = axial_ray(model.perturbed_trace_lens(d));
    REQUIRE(ray.status[0] == kRayOk);
    const double moved = which == tsdy3 ? ray.y[0] : ray.x[0];
    const double across = which == tsdy3 ? ray.x[0] : ray.y[0];
    MESSAGE(fmt::format("{}: image moves {:.12e} mm, first order {:.12e} mm",
                        which == tsdy3 ? "tsdy3" : "tsdx3", moved, expected));
    CHECK(std::abs(moved - expected) < 1e-6 * std::abs(expected));
    CHECK(std::abs(across) < 1e-18);
  }
  // The spot changes are even in a decenter across the fields' meridian (x: the mirror x -> -x
  // takes +delta to -delta; the centroid-referenced RMS spot is the same).
  std::vector<double> d(model.parameters().size(), 0.0);
  const TrialResult n0 = model.evaluate(d);
  d[static_cast<std::size_t>(tsdx3)] = 0.01;
  const TrialResult plus = model.evaluate(d);
  d[static_cast<std::size_t>(tsdx3)] = -0.01;
  const TrialResult minus = model.evaluate(d);
  REQUIRE(plus.valid);
  REQUIRE(minus.valid);
  CHECK(plus.mean_spot_um > n0.mean_spot_um);
  CHECK(plus.mean_spot_um == doctest::Approx(minus.mean_spot_um).epsilon(1e-9));
}

TEST_CASE("tolerance surface: inverse sensitivity reproduces its drop when applied") {
  const Lens lens = singlet(1.0 / 100.0, -1.0 / 100.0, 95.0);
  ToleranceOptions o = surface_options(0.01, 1.0);
  const ToleranceModel model(lens, o);
  const std::vector<double> zero(model.parameters().size(), 0.0);
  const TrialResult nominal = model.evaluate(zero);
  REQUIRE(nominal.valid);
  const double drop = 0.5;  // um of mean RMS spot
  for (const char* name : {"tstx2", "tsdy3"}) {
    const int p = parameter_index(model, name);
    REQUIRE(p >= 0);
    const InverseSensitivity inv = inverse_sensitivity(model, p, drop, nominal.mean_spot_um);
    REQUIRE(inv.limit);
    std::vector<double> d = zero;
    double worst = 0.0;
    for (const double sign : {1.0, -1.0}) {
      d[static_cast<std::size_t>(p)] = sign * *inv.limit;
      const TrialResult r = model.evaluate(d);
      REQUIRE(r.valid);
      worst = std::max(worst, r.mean_spot_um - nominal.mean_spot_um);
    }
    MESSAGE(fmt::format("{}: inverse limit {:.6g} ({} evaluations), spot rise {:.9f} um", name,
                        *inv.limit, inv.evaluations, worst));
    CHECK(std::abs(worst - drop) <= 1e-4 * drop);
    CHECK(inv.spot_change_um == doctest::Approx(worst).epsilon(1e-12));
  }
  // In the report: every sensitivity row carries its inverse limit.
  o.trials = 4;
  o.inverse_drop_um = drop;
  const ToleranceReport report = run_tolerance(lens, o);
  REQUIRE(!report.sensitivity.empty());
  for (const SensitivityRow& row : report.sensitivity) {
    REQUIRE(row.inverse_limit);
    CHECK(std::abs(row.inverse_spot_um - drop) <= 1e-4 * drop);
  }
  CHECK(format_tolerance_text(report).find("inverse") != std::string::npos);
  CHECK(format_tolerance_json(report).find("\"inverse_limit\"") != std::string::npos);
}

TEST_CASE("tolerance surface: a tilted mirror turns the reflected axial ray by twice its tilt") {
  // A concave spherical mirror (R = -200 mm) 50 mm behind its stop, the image at its focus (the
  // thickness after a mirror is negative). Tilting it by theta about x through its vertex, where
  // the axial ray meets it, turns the reflected ray by 2 theta: the image plane 100 mm back sees
  // it at 100 tan(2 theta), exactly.
  Lens lens = singlet(0.0, 0.0, 0.0);
  Surface stop, mirror;
  stop.is_stop = true;
  stop.thickness_mm = 50.0;
  mirror.curvature_per_mm = -1.0 / 200.0;
  mirror.mirror = true;
  mirror.thickness_mm = -100.0;
  lens.surfaces = {stop, mirror};
  lens.specs.fields = {FieldPoint{0.0}, FieldPoint{0.5}};
  const ToleranceModel model(lens, surface_options(0.0, 20.0));
  const int tstx2 = parameter_index(model, "tstx2");
  REQUIRE(tstx2 >= 0);
  CHECK(model.parameters()[static_cast<std::size_t>(tstx2)].description ==
        "surface 2 mirror tilt about x");
  std::vector<double> d(model.parameters().size(), 0.0);
  const RayBundle<double> nominal = axial_ray(model.perturbed_trace_lens(d));
  REQUIRE(nominal.status[0] == kRayOk);
  CHECK(std::abs(nominal.y[0]) < 1e-15);
  d[static_cast<std::size_t>(tstx2)] = 20.0;  // arcmin
  const RayBundle<double> ray = axial_ray(model.perturbed_trace_lens(d));
  REQUIRE(ray.status[0] == kRayOk);
  const double theta = 20.0 / 60.0 * kPi / 180.0;
  MESSAGE(fmt::format("mirror tilted 20': image {:.15e} mm, 100 tan(2 theta) {:.15e} mm", ray.y[0],
                      100.0 * std::tan(2.0 * theta)));
  CHECK(std::abs(std::abs(ray.y[0]) - 100.0 * std::tan(2.0 * theta)) < 1e-12);
  CHECK(std::abs(ray.x[0]) < 1e-15);
  // And a trial with it evaluates (the sensitivity table's path).
  const TrialResult tilted = model.evaluate(d);
  REQUIRE(tilted.valid);
}

}  // namespace test_tolerance_surface
