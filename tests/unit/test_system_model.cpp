// The optical system model (issue 14): one lens-to-trace builder for every consumer, system data
// as OpticStudio has them (wavelengths with weights and a primary, field types and weights,
// apertures, finite objects, spec modes), clear apertures and vignetting factors.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>

#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/apertures.h"
#include "lensopt/analysis/field_maps.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_sampling.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/render/psf.h"
#include "lensopt/tolerance/tolerance.h"
#include "test_support.h"
#include "trace_checks.h"

namespace test_system_model {

using namespace lensopt;

namespace {

constexpr double kPiValue = 3.14159265358979323846;

Lens shipped(const char* name) {
  return read_lens(test::source_dir() / "lenses" / (std::string(name) + ".toml"));
}

// A .zmx text: a 50 mm achromat-like doublet with model glasses and the given system lines.
std::string doublet_zmx(const std::string& system_lines,
                        const std::string& object_disz = "INFINITY",
                        const std::string& front_diam = "") {
  return "VERS 190513 80 123457 L123457\nMODE SEQ\nNAME test doublet\nUNIT MM X W X CM MR CPMM\n" +
         system_lines + "SURF 0\n  TYPE STANDARD\n  CURV 0\n  DISZ " + object_disz +
         "\nSURF 1\n  TYPE STANDARD\n  CURV 0\n  DISZ 2\n  STOP\n  DIAM 6 1\n"
         "SURF 2\n  TYPE STANDARD\n  CURV 0.03\n  DISZ 5\n  GLAS ___BLANK 1 0 1.6 60 0 0 0 0 0 "
         "0\n" +
         front_diam +
         "SURF 3\n  TYPE STANDARD\n  CURV -0.035\n  DISZ 2\n  GLAS ___BLANK 1 0 1.7 30 0 0 0 0 0 "
         "0\n"
         "SURF 4\n  TYPE STANDARD\n  CURV -0.004\n  DISZ 45\n"
         "SURF 5\n  TYPE STANDARD\n  CURV 0\n  DISZ 0\n";
}

const char* kFdc = "WAVM 1 0.4861327 1\nWAVM 2 0.5875618 1\nWAVM 3 0.6562725 1\nPWAV 2\n";

using test::quick;

}  // namespace

TEST_CASE("system: the optimizer's merit is the analysis figure for a catalog-dispersion lens") {
  Lens lens = shipped("cooke");
  lens.specs.dispersion = DispersionModel::kCatalog;
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x = param.from_lens(lens);
  const Lens back = param.to_lens(x.data(), GlassMode::kQuantized);
  // The optimizer's traced lens and the builder's agree index for index (catalog correction).
  const TraceLens<double> opt = param.to_trace_lens(x.data(), GlassMode::kQuantized);
  const TraceLens<double> built = make_trace_lens(back);
  REQUIRE(opt.wavelengths_nm == built.wavelengths_nm);
  for (int k = 0; k < built.surface_count(); ++k)
    for (std::size_t w = 0; w < built.wavelengths_nm.size(); ++w)
      CHECK(opt.index(k, static_cast<int>(w)) ==
            doctest::Approx(built.index(k, static_cast<int>(w))).epsilon(1e-15));
  // The merit's spot term equals analyze's mean RMS spot at the same sampling.
  TraceOptions t = quick(6);
  DesignLoss<double> loss;
  REQUIRE(evaluate_design<double>(param, x.data(), GlassMode::kQuantized, {}, t,
                                  DesignLossOptions{}, nullptr, nullptr, &loss));
  AnalyzeOptions a;
  a.trace = t;
  const AnalysisReport report = analyze_lens(back, a);
  REQUIRE(report.mean_rms_spot_um);
  CHECK(loss.spot_mm * 1000.0 == doctest::Approx(*report.mean_rms_spot_um).epsilon(1e-9));
}

TEST_CASE("system: paraxial data use the real rays' index at the same wavelength") {
  Lens lens = shipped("tessar");
  lens.specs.dispersion = DispersionModel::kCatalog;
  const TraceLens<double> tl = make_trace_lens(lens);
  const double ref = tl.reference_nm();
  const double efl = paraxial_data(tl, ref).efl_mm;
  // A real ray at a tiny height: EFL = -y / (final direction slope), up to O(y^2).
  RayBundle<double> ray;
  ray.resize(1);
  const double y0 = 1e-5;
  ray.x[0] = 0;
  ray.y[0] = y0;
  ray.z[0] = 0;
  ray.l[0] = 0;
  ray.m[0] = 0;
  ray.n[0] = 1;
  trace_bundle(tl, static_cast<int>(tl.wavelengths_nm.size()) - 1, tl.surface_count(), false, ray,
               static_cast<RayRecord<double>*>(nullptr));
  REQUIRE(ray.status[0] == kRayOk);
  const double real_efl = -y0 * ray.n[0] / ray.m[0];
  CHECK(real_efl == doctest::Approx(efl).epsilon(1e-8));
}

TEST_CASE("system: a catalog-dispersion lens has no index at a wavelength it does not hold") {
  // The catalog corrections exist at the lens's own wavelengths only; the abbe model elsewhere
  // would be another dispersion model (5e-4 in EFL on a real file), so asking is an error.
  Lens lens = shipped("tessar");
  lens.specs.dispersion = DispersionModel::kCatalog;
  const TraceLens<double> catalog = make_trace_lens(lens);
  const double ref = catalog.reference_nm();
  CHECK_NOTHROW(paraxial_data(catalog, ref));
  CHECK_THROWS_AS(paraxial_data(catalog, std::nextafter(ref, 1e9)), std::logic_error);
  CHECK_THROWS_AS(catalog.index_at_nm(0, 550.0), std::logic_error);
  // The abbe model is a formula: any wavelength.
  lens.specs.dispersion = DispersionModel::kAbbe;
  const TraceLens<double> abbe = make_trace_lens(lens);
  REQUIRE(abbe.is_glass[0]);
  CHECK(abbe.index_at_nm(0, 550.0) == abbe_index(abbe.nd[0], abbe.vd[0], 550.0));
}

TEST_CASE("system: any wavelength count; channels by band, a single wavelength feeds R, G, B") {
  CHECK(default_wavelength_channels({486.1327, 587.5618, 656.2725}) == std::vector<int>{2, 1, 0});
  const auto one = channel_wavelengths({1}, {550.0});
  for (const auto& members : one) CHECK(members == std::vector<int>{0});
  const ZmxImport single =
      parse_zmx(doublet_zmx("ENPD 10\nFTYP 0 0 2 1 0 0 0\nXFLN 0 0\nYFLN 0 5\nWAVM 1 0.55 1\n"),
                "single.zmx");
  REQUIRE(single.lens.specs.wavelengths_nm.size() == 1);
  CHECK(single.lens.specs.primary_wavelength_nm == 550.0);
  const TraceSystem<double> sys = prepare_lens_system(single.lens, quick());
  const PsfSet<double> psfs =
      compute_psfs(sys, single.lens.specs.wavelength_channels, PsfOptions{}, 1);
  for (int k = 0; k < kColourChannels; ++k) CHECK(psfs.fields[0].traced_rays[k] > 0);
}

TEST_CASE("system: a lens whose only field is on axis traces (no infinite scale, no NaN)") {
  const ZmxImport imp = parse_zmx(
      doublet_zmx(std::string("ENPD 10\nFTYP 0 0 1 3 0 0 0\nXFLN 0\nYFLN 0\n") + kFdc), "axis.zmx");
  CHECK(imp.lens.specs.mode == SpecMode::kAsWritten);
  AnalyzeOptions a;
  a.trace = quick();
  const AnalysisReport r = analyze_lens(imp.lens, a);
  CHECK(std::isfinite(r.efl_mm));
  CHECK(r.scale == 1.0);
  CHECK(r.ray_failures == 0);
  REQUIRE(r.mean_rms_spot_um);
  CHECK(std::isfinite(*r.mean_rms_spot_um));
  const std::string json = format_report_json(r);
  CHECK(json.find("\"efl_mm\": null") == std::string::npos);
  CHECK(json.find("\"mean_rms_spot_um\": null") == std::string::npos);
  CHECK(json.find("\"relative_illumination\": [\n    null") == std::string::npos);
  // In the paper's mode the same lens is refused with a reason, not traced to NaN.
  Lens paper = imp.lens;
  paper.specs.mode = SpecMode::kPaper;
  CHECK_THROWS_AS(paper.validate(), Error);
}

TEST_CASE("system: field types, weights, apertures and finite objects from .zmx") {
  // Real image height: the solved chief ray lands on the written height.
  const ZmxImport real = parse_zmx(
      doublet_zmx(std::string("FNUM 5 0\nFTYP 3 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 4\nFWGN 1 2\n") +
                  kFdc),
      "real.zmx");
  CHECK(real.lens.specs.field_type == FieldType::kRealImageHeight);
  CHECK(real.lens.specs.fields[1].weight == 2.0);
  TraceOptions t = quick();
  t.ray_aiming = false;
  const TraceSystem<double> sys = prepare_lens_system(real.lens, t);
  REQUIRE(sys.fields_deg.size() == 2);
  RayBundle<double> chief;
  PupilSamples centre;
  centre.x = {0.0};
  centre.y = {0.0};
  start_rays(sys, 1, sys.wavelength_count, chief, &centre);
  trace_bundle(sys.lens, sys.wavelength_count, sys.lens.surface_count(), true, chief,
               static_cast<RayRecord<double>*>(nullptr));
  CHECK(chief.y[0] == doctest::Approx(4.0).epsilon(1e-10));
  CHECK(sys.epd_mm == doctest::Approx(sys.efl_mm / 5.0).epsilon(1e-14));
  // Paraxial image height: linear in tan(theta).
  const ZmxImport par = parse_zmx(
      doublet_zmx(std::string("ENPD 10\nFTYP 2 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 4\n") + kFdc),
      "par.zmx");
  const TraceSystem<double> ps = prepare_lens_system(par.lens, t);
  const double y_par =
      paraxial_image_height(ps.lens, ps.entrance_pupil_z_mm,
                            std::tan(ps.fields_deg[1] * kPiValue / 180.0), ps.lens.reference_nm());
  CHECK(y_par == doctest::Approx(4.0).epsilon(1e-12));
  CHECK(ps.epd_mm == 10.0);
  // Finite object, object height, object-space NA: the marginal ray from the axial object point
  // has sin U = NA; rays of a field start at its object point.
  const ZmxImport near = parse_zmx(
      doublet_zmx(std::string("OBNA 0.05\nFTYP 1 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 10\n") + kFdc,
                  "300"),
      "near.zmx");
  CHECK(near.lens.specs.object_distance_mm == 300.0);
  const TraceSystem<double> ns = prepare_lens_system(near.lens, t);
  const double u = std::atan((ns.epd_mm / 2) / (ns.entrance_pupil_z_mm + 300.0));
  CHECK(std::sin(u) == doctest::Approx(0.05).epsilon(1e-12));
  RayBundle<double> rays;
  start_rays(ns, 1, 0, rays);
  for (std::size_t i = 0; i < rays.size(); i += 97) {
    // Back along the ray to the object plane z = -300: height -10 (the chief ray goes up).
    const double s = (-300.0 - rays.z[i]) / rays.n[i];
    CHECK(rays.y[i] + s * rays.m[i] == doctest::Approx(-10.0).epsilon(1e-12));
    CHECK(std::abs(rays.x[i] + s * rays.l[i]) < 1e-12);
  }
  // Float by stop size: the stop's DIAM sets the pupil; the real marginal ray fills it.
  const ZmxImport floa =
      parse_zmx(doublet_zmx(std::string("FLOA\nFTYP 0 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 3\n") + kFdc),
                "floa.zmx");
  const TraceSystem<double> fs = prepare_lens_system(floa.lens, quick());
  CHECK(fs.stop_radius_mm == 6.0);
  CHECK(fs.epd_mm == doctest::Approx(12.0).epsilon(1e-14));  // stop in front: EP = stop
}

TEST_CASE("system: TOML and .zmx carry the system data exactly") {
  const ZmxImport imp =
      parse_zmx(doublet_zmx("ENPD 10\nFTYP 3 0 3 3 0 0 0\nXFLN 0 0 0\nYFLN 0 3 4\nFWGN 1 2 3\n"
                            "VDYN 0 0.05 0.1\nVCXN 0 0.1 0.2\nVCYN 0 0.1 0.3\n"
                            "WAVM 1 0.4861327 1\nWAVM 2 0.5875618 2\nWAVM 3 0.6562725 1\nPWAV 2\n",
                            "250", "  DIAM 7.5 1\n"),
                "sys.zmx");
  const Specs& s = imp.lens.specs;
  CHECK(s.wavelength_weights == std::vector<double>{1, 2, 1});
  CHECK(s.fields[2].vignetting.vcy == 0.3);
  CHECK(imp.lens.surfaces[1].semi_diameter_mm == 7.5);
  for (const Lens& back : {parse_zmx(format_zmx(imp.lens), "back.zmx").lens,
                           parse_lens_toml(format_lens_toml(imp.lens), "back.toml")}) {
    const Specs& b = back.specs;
    CHECK(b.mode == SpecMode::kAsWritten);
    CHECK(b.aperture_type == ApertureType::kEntrancePupilDiameter);
    CHECK(b.aperture_value == 10.0);
    CHECK(b.field_type == FieldType::kRealImageHeight);
    CHECK(b.object_distance_mm == 250.0);
    CHECK(b.primary_wavelength_nm == s.primary_wavelength_nm);
    CHECK(b.wavelength_weights == s.wavelength_weights);
    REQUIRE(b.fields.size() == 3);
    for (std::size_t i = 0; i < 3; ++i) {
      CHECK(b.fields[i].value == s.fields[i].value);
      CHECK(b.fields[i].weight == s.fields[i].weight);
      CHECK(b.fields[i].vignetting.vdy == s.fields[i].vignetting.vdy);
      CHECK(b.fields[i].vignetting.vcx == s.fields[i].vignetting.vcx);
      CHECK(b.fields[i].vignetting.vcy == s.fields[i].vignetting.vcy);
    }
    CHECK(back.surfaces[1].semi_diameter_mm == 7.5);
  }
}

TEST_CASE("system: vignetting factors move the pupil as OpticStudio defines them") {
  // px' = VDX + (1 - VCX) px, py' = VDY + (1 - VCY) py on the normalized pupil (VDX = 0 here).
  const ZmxImport imp =
      parse_zmx(doublet_zmx(std::string("ENPD 10\nFTYP 0 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 5\n"
                                        "VDYN 0 0.1\nVCXN 0 0.3\nVCYN 0 0.2\n") +
                            kFdc),
                "vig.zmx");
  TraceOptions t = quick();
  t.ray_aiming = false;  // the aimed map is the identity: the factors alone move the pupil
  const TraceSystem<double> sys = prepare_lens_system(imp.lens, t);
  RayBundle<double> rays;
  start_rays(sys, 1, 0, rays);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    CHECK(rays.x[i] == doctest::Approx(5.0 * 0.7 * sys.pupil.x[i]).epsilon(1e-14));
    CHECK(rays.y[i] == doctest::Approx(5.0 * (0.1 + 0.8 * sys.pupil.y[i])).epsilon(1e-14));
  }
  // On axis (factors 0) the pupil is untouched.
  start_rays(sys, 0, 0, rays);
  CHECK(rays.y[rays.size() - 1] == doctest::Approx(5.0 * sys.pupil.y[rays.size() - 1]));
}

TEST_CASE("system: a stop-sized front aperture vignettes as the clipped pupil area says") {
  // A front aperture of the stop's radius r, a distance L before the stop (nothing refracts
  // between them, so the pupil is the stop): a collimated field theta reaches the aperture
  // plane shifted by L tan(theta); the transmitted part is the overlap of two circles of radius
  // r at centre distance d, A = 2 r^2 acos(d / 2r) - (d / 2) sqrt(4 r^2 - d^2).
  const double r = 5.0, length = 20.0;
  Lens lens;
  lens.name = "front aperture";
  Surface front;
  front.thickness_mm = length;
  front.semi_diameter_mm = r;
  Surface stop;
  stop.is_stop = true;
  stop.thickness_mm = 2.0;
  Surface s1;
  s1.curvature_per_mm = 0.03;
  s1.thickness_mm = 5.0;
  s1.material = Material::model(1.6, 60.0);
  Surface s2;
  s2.curvature_per_mm = -0.01;
  s2.thickness_mm = 50.0;
  lens.surfaces = {front, stop, s1, s2};
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 2 * r;
  lens.specs.wavelengths_nm = {587.6};
  lens.specs.wavelength_channels = {1};
  lens.specs.half_field_deg = 12.0;
  for (double f : {0.0, 4.0, 8.0, 12.0}) lens.specs.fields.push_back({f, 1.0, {}});
  Lens open = lens;
  open.surfaces[0].semi_diameter_mm = 0.0;
  TraceOptions t = quick(48);
  const TraceSystem<double> clipped = prepare_lens_system(lens, t);
  const TraceSystem<double> free = prepare_lens_system(open, t);
  const std::vector<double> ri_clipped = relative_illuminations(clipped);
  const std::vector<double> ri_free = relative_illuminations(free);
  for (std::size_t h = 1; h < clipped.fields_deg.size(); ++h) {
    const double d = length * std::tan(clipped.fields_deg[h] * kPiValue / 180.0);
    const double area = 2 * r * r * std::acos(d / (2 * r)) - d / 2 * std::sqrt(4 * r * r - d * d);
    const double expected = area / (kPiValue * r * r);
    INFO("field ", clipped.fields_deg[h], " deg");
    CHECK(ri_clipped[h] / ri_free[h] == doctest::Approx(expected).epsilon(0.02));
    CHECK(ri_clipped[h] < ri_free[h]);
  }
  // Automatic semi-diameters (no aperture given): at the front surface the largest height is the
  // pupil edge shifted by L tan(theta_max), r + L tan(12 deg); at the stop it is r.
  const std::vector<double> automatic = automatic_semi_diameters(open);
  CHECK(automatic[0] ==
        doctest::Approx(r + length * std::tan(12.0 * kPiValue / 180.0)).epsilon(1e-12));
  CHECK(automatic[1] == doctest::Approx(r).epsilon(1e-12));
  // Written to .zmx as automatic DIAMs (flag 0), which read back as no aperture.
  const std::string zmx = format_zmx(open);
  CHECK(zmx.find(fmt::format("  DIAM {} 0\r\n", automatic[0])) != std::string::npos);
  CHECK(parse_zmx(zmx, "auto.zmx").lens.surfaces[0].semi_diameter_mm == 0.0);
  // Counted per field and surface in analyze, apart from failures.
  AnalyzeOptions a;
  a.trace = t;
  const AnalysisReport report = analyze_lens(lens, a);
  CHECK(report.ray_failures == 0);
  CHECK(report.fields[0].vignetted_rays == 0);
  CHECK(report.fields.back().vignetted_rays > 0);
  CHECK(report.vignetted_by_surface[0] == report.vignetted_rays);
  CHECK(report.fields[2].field_value == 8.0);
}

TEST_CASE("system: a real file's vignetting factors move the chief and marginal rays") {
  // rayoptics_US00583336-2-scaled.zmx (tests/data/zmx-real): fields 0, 17 and 24 deg with
  // VDYN, VCXN, VCYN from OpticStudio's Set Vignetting. OpticStudio's definition on the
  // normalized pupil: px' = VDX + (1 - VCX) px, py' = VDY + (1 - VCY) py. By hand, the chief
  // ray (0, 0) starts at (0, VDY), the upper and lower marginal rays (0, +-1) at
  // (0, VDY +- (1 - VCY)), the sagittal ray (1, 0) at (1 - VCX, VDY); lensopt then maps the
  // normalized point through the field's aimed pupil (x = R scale_x px', y = R (offset_y +
  // scale_y py'), R = EPD / 2).
  const ZmxImport imp = read_zmx(test::source_dir() / "tests" / "data" / "zmx-real" /
                                 "rayoptics_US00583336-2-scaled.zmx");
  const Specs& s = imp.lens.specs;
  REQUIRE(s.fields.size() == 3);
  // The file's values (line 22-24), read exactly.
  const double vdy[3] = {0, 6.208442661354E-2, 5.473246586901E-2};
  const double vcx[3] = {0, 2.455956935883E-3, 2.0477435112E-3};
  const double vcy[3] = {0, 1.556542586327E-1, 3.64762539196E-1};
  for (int h = 0; h < 3; ++h) {
    CHECK(s.fields[h].vignetting.vdx == 0.0);
    CHECK(s.fields[h].vignetting.vdy == vdy[h]);
    CHECK(s.fields[h].vignetting.vcx == vcx[h]);
    CHECK(s.fields[h].vignetting.vcy == vcy[h]);
    CHECK(s.fields[h].vignetting.van_deg == 0.0);
  }
  const TraceSystem<double> sys = prepare_lens_system(imp.lens, quick());
  Lens plain_lens = imp.lens;
  for (FieldPoint& f : plain_lens.specs.fields) f.vignetting = {};
  const TraceSystem<double> plain = prepare_lens_system(plain_lens, quick());
  REQUIRE(sys.fields_deg.size() == 3);
  const double efl = sys.efl_mm;
  const double r_ep = sys.epd_mm / 2;
  PupilSamples rays4;  // chief, upper marginal, lower marginal, sagittal
  rays4.x = {0.0, 0.0, 0.0, 1.0};
  rays4.y = {0.0, 1.0, -1.0, 0.0};
  const int w = static_cast<int>(s.wavelengths_nm.size()) - 1;
  double largest_shift = 0.0;
  for (int h = 0; h < 3; ++h) {
    CAPTURE(h);
    const PupilMap<double>& map = sys.pupil_map(h, w);
    // The same aimed map with and without the factors (aiming does not see them).
    CHECK(map.scale_y == plain.pupil_map(h, w).scale_y);
    PupilSamples hand;  // px', py' by hand
    for (std::size_t i = 0; i < 4; ++i) {
      hand.x.push_back((1.0 - vcx[h]) * rays4.x[i]);  // VDX = 0
      hand.y.push_back(vdy[h] + (1.0 - vcy[h]) * rays4.y[i]);
    }
    RayBundle<double> vignetted, by_hand, unvignetted;
    start_rays(sys, h, w, vignetted, &rays4);
    start_rays(plain, h, w, by_hand, &hand);
    start_rays(plain, h, w, unvignetted, &rays4);
    for (std::size_t i = 0; i < 4; ++i) {
      CAPTURE(i);
      CHECK(std::abs(vignetted.x[i] - r_ep * map.scale_x * hand.x[i]) <= 1e-13 * efl);
      CHECK(std::abs(vignetted.y[i] - r_ep * (map.offset_y + map.scale_y * hand.y[i])) <=
            1e-13 * efl);
    }
    for (RayBundle<double>* b : {&vignetted, &by_hand, &unvignetted})
      trace_bundle(sys.lens, w, sys.lens.surface_count(), true, *b,
                   static_cast<RayRecord<double>*>(nullptr));
    for (std::size_t i = 0; i < 4; ++i) {
      CAPTURE(i);
      REQUIRE(vignetted.status[i] == kRayOk);
      REQUIRE(by_hand.status[i] == kRayOk);
      // At the image: the vignetted rays are the rays started from the hand-computed points.
      CHECK(std::abs(vignetted.x[i] - by_hand.x[i]) <= 1e-12 * efl);
      CHECK(std::abs(vignetted.y[i] - by_hand.y[i]) <= 1e-12 * efl);
      if (unvignetted.status[i] == kRayOk)
        largest_shift = std::max(largest_shift, std::abs(vignetted.y[i] - unvignetted.y[i]));
    }
  }
  // The factors matter: a marginal ray lands elsewhere by a sizeable part of the focal length.
  MESSAGE("largest image shift from the factors: ", largest_shift / efl, " of the EFL");
  CHECK(largest_shift > 1e-3 * efl);
}

TEST_CASE("system: VDX and VAN are kept in TOML and .zmx; fields on -y and on x turn the factors") {
  // A field on -y mirrors y (VDY -> -VDY); a field on +x turns the pupil a quarter turn
  // (VDY' = VDX, VDX' = -VDY, VCX and VCY swap), on -x the other way.
  const ZmxImport imp = parse_zmx(
      doublet_zmx(std::string("ENPD 10\nFTYP 0 0 4 3 0 0 0\nXFLN 0 0 3 -3\nYFLN 0 -3 0 0\n"
                              "VDXN 0.01 0.02 0.03 0.04\nVDYN 0.05 0.06 0.07 0.08\n"
                              "VCXN 0.1 0.2 0.3 0.4\nVCYN 0.5 0.6 0.7 0.8\nVANN 1 0 0 0\n") +
                  kFdc),
      "turn.zmx");
  const std::vector<FieldPoint>& f = imp.lens.specs.fields;
  REQUIRE(f.size() == 4);
  CHECK(f[0].vignetting.vdx == 0.01);
  CHECK(f[0].vignetting.vdy == 0.05);
  CHECK(f[0].vignetting.van_deg == 1.0);
  CHECK(f[1].vignetting.vdy == -0.06);  // -y
  CHECK(f[1].vignetting.vdx == 0.02);
  CHECK(f[1].vignetting.vcy == 0.6);
  CHECK(f[2].vignetting.vdy == 0.03);  // +x
  CHECK(f[2].vignetting.vdx == -0.07);
  CHECK(f[2].vignetting.vcy == 0.3);
  CHECK(f[2].vignetting.vcx == 0.7);
  CHECK(f[3].vignetting.vdy == -0.04);  // -x
  CHECK(f[3].vignetting.vdx == 0.08);
  CHECK(f[3].vignetting.vcy == 0.4);
  CHECK(f[3].vignetting.vcx == 0.8);
  // VDX and VAN are traced (test_trace_vignetting.cpp): the reader does not warn about them.
  for (const std::string& w : imp.warnings) {
    CHECK(w.find("VDXN") == std::string::npos);
    CHECK(w.find("VANN") == std::string::npos);
  }
  for (const Lens& back : {parse_zmx(format_zmx(imp.lens), "back.zmx").lens,
                           parse_lens_toml(format_lens_toml(imp.lens), "back.toml")}) {
    REQUIRE(back.specs.fields.size() == 4);
    for (std::size_t i = 0; i < 4; ++i) {
      CAPTURE(i);
      const VignettingFactors& a = back.specs.fields[i].vignetting;
      const VignettingFactors& b = f[i].vignetting;
      CHECK(a.vdx == b.vdx);
      CHECK(a.vdy == b.vdy);
      CHECK(a.vcx == b.vcx);
      CHECK(a.vcy == b.vcy);
      CHECK(a.van_deg == b.van_deg);
    }
  }
}

TEST_CASE("system: optimize and tolerance sample an as-written lens at its fields and weights") {
  // A .zmx lens (as written): the design loss's spot fields are the file's 0, 14 and 20 deg with
  // their weights, its wavelength weights kept; the constraint fields spread 0..20 (21, which
  // hold 0, 14 and 20). The paper's Cooke keeps the paper's sampling: 11 of 21 angles 0..hfov.
  Lens lens = read_zmx(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx").lens;
  REQUIRE(lens.specs.fields.size() == 3);
  lens.specs.fields[1].weight = 2.0;
  lens.specs.wavelength_weights = {1.0, 3.0, 0.5};
  TraceOptions sampling;
  sampling.rings = 3;
  sampling.fields = 11;
  const DesignSampling d = design_sampling(lens, sampling);
  CHECK(d.spot_fields == 3);
  CHECK(d.setup.field_values.size() == 21);
  std::vector<double> values, weights;
  for (std::size_t hf = 0; hf < d.spot_field.size(); ++hf) {
    if (d.spot_field[hf] < 0) continue;
    CHECK(d.spot_field[hf] == static_cast<int>(values.size()));
    values.push_back(d.setup.field_values[hf]);
    weights.push_back(d.setup.field_weights[hf]);
  }
  CHECK(values == std::vector<double>{0.0, 14.0, 20.0});
  CHECK(weights == std::vector<double>{1.0, 2.0, 1.0});
  CHECK(d.setup.wavelength_weights == std::vector<double>{1.0, 3.0, 0.5});
  CHECK(d.setup.aperture_type == ApertureType::kEntrancePupilDiameter);
  CHECK(describe_design_sampling(lens, sampling).find("(as written)") != std::string::npos);
  const Lens cooke = shipped("cooke");
  const DesignSampling p = design_sampling(cooke, sampling);
  CHECK(p.spot_fields == 11);
  CHECK(p.setup.field_values.size() == 21);
  std::vector<double> paper_values;
  for (std::size_t hf = 0; hf < p.spot_field.size(); ++hf)
    if (p.spot_field[hf] >= 0) paper_values.push_back(p.setup.field_values[hf]);
  CHECK(paper_values == field_angles_deg(cooke.specs.half_field_deg, 11));
  // tolerance: the file's fields, not 5 angles 0..hfov.
  ToleranceOptions t;
  t.rings = 3;
  t.fields = 5;
  const ToleranceModel model(lens, t);
  CHECK(model.fields_deg() == std::vector<double>{0.0, 14.0, 20.0});
  const ToleranceModel paper_model(cooke, t);
  CHECK(paper_model.fields_deg() == field_angles_deg(cooke.specs.half_field_deg, 5));
}

TEST_CASE("apertures: crossing surfaces are found at the vertex and inside the clear aperture") {
  const Lens doublet = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  CHECK(crossing_surfaces(doublet).empty());
  // The stop moved 4 mm before the front vertex (a negative air thickness next to a dummy): a
  // virtual plane, not a crossing.
  Lens front_stop = doublet;
  front_stop.surfaces[1].thickness_mm = -5.6;
  CHECK(crossing_surfaces(front_stop).empty());
  // The second element's front vertex 2.4 mm before the first element's rear vertex (the stop's
  // thickness -8 mm): surfaces 2 and 4 cross on the axis, g(0) = t_2 + t_3 = 5.6015 - 8.
  Lens through = doublet;
  through.surfaces[2].thickness_mm = -8.0;
  const std::vector<SurfaceCrossing> axis = crossing_surfaces(through);
  REQUIRE(axis.size() == 1);
  CHECK(axis[0].first == 1);
  CHECK(axis[0].second == 3);
  CHECK(axis[0].height_mm == 0.0);
  CHECK(axis[0].gap_mm == doctest::Approx(doublet.surfaces[1].thickness_mm - 8.0).epsilon(1e-12));
  // A glass whose edge thickness is negative inside the given semi-diameter: a biconvex element
  // R = +-10 mm, 0.5 mm thick at the centre, semi-diameter 4 mm: g(4) = 0.5 - 2 (10 - sqrt(84)).
  Lens thin = doublet;
  thin.surfaces[0].curvature_per_mm = 0.1;
  thin.surfaces[1].curvature_per_mm = -0.1;
  thin.surfaces[0].thickness_mm = 0.5;
  thin.surfaces[0].semi_diameter_mm = 4.0;
  thin.surfaces[1].semi_diameter_mm = 4.0;
  const std::vector<SurfaceCrossing> rim = crossing_surfaces(thin);
  REQUIRE(!rim.empty());
  CHECK(rim[0].first == 0);
  CHECK(rim[0].second == 1);
  CHECK(rim[0].height_mm > 0.0);
  CHECK(rim[0].height_mm <= 4.0);
  const double r = rim[0].height_mm;
  CHECK(rim[0].gap_mm ==
        doctest::Approx(0.5 - 2.0 * (10.0 - std::sqrt(100.0 - r * r))).epsilon(1e-12));
}

}  // namespace test_system_model
