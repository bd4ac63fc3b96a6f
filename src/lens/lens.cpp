#include "lensopt/lens/lens.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/glass/glass_range.h"
#include "lensopt/lens/input_limits.h"
#include "lensopt/lens/profile_sag.h"
#include "lensopt/lens/validate.h"

namespace lensopt {

Material Material::model(double nd, double vd) {
  Material m;
  m.kind = Kind::kModel;
  m.nd = nd;
  m.vd = vd;
  return m;
}

Material Material::zemax_model(double nd, double vd, double dpgf) {
  Material m = model(nd, vd);
  m.model_glass = ModelGlass::kZemax;
  m.dpgf = dpgf;
  return m;
}

Material Material::from_catalog(const Glass& glass) {
  Material m;
  m.kind = Kind::kCatalog;
  m.glass_name = glass.name;
  m.nd = glass.nd;
  m.vd = glass.vd;
  if (!(glass.nd > 1.0) || !(glass.vd > 0.0)) {
    // An infrared material: no d line in its range, so no nd or vd. The paper's model gets the
    // index at the middle of the range (geometric mean of its ends) and the flattest dispersion
    // lensopt accepts (vd = kMaxAbbe); the catalog model (a .zmx import's default) adds the
    // correction to the formula's own index at every traced wavelength.
    const double middle_um = std::sqrt(glass.min_wavelength_um * glass.max_wavelength_um);
    const double n = glass.index(middle_um * 1000.0);
    if (std::isfinite(n) && n > 1.0) {
      m.nd = n;
      m.vd = kMaxAbbe;
    }
  }
  m.glass = std::make_shared<Glass>(glass);
  return m;
}

std::string Material::label() const {
  switch (kind) {
    case Kind::kAir:
      return "air";
    case Kind::kCatalog:
      return glass_name;
    case Kind::kModel:
      return fmt::format("model({:.5f}, {:.2f})", nd, vd);
  }
  return "?";
}

std::vector<int> default_wavelength_channels(const std::vector<double>& wavelengths_nm) {
  std::vector<int> out;
  for (const double nm : wavelengths_nm) out.push_back(nm < 500.0 ? 2 : (nm < 600.0 ? 1 : 0));
  return out;
}

double Specs::max_field_value() const {
  if (fields.empty()) return half_field_deg;
  double out = 0.0;
  for (const FieldPoint& f : fields) out = std::max(out, f.radius());
  return out;
}

const std::vector<double>& paper_wavelengths_nm() {
  // Supplement, table "Selected wavelengths": R, G, B, five each (odd 10-quantiles of the
  // Sony IMX172 quantum efficiency per channel).
  static const std::vector<double> wavelengths = {584.1, 604.2, 622.5, 642.2, 665.9,
                                                  487.1, 512.1, 535.1, 560.8, 596.3,
                                                  409.4, 435.4, 456.6, 477.9, 505.9};
  return wavelengths;
}

const std::vector<int>& paper_wavelength_channels() {
  static const std::vector<int> channels = {0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 2, 2, 2, 2, 2};
  return channels;
}

Specs::Specs()
    : wavelengths_nm(paper_wavelengths_nm()), wavelength_channels(paper_wavelength_channels()) {}

double Specs::focal_length_mm() const {
  return sensor_diagonal_mm / (2.0 * std::tan(half_field_deg * kPi / 180.0));
}

int Lens::stop_index() const {
  for (std::size_t i = 0; i < surfaces.size(); ++i) {
    if (surfaces[i].is_stop) return static_cast<int>(i);
  }
  return -1;
}

int Lens::element_count() const {
  // Each glass medium between two surfaces is one element (a cemented pair counts two).
  int count = 0;
  for (const Surface& s : surfaces) count += s.material.is_air() ? 0 : 1;
  return count;
}

double Lens::track_length_mm() const {
  double sum = 0;
  for (std::size_t i = 0; i + 1 < surfaces.size(); ++i) sum += surfaces[i].thickness_mm;
  return sum;
}

double Lens::total_track_mm() const {
  double sum = 0;
  for (const Surface& s : surfaces) sum += s.thickness_mm;
  return sum;
}

void Lens::validate() const {
  validate_lens(*this);
}

void validate_lens(const Lens& lens, const LensSourceLines& lines) {
  const std::vector<Surface>& surfaces = lens.surfaces;
  const Specs& specs = lens.specs;
  const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
  auto fail_at = [&](int line, const std::string& message) {
    throw Error(SourceLocation{where, line}, message);
  };
  auto fail = [&](const std::string& message) { fail_at(0, message); };
  auto surface_line = [&](std::size_t i) {
    return i < lines.surfaces.size() ? lines.surfaces[i] : 0;
  };
  if (surfaces.size() < 2) fail("a lens needs at least two surfaces");
  if (surfaces.size() > kMaxSurfaces)
    fail_at(surface_line(kMaxSurfaces),
            fmt::format("the lens has {} surfaces; lensopt reads at most {}", surfaces.size(),
                        kMaxSurfaces));
  if (specs.wavelengths_nm.size() > kMaxWavelengths)
    fail(fmt::format("{} wavelengths; lensopt reads at most {}", specs.wavelengths_nm.size(),
                     kMaxWavelengths));
  if (specs.fields.size() > kMaxFields)
    fail(fmt::format("{} fields; lensopt reads at most {}", specs.fields.size(), kMaxFields));
  // The lens's own length scale: the bounds on radii and thicknesses are relative to it, so a
  // prescription normalized to f = 1 and one in mm are judged alike.
  double length = 0;
  for (std::size_t i = 0; i + 1 < surfaces.size(); ++i)
    length += std::abs(surfaces[i].thickness_mm);
  if (!(length > 0) || !std::isfinite(length)) {
    length = 0;
    for (const Surface& s : surfaces)
      if (s.curvature_per_mm != 0 && std::isfinite(s.curvature_per_mm))
        length = std::max(length, std::abs(1.0 / s.curvature_per_mm));
  }
  // Pickups and solves (lens.h): a source before the surface, a flat stop stays flat, a
  // nonzero marginal height only on the last thickness (paraxial/solves.h), one rule per value.
  for (std::size_t i = 0; i < surfaces.size(); ++i) {
    const Surface& s = surfaces[i];
    const int n = static_cast<int>(i) + 1;
    const int line = surface_line(i);
    for (const auto& [p, what] : {std::pair{&s.curvature_pickup, "curvature"},
                                  std::pair{&s.thickness_pickup, "thickness"}}) {
      if (!p->active()) continue;
      if (p->source >= static_cast<int>(i))
        fail_at(line, fmt::format("surface {}: the {} pickup's source is surface {}; a pickup "
                                  "takes its value from an earlier surface",
                                  n, what, p->source + 1));
      if (!std::isfinite(p->scale) || !std::isfinite(p->offset_mm))
        fail_at(line, fmt::format("surface {}: the {} pickup's scale and offset must be finite", n,
                                  what));
    }
    if (s.curvature_pickup.active() && (s.is_stop || s.coordinate_break))
      fail_at(line, fmt::format("surface {}: a {} has no curvature to pick up", n,
                                s.is_stop ? "stop (flat)" : "coordinate break"));
    if (s.thickness_pickup.active() && s.thickness_solve.active())
      fail_at(line, fmt::format("surface {}: the thickness has both a pickup and a solve", n));
    if (s.thickness_solve.active()) {
      if (!std::isfinite(s.thickness_solve.height_mm))
        fail_at(line, fmt::format("surface {}: the marginal-ray height must be finite", n));
      if (s.thickness_solve.height_mm != 0.0 && i + 1 != surfaces.size())
        fail_at(line, fmt::format("surface {}: a marginal-ray-height solve with a nonzero height "
                                  "({:g} mm) is supported on the last thickness only (its "
                                  "marginal ray scales with the pupil, which a thickness before "
                                  "it can change)",
                                  n, s.thickness_solve.height_mm));
    }
    if (s.vary.radius && (s.is_stop || s.coordinate_break))
      fail_at(line, fmt::format("surface {}: vary \"radius\" on a {}", n,
                                s.is_stop ? "stop (it stays flat)" : "coordinate break"));
  }
  int stops = 0;
  bool reflected = false;  // an odd number of mirrors so far: thicknesses run backwards
  for (std::size_t i = 0; i < surfaces.size(); ++i) {
    const Surface& s = surfaces[i];
    const int n = static_cast<int>(i) + 1;
    const int line = surface_line(i);
    {
      const Placement& p = s.placement;
      for (double v : {p.decenter_x_mm, p.decenter_y_mm, p.tilt_x_deg, p.tilt_y_deg, p.tilt_z_deg,
                       s.obscuration_mm, s.aperture_decenter_x_mm, s.aperture_decenter_y_mm})
        if (!std::isfinite(v))
          fail_at(line,
                  fmt::format("surface {}: a decenter, tilt or obscuration is not finite", n));
      for (double t : {p.tilt_x_deg, p.tilt_y_deg, p.tilt_z_deg})
        if (std::abs(t) > 360.0)
          fail_at(line, fmt::format("surface {}: tilt {:g} deg is outside [-360, 360]", n, t));
      if (s.obscuration_mm < 0.0)
        fail_at(line, fmt::format("surface {}: obscuration radius {:g} mm must be >= 0", n,
                                  s.obscuration_mm));
      if (s.coordinate_break) {
        if (s.curvature_per_mm != 0.0 || !s.is_spherical() || s.mirror || s.is_stop ||
            s.semi_diameter_mm > 0.0 || s.obscuration_mm > 0.0)
          fail_at(line, fmt::format("surface {}: a coordinate break is a dummy surface: no "
                                    "curvature, profile, mirror, stop or aperture",
                                    n));
        if (s.restore_frame)
          fail_at(line, fmt::format("surface {}: a coordinate break moves the frame of what "
                                    "follows; restore_frame is for a tilted or decentred surface",
                                    n));
      }
      const Material& before = i > 0 ? surfaces[i - 1].material : Material::air();
      if ((s.mirror || s.coordinate_break) &&
          (s.material.kind != before.kind || s.material.glass_name != before.glass_name ||
           s.material.nd != before.nd || s.material.vd != before.vd))
        fail_at(line, fmt::format("surface {}: the medium after a {} is the one before it ({}), "
                                  "not {}",
                                  n, s.mirror ? "mirror" : "coordinate break", before.label(),
                                  s.material.label()));
      if (s.mirror) reflected = !reflected;
    }
    if (!std::isfinite(s.curvature_per_mm))
      fail_at(line, fmt::format("surface {}: curvature is not finite (radius too small)", n));
    if (!std::isfinite(s.thickness_mm))
      fail_at(line, fmt::format("surface {}: thickness is not finite", n));
    if (!std::isfinite(s.conic))
      fail_at(line, fmt::format("surface {}: conic constant is not finite", n));
    if (!std::isfinite(s.asphere_r2_per_mm))
      fail_at(line, fmt::format("surface {}: asphere r^2 term is not finite", n));
    for (std::size_t j = 0; j < s.asphere.size(); ++j)
      if (!std::isfinite(s.asphere[j]))
        fail_at(line, fmt::format("surface {}: asphere a{} is not finite", n, 2 * j + 4));
    if (length > 0 && s.curvature_per_mm != 0 &&
        std::abs(1.0 / s.curvature_per_mm) < kMinRadiusOfLength * length)
      fail_at(line, fmt::format("surface {}: radius {:g} mm is below {:g} of the lens length "
                                "{:g} mm; no real lens has such a surface",
                                n, 1.0 / s.curvature_per_mm, kMinRadiusOfLength, length));
    if (length > 0 && std::abs(s.thickness_mm) > kMaxThicknessOfLength * length)
      fail_at(line, fmt::format("surface {}: thickness {:g} mm is more than {:g} times the lens "
                                "length {:g} mm",
                                n, s.thickness_mm, kMaxThicknessOfLength, length));
    if (s.is_stop) {
      ++stops;
      if (s.curvature_per_mm != 0.0 || !s.is_spherical())
        fail_at(line, fmt::format("surface {}: the stop must be flat", n));
    }
    if (!s.material.is_air()) {
      if (!(s.material.nd > 1.0 && s.material.nd <= kMaxIndex))
        fail_at(line, fmt::format("surface {}: glass {} has nd = {} (must be in (1, {:g}])", n,
                                  s.material.label(), s.material.nd, kMaxIndex));
      if (!(s.material.vd >= kMinAbbe && s.material.vd <= kMaxAbbe))
        fail_at(line, fmt::format("surface {}: glass {} has vd = {} (must be in [{:g}, {:g}])", n,
                                  s.material.label(), s.material.vd, kMinAbbe, kMaxAbbe));
      if (i + 1 < surfaces.size() && !((reflected ? -s.thickness_mm : s.thickness_mm) >= 0))
        fail_at(line, fmt::format("surface {}: a glass thickness of {:g} mm must be {} 0", n,
                                  s.thickness_mm, reflected ? "<= (after a mirror)" : ">="));
    }
  }
  if (!(length > 0)) fail("the lens has no length: every thickness is 0 and every surface flat");
  if (stops == 0) fail("no surface is marked as the aperture stop");
  if (stops > 1)
    fail(fmt::format("{} surfaces are marked as the aperture stop; one must be", stops));
  if (!surfaces.back().material.is_air()) fail("the last surface must be followed by air");
  // A requested F-number (the paper's mode) is bounded by physics, a lens's own one only by
  // sanity (validate.h).
  const bool paper = specs.mode == SpecMode::kPaper;
  const double min_f_number = paper ? kMinFNumber : kMinParaxialFNumber;
  if (!(specs.f_number >= min_f_number && specs.f_number <= kMaxFNumber))
    fail_at(lines.f_number,
            fmt::format("f_number = {} must be in [{:g}, {:g}]{}", specs.f_number, min_f_number,
                        kMaxFNumber,
                        paper ? " (the paper's spec mode: F/0.5 is an image-space NA of 1 in air)"
                              : " (the paraxial EFL / EPD of a lens as written)"));
  // The paper's spec mode derives the focal length from the field; a lens traced as written
  // (its own fields, possibly one on axis) needs neither.
  if (specs.mode == SpecMode::kPaper) {
    if (!(specs.half_field_deg >= kMinHalfFieldDeg && specs.half_field_deg < 89.0))
      fail_at(lines.half_field_deg,
              fmt::format("half_field_deg = {} must be in [{:g}, 89): a lens needs a field of view "
                          "(it sets the focal length f = d / (2 tan hfov))",
                          specs.half_field_deg, kMinHalfFieldDeg));
    if (!(specs.sensor_diagonal_mm >= kMinSensorDiagonalMm &&
          specs.sensor_diagonal_mm <= kMaxSensorDiagonalMm))
      fail_at(lines.sensor_diagonal_mm,
              fmt::format("sensor_diagonal_mm = {} must be in [{:g}, {:g}]",
                          specs.sensor_diagonal_mm, kMinSensorDiagonalMm, kMaxSensorDiagonalMm));
    const double f = specs.focal_length_mm();
    if (!(f >= kMinFocalLengthMm && f <= kMaxFocalLengthMm))
      fail_at(lines.sensor_diagonal_mm,
              fmt::format("the focal length from sensor_diagonal_mm and half_field_deg, {:g} mm, "
                          "must be in [{:g}, {:g}] mm",
                          f, kMinFocalLengthMm, kMaxFocalLengthMm));
  }
  if (specs.afocal) {
    // An afocal lens has no focal length: nothing of it may derive from one (analysis/afocal.h).
    if (specs.mode == SpecMode::kPaper)
      fail(
          "afocal = true needs a lens traced as written ([system] mode = \"as-written\"): the "
          "paper's spec mode scales the lens to a focal length, which an afocal lens lacks");
    if (specs.aperture_type == ApertureType::kFNumber)
      fail(
          "an afocal lens has no F-number (no focal length): give its aperture as \"epd\", "
          "\"object-na\" or \"float-by-stop\"");
    if (specs.field_type == FieldType::kParaxialImageHeight ||
        specs.field_type == FieldType::kRealImageHeight)
      fail(
          "an afocal lens has no image height (its image is at infinity): give its fields by "
          "angle or object height");
  }
  if (specs.wavelengths_nm.empty()) fail("no wavelengths");
  for (double w : specs.wavelengths_nm)
    if (!(w > 200.0 && w < 20000.0)) fail(fmt::format("wavelength {} nm is out of range", w));
  if (specs.wavelength_channels.size() != specs.wavelengths_nm.size())
    fail("wavelength channels and wavelengths differ in count");
  if (!specs.wavelength_weights.empty()) {
    if (specs.wavelength_weights.size() != specs.wavelengths_nm.size())
      fail("wavelength weights and wavelengths differ in count");
    for (double w : specs.wavelength_weights)
      if (!(w >= 0.0) || !std::isfinite(w))
        fail(fmt::format("wavelength weight {} must be >= 0", w));
    if (std::all_of(specs.wavelength_weights.begin(), specs.wavelength_weights.end(),
                    [](double w) { return w == 0.0; }))
      fail("every wavelength weight is 0: no wavelength would count");
  }
  if (!(specs.primary_wavelength_nm > 200.0 && specs.primary_wavelength_nm < 20000.0))
    fail(fmt::format("primary wavelength {} nm is out of range", specs.primary_wavelength_nm));
  for (const FieldPoint& f : specs.fields) {
    if (!std::isfinite(f.value) || !std::isfinite(f.x)) fail("a field value is not finite");
    if (specs.field_type == FieldType::kAngle && !(f.radius() < 89.0))
      fail(fmt::format("field ({:g}, {:g}) deg is {:g} deg off axis; it must be below 89", f.x,
                       f.value, f.radius()));
    if (!(f.weight >= 0.0) || !std::isfinite(f.weight))
      fail(fmt::format("field weight {} must be >= 0", f.weight));
    const VignettingFactors& v = f.vignetting;
    if (!std::isfinite(v.vdx) || !std::isfinite(v.vdy) || !(v.vcx < 1.0) || !(v.vcy < 1.0) ||
        !std::isfinite(v.vcx) || !std::isfinite(v.vcy) || !std::isfinite(v.van_deg))
      fail("vignetting factors must be finite with VCX, VCY < 1");
  }
  if (!specs.fields.empty() && std::all_of(specs.fields.begin(), specs.fields.end(),
                                           [](const FieldPoint& f) { return f.weight == 0.0; }))
    fail("every field weight is 0: no field would count");
  if (!specs.object_at_infinity() && !(specs.object_distance_mm > 0.0))
    fail(fmt::format("object distance {} mm must be > 0 (or infinite)", specs.object_distance_mm));
  if (specs.field_type == FieldType::kObjectHeight && specs.object_at_infinity())
    fail("object-height fields need a finite object distance");
  if (specs.aperture_type == ApertureType::kObjectNA && specs.object_at_infinity())
    fail("an object-space NA aperture needs a finite object distance");
  if ((specs.aperture_type == ApertureType::kEntrancePupilDiameter ||
       specs.aperture_type == ApertureType::kObjectNA) &&
      !(specs.aperture_value > 0.0 && std::isfinite(specs.aperture_value)))
    fail(fmt::format("aperture value {} must be > 0", specs.aperture_value));
  if (specs.aperture_type == ApertureType::kObjectNA && !(specs.aperture_value < 1.0))
    fail(fmt::format("object-space NA {} must be < 1", specs.aperture_value));
  if (specs.aperture_type == ApertureType::kFloatByStop) {
    const int s = lens.stop_index();
    if (s < 0 || !(surfaces[s].semi_diameter_mm > 0.0))
      fail("aperture 'float by stop size' needs the stop's semi-diameter");
  }
  if (specs.mode == SpecMode::kPaper && !(specs.half_field_deg > 0.0))
    fail(
        "the paper's spec mode scales to f = d / (2 tan(hfov)) and needs half_field_deg > 0; "
        "trace the lens as written (mode = \"as-written\") for an on-axis-only lens");
}

bool Surface::has_asphere() const {
  if (asphere_r2_per_mm != 0.0) return true;
  for (double a : asphere)
    if (a != 0.0) return true;
  return false;
}

double Surface::sag_mm(double r_mm) const {
  const double rho = r_mm * r_mm;
  const double c = curvature_per_mm;
  const double q2 = profile_q2(c, 1.0 + conic, rho);
  // Outside the conic's domain the profile does not exist: NaN (lens.h).
  if (q2 < 0.0) return std::numeric_limits<double>::quiet_NaN();
  const double a[kAsphereOrders + 1] = {asphere_r2_per_mm, asphere[0], asphere[1], asphere[2],
                                        asphere[3],        asphere[4], asphere[5], asphere[6]};
  return profile_sag_at_q(c, a, rho, std::sqrt(q2));
}

std::vector<std::string> glass_range_warnings(const Lens& lens) {
  std::vector<std::string> out;
  std::vector<std::string> seen;
  for (std::size_t i = 0; i < lens.surfaces.size(); ++i) {
    const Material& m = lens.surfaces[i].material;
    if (m.kind != Material::Kind::kCatalog || !m.glass) continue;
    if (std::find(seen.begin(), seen.end(), m.glass->name) != seen.end()) continue;
    seen.push_back(m.glass->name);
    std::vector<std::string> outside;
    // Every traced wavelength: the system's and the primary one.
    std::vector<double> traced = lens.specs.wavelengths_nm;
    if (std::find(traced.begin(), traced.end(), lens.specs.primary_wavelength_nm) == traced.end())
      traced.push_back(lens.specs.primary_wavelength_nm);
    for (double w : traced)
      if (!glass_in_range(*m.glass, w)) outside.push_back(fmt::format("{:g}", w));
    if (outside.empty()) continue;
    std::vector<std::string> surfaces;
    for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
      const Material& mk = lens.surfaces[k].material;
      if (mk.kind == Material::Kind::kCatalog && mk.glass && mk.glass->name == m.glass->name)
        surfaces.push_back(std::to_string(k + 1));
    }
    std::string list, where;
    for (const std::string& w : outside) list += (list.empty() ? "" : ", ") + w;
    for (const std::string& s : surfaces) where += (where.empty() ? "" : ", ") + s;
    const std::string file = lens.source_path.empty() ? lens.name : lens.source_path;
    out.push_back(fmt::format(
        "{}{}glass {} (catalog {}, surface {}): {} nm outside its formula's range {:g}-{:g} nm "
        "(AGF LD line); its index there is extrapolated",
        file, file.empty() ? "" : ": ", m.glass->name, m.glass->catalog, where, list,
        m.glass->min_wavelength_um * 1000.0, m.glass->max_wavelength_um * 1000.0));
  }
  return out;
}

std::vector<std::string> f_number_warnings(const Lens& lens) {
  const Specs& specs = lens.specs;
  if (specs.mode == SpecMode::kPaper || !(specs.f_number < kMinFNumber)) return {};
  const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
  return {fmt::format(
      "{}: paraxial F-number EFL / EPD = {:.5g} is below {:g}, the smallest real working "
      "F-number in air (image-space NA 1): the full aperture cannot be imaged sharply (the sine "
      "condition fails), and rays that miss a surface are counted as failed",
      where, specs.f_number, kMinFNumber)};
}

Lens scaled(const Lens& lens, double scale) {
  Lens out = lens;
  for (Surface& s : out.surfaces) {
    s.curvature_per_mm /= scale;
    s.thickness_mm *= scale;
    s.semi_diameter_mm *= scale;
    s.obscuration_mm *= scale;
    s.aperture_decenter_x_mm *= scale;
    s.aperture_decenter_y_mm *= scale;
    s.placement.decenter_x_mm *= scale;  // tilts are angles
    s.placement.decenter_y_mm *= scale;
    s.thickness_pickup.offset_mm *= scale;  // pickup scales are ratios
    s.thickness_solve.height_mm *= scale;
    s.asphere_r2_per_mm /= scale;
    double power = scale;  // s^(2i-1) for a_{2i}: s^3 for a4
    for (double& a : s.asphere) {
      power *= scale * scale;
      a /= power;
    }
  }
  return out;
}

}  // namespace lensopt
