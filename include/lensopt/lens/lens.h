// The lens model: a sequence of surfaces, each with the thickness to the next and the medium after
// it; one flat surface is the aperture stop; the last thickness is the distance from the last
// surface to the image plane. Lengths in mm, curvatures in 1/mm (flat = 0), angles in degrees
// unless a name says otherwise.
//
// Surface profile (sag z as a function of the height r, z positive towards the image), as
// OpticStudio's STANDARD and EVENASPH surfaces define it:
//   z(r) = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)) + a2 r^2 + a4 r^4 + ... + a16 r^16
// c the curvature (1/mm), k the conic constant (0 sphere, -1 paraboloid, < -1 hyperboloid,
// (-1, 0) prolate and > 0 oblate ellipsoid), a_{2i} in mm^(1-2i) (a2 in 1/mm is Zemax's EVENASPH
// PARM 1; a4..a16 are PARM 2..8). k = 0 and every a = 0 is today's sphere.
#pragma once

#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lensopt/core/constants.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/glass/glass.h"

namespace lensopt {

// The medium after a surface: air, a catalog glass, or a model glass given by (nd, vd).
struct Material {
  enum class Kind { kAir, kCatalog, kModel };
  Kind kind = Kind::kAir;
  std::string glass_name;  // catalog glass name (kCatalog)
  double nd = 1.0;         // d-line index (catalog's figure for kCatalog)
  double vd = 0.0;         // Abbe number (catalog's figure for kCatalog); 0 for air
  std::shared_ptr<const Glass>
      glass;  // the catalog entry (kCatalog), for DispersionModel::kCatalog
  // kModel: which model glass (glass/dispersion.h): the paper's, or OpticStudio's with its
  // partial-dispersion deviation dPgF (a .zmx model glass).
  ModelGlass model_glass = ModelGlass::kPaper;
  double dpgf = 0.0;

  bool is_air() const { return kind == Kind::kAir; }
  static Material air() { return {}; }
  static Material model(double nd, double vd);
  // OpticStudio's model glass (n(587.5618 nm) = nd exactly).
  static Material zemax_model(double nd, double vd, double dpgf = 0.0);
  static Material from_catalog(const Glass& glass);
  // "air", the glass name, or "model(nd, vd)".
  std::string label() const;
};

// Number of even-asphere terms a4, a6, ..., a16.
inline constexpr int kAsphereOrders = 7;

// Where a surface sits in 3D (issue 32), as OpticStudio's coordinate break and surface
// tilt/decenter define it. The frame of the surface is the current frame moved by
//   order 0 (decenter first): translate by (dx, dy, 0), then rotate about x, the new y, the
//                             new z:  p_parent = D + Rx(a) Ry(b) Rz(c) p_local
//   order 1 (tilt first):     rotate about z, the new y, the new x, then translate along the
//                             tilted axes:  p_parent = Rz(c) Ry(b) Rx(a) (D + p_local)
// Each rotation is right-handed about its axis (a positive tilt about x turns +y towards +z).
struct Placement {
  double decenter_x_mm = 0.0, decenter_y_mm = 0.0;
  double tilt_x_deg = 0.0, tilt_y_deg = 0.0, tilt_z_deg = 0.0;
  bool tilt_first = false;  // OpticStudio's order flag (PARM 6 of a COORDBRK): 1 = tilt first
  bool any() const {
    return decenter_x_mm != 0.0 || decenter_y_mm != 0.0 || tilt_x_deg != 0.0 || tilt_y_deg != 0.0 ||
           tilt_z_deg != 0.0;
  }
};

// Solves and variables (issue 31), as OpticStudio marks them in its Lens Data Editor.
// Which of a surface's values the optimizer may change (TOML `vary = ["radius", "thickness",
// "conic", "glass"]`; a .zmx curvature variable flag). When any surface of a lens carries a
// flag, only flagged values are free (OpticStudio's rule); with none, every value is (the
// default); optimize --freeze / --vary override the file (optimize/variables.h states the rule).
struct VaryFlags {
  bool radius = false, thickness = false, conic = false, glass = false;
  bool any() const { return radius || thickness || conic || glass; }
};

// A pickup: a value computed from another surface's (OpticStudio's pickup solve). Curvature:
// c = scale * c_source (OpticStudio scales the curvature, not the radius: scale -1 is a mirrored
// surface R = -R_source); thickness: t = scale * t_source + offset_mm. `source` is the 0-based
// surface (-1: no pickup); it must come before the surface.
struct Pickup {
  int source = -1;
  double scale = 1.0;
  double offset_mm = 0.0;  // thickness pickups only
  bool active() const { return source >= 0; }
};

// A thickness solve: kMarginalHeight sets the thickness so that the paraxial marginal ray (the
// axial object point to the edge of the entrance pupil, primary wavelength) meets the next
// surface's tangent plane at height_mm (OpticStudio's "marginal ray height" solve, pupil zone 0;
// height 0 on the last thickness = the paraxial image). Evaluated whenever the lens changes
// (trace/solves.h: on reading, after each optimizer step, before analysis).
struct ThicknessSolve {
  enum class Kind { kNone, kMarginalHeight };
  Kind kind = Kind::kNone;
  double height_mm = 0.0;
  bool active() const { return kind != Kind::kNone; }
};

// One refracting (or stop) surface.
struct Surface {
  double curvature_per_mm = 0.0;   // c = 1/R; 0 for a flat surface
  double thickness_mm = 0.0;       // axial distance to the next surface (or the image plane)
  Material material;               // medium from this surface to the next
  bool is_stop = false;            // the aperture stop (must be flat)
  double semi_diameter_mm = 0.0;   // clear semi-aperture if known; 0 = not set
  bool written_as_radius = true;   // TOML round trip: written as radius_mm (else curvature_per_mm)
  double conic = 0.0;              // conic constant k (dimensionless)
  double asphere_r2_per_mm = 0.0;  // a2, the r^2 term (Zemax EVENASPH PARM 1), 1/mm
  std::array<double, kAsphereOrders> asphere{};  // a4, a6, ..., a16 in mm^(1-2i) (i = 2..8)
  // 3D placement and reflection (issue 32; kernel.h states the model). A coordinate break is a
  // dummy surface (no intersection, no refraction, the medium before it continues) whose
  // placement moves the frame of every surface after it; on any other surface the placement
  // moves that surface and, unless restore_frame, everything after it too (OpticStudio's
  // "before surface" tilt/decenter; restore_frame is its "after surface: reverse this surface").
  Placement placement;
  bool coordinate_break = false;
  bool restore_frame = false;
  // A reflecting surface: the medium after it is the one before it, traversed backwards
  // (OpticStudio's GLAS MIRROR: the thicknesses after an odd number of mirrors are negative).
  bool mirror = false;
  // Central obscuration radius (mm, 0 = none): a ray with x^2 + y^2 < r^2 on the surface is
  // blocked (e.g. a Cassegrain secondary's shadow).
  double obscuration_mm = 0.0;
  // Centre of the clear aperture and obscuration in the surface's frame (OpticStudio's aperture
  // decenter, OBDC), mm.
  double aperture_decenter_x_mm = 0.0, aperture_decenter_y_mm = 0.0;
  // Variables, pickups and solves (above).
  VaryFlags vary;
  Pickup curvature_pickup, thickness_pickup;
  ThicknessSolve thickness_solve;
  // Any 3D placement, coordinate break or aperture decenter: the lens is not rotationally
  // symmetric (traced through the general path of kernel.h on the full pupil).
  bool breaks_symmetry() const {
    return coordinate_break || placement.any() || aperture_decenter_x_mm != 0.0 ||
           aperture_decenter_y_mm != 0.0;
  }

  // Any a2..a16 nonzero.
  bool has_asphere() const;
  // k = 0 and no asphere term: the exact sphere (or plane).
  bool is_spherical() const { return conic == 0.0 && !has_asphere(); }
  // Sag z(r) of the profile (mm) at height r (mm); NaN outside the conic's domain.
  double sag_mm(double r_mm) const;
};

// How a lens's specs are applied when it is traced.
//   kPaper:     the paper's mode. The prescription is scaled to f = d / (2 tan(hfov)); the
//               entrance pupil is f / N; fields are sampled from 0 to hfov. Default for the
//               paper's lenses (lenses/*.toml) and its YAML.
//   kAsWritten: the prescription is traced as written (no scaling); the aperture is the
//               written one (aperture_type); fields are sampled from 0 to the largest written
//               field. Default for .zmx imports and TOML with a [system] table.
enum class SpecMode { kPaper, kAsWritten };

// The system aperture, as OpticStudio names them.
enum class ApertureType {
  kFNumber,                // image-space F/# (f_number): EPD = EFL / N
  kEntrancePupilDiameter,  // aperture_value = EPD, mm
  kObjectNA,               // aperture_value = n sin(U) of the axial marginal ray (finite object)
  kFloatByStop,            // EPD = 2 (stop semi-diameter) / (paraxial stop magnification)
};

// Field types, as OpticStudio's FTYP numbers them (0..3).
enum class FieldType { kAngle, kObjectHeight, kParaxialImageHeight, kRealImageHeight };

// OpticStudio's vignetting factors of one field. The normalized pupil point (px, py) of a ray is
// compressed, turned by VAN about the pupil centre and decentred:
//   u = (1 - VCX) px,  t = (1 - VCY) py,   a = VAN (deg, counterclockwise from +x towards +y)
//   px' = VDX + u cos a - t sin a,   py' = VDY + u sin a + t cos a
// so VAN = 0 is OpticStudio's px' = VDX + (1 - VCX) px, py' = VDY + (1 - VCY) py, and VAN turns the
// compressed ellipse about its (decentred) centre. The factors are in the frame in which the field
// lies on +y (the .zmx reader turns any field into it). A pupil with VDX or VAN set is not
// mirror-symmetric about the meridional (y-z) plane: such a field is traced on the full pupil
// (TraceSystem::full_pupil), the others on the mirrored half pupil.
struct VignettingFactors {
  double vdx = 0.0, vdy = 0.0, vcx = 0.0, vcy = 0.0, van_deg = 0.0;
  bool any() const {
    return vdx != 0.0 || vdy != 0.0 || vcx != 0.0 || vcy != 0.0 || van_deg != 0.0;
  }
  // VDX or VAN is set: the pupil is not mirror-symmetric about the field's meridian.
  bool asymmetric() const { return vdx != 0.0 || van_deg != 0.0; }
  // (px', py') of (px, py) by the definition above.
  void pupil_point(double px, double py, double& qx, double& qy) const {
    const double a = van_deg * kDegToRad;
    const double c = std::cos(a), s = std::sin(a);
    const double u = (1.0 - vcx) * px, t = (1.0 - vcy) * py;
    qx = vdx + (c * u - s * t);
    qy = vdy + (s * u + c * t);
  }
};

// One field point as written: its y value (deg for kAngle, mm for the heights), its weight, its
// vignetting factors and its x value (OpticStudio's XFLN; 0 for a field on the y axis). The field
// point is (x, value); its radial distance hypot(x, value). A field off the y axis (x != 0) is
// traced in its own frame, the lens frame turned about z so that the field lies on +y (the
// vignetting factors are in that frame); a rotationally symmetric lens traces it as the field
// (0, hypot) and reports image coordinates turned back (trace/system.h, field azimuths).
struct FieldPoint {
  double value = 0.0;
  double weight = 1.0;
  VignettingFactors vignetting;
  double x = 0.0;
  // The radial distance sqrt(x^2 + value^2) (|value| on the y axis, the same bits).
  double radius() const { return x == 0.0 ? std::abs(value) : std::hypot(x, value); }
  // The angle (deg) from +y towards +x of the field point: 0 on the y axis (a field on -y is
  // mirrored, not turned, on a rotationally symmetric lens), atan2(x, value) off it.
  double azimuth_deg() const { return x == 0.0 ? 0.0 : std::atan2(x, value) / kDegToRad; }
};

// First-order specifications and sampling (SPEC "Lens model"), and the system data an optical
// engineer writes (wavelengths with weights and a primary, fields with a type and weights, the
// aperture, the object distance).
struct Specs {
  double f_number = 2.0;
  double half_field_deg = 25.0;
  double sensor_diagonal_mm = 16.0;
  std::vector<double> wavelengths_nm;              // default: the paper's 15 (R, G, B five each)
  std::vector<int> wavelength_channels;            // 0 = R, 1 = G, 2 = B, one per wavelength
  std::vector<double> wavelength_weights;          // one per wavelength, or empty: all 1
  double primary_wavelength_nm = kWavelengthD_nm;  // the paraxial reference wavelength
  DispersionModel dispersion = DispersionModel::kAbbe;

  SpecMode mode = SpecMode::kPaper;
  ApertureType aperture_type = ApertureType::kFNumber;
  double aperture_value = 0.0;  // EPD (mm) or object NA; unused for kFNumber and kFloatByStop
  FieldType field_type = FieldType::kAngle;
  std::vector<FieldPoint> fields;  // as written (kAsWritten); empty: 0 and half_field_deg
  double object_distance_mm = std::numeric_limits<double>::infinity();  // object to surface 1
  // OpticStudio's "Afocal Image Space" (a .zmx FTYP's seventh value; TOML [system] afocal):
  // the image is at infinity and image space is measured in angle (analysis/afocal.h): angular
  // magnification, exit-pupil size, output angles, angular spot and a plane-wave reference.
  // Needs a lens traced as written, with an aperture that does not use the EFL (EPD, object NA
  // or float by stop) and fields by angle or object height.
  bool afocal = false;

  bool object_at_infinity() const { return !std::isfinite(object_distance_mm); }
  // The largest written field value (deg or mm), or half_field_deg without written fields.
  double max_field_value() const;

  // The paper's defaults: f/2, 25 deg, 16 mm, 15 wavelengths.
  Specs();

  // f = d / (2 tan(hfov)), mm.
  double focal_length_mm() const;
};

// Colour channels for any wavelength set: by band (< 500 nm B, < 600 nm G, else R), so F, d, C
// map to B, G, R. A channel left empty borrows the nearest wavelength when PSFs are made
// (channel_wavelengths in render/psf.h), so a single wavelength feeds all three.
std::vector<int> default_wavelength_channels(const std::vector<double>& wavelengths_nm);

// The paper's 15 wavelengths (nm), R then G then B, and their channels.
const std::vector<double>& paper_wavelengths_nm();
const std::vector<int>& paper_wavelength_channels();

// A lens prescription with its specs.
struct Lens {
  std::string name;
  std::string catalog_name;  // the catalog its glass names refer to ("ohara"), may be empty
  Specs specs;
  std::vector<Surface> surfaces;
  std::string source_path;  // file it was read from, for messages
  std::string extra_toml;   // other top-level TOML tables ([optimize], [tolerance], ...), verbatim

  // Index of the stop surface; -1 if none.
  int stop_index() const;
  // Number of glass elements (runs of consecutive glass media).
  int element_count() const;
  // Some surface has a 3D placement, is a coordinate break or has a decentred aperture.
  bool breaks_symmetry() const {
    for (const Surface& s : surfaces)
      if (s.breaks_symmetry()) return true;
    return false;
  }
  // Some surface carries a vary flag (then only flagged values are free; VaryFlags).
  bool has_vary_flags() const {
    for (const Surface& s : surfaces)
      if (s.vary.any()) return true;
    return false;
  }
  // Some surface has a pickup or a thickness solve.
  bool has_solves() const {
    for (const Surface& s : surfaces)
      if (s.curvature_pickup.active() || s.thickness_pickup.active() || s.thickness_solve.active())
        return true;
    return false;
  }
  // Sum of all thicknesses but the last (first vertex to last vertex), mm.
  double track_length_mm() const;
  // Sum of all thicknesses (first vertex to image plane), mm.
  double total_track_mm() const;

  // Throws Error if the lens cannot be traced: no surfaces, no stop or a curved stop, a
  // non-finite number, a glass with nd <= 1 or vd <= 0, no wavelength or a spec out of range.
  // Messages name the surface (1-based) and source_path.
  void validate() const;
};

// Uniformly scales a lens: curvatures / s, thicknesses, semi-diameters, obscurations and
// decenters * s (tilts unchanged), a_{2i} * s^(1-2i) (k unchanged), so every sag scales by s;
// the lengths of pickups and solves too: a thickness pickup's offset and a marginal-ray-height
// solve's height * s (pickup scales are ratios, unchanged), so a scaled lens's pickups and solves
// give the scaled values.
Lens scaled(const Lens& lens, double scale);

}  // namespace lensopt
