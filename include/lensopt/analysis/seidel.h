// First-order data and third-order (Seidel) aberrations of a traced system, per surface and summed,
// with the primary chromatic aberrations: what a lens designer reads first (`lensopt analyze
// --prescription`).
//
// Paraxial rays (paraxial/paraxial.h: height y, reduced angle w = n u; refraction
// w' = w - y c (n' - n), c the paraxial curvature) at the primary wavelength:
//   marginal ray: from the axial object point through the entrance-pupil rim (object at infinity:
//     parallel at height r_EP);
//   chief ray: from the largest field's object point through the entrance-pupil centre (object at
//     infinity: at angle tan theta_max).
// At surface k (media n before, n' after; A = n (u + y c) = w + n y c the refraction invariant of
// the marginal ray, Abar the chief ray's, H = Abar y - A ybar the Lagrange invariant):
//   Delta(u/n) = w'/n'^2 - w/n^2 = A Delta(1/n^2) - y c Delta(1/n)
//   S_I   = -A^2 y Delta(u/n)                        spherical
//   S_II  = -A Abar y Delta(u/n)                     coma
//   S_III = -Abar^2 y Delta(u/n)                     astigmatism
//   S_IV  = -H^2 c Delta(1/n)                        Petzval
//   S_V   = (Abar / A)(S_III + S_IV)
//         = Abar (c ybar Delta(1/n) (2 Abar y - A ybar) - Abar^2 y Delta(1/n^2))   distortion
// (the second form, from H = Abar y - A ybar, has no division and holds where A = 0: a flat
// surface in a collimated beam). A conic or an r^4 term adds, with Delta_4 the surface's r^4 sag
// coefficient less that of its paraxial sphere, Delta_4 = (1 + k) c_s^3 / 8 + a4 - c^3 / 8 (c_s the
// base curvature, c = c_s + 2 a2 the paraxial one):
//   dS_I = 8 Delta_4 y^4 (n' - n),  dS_II = dS_I (ybar / y),  dS_III = dS_I (ybar / y)^2,
//   dS_V = dS_I (ybar / y)^3.
// Chromatic (dn = n(short) - n(long), the spec band's ends): C_I = A y Delta(dn / n),
// C_II = Abar y Delta(dn / n).
// In these signs the transverse ray aberration on the paraxial image plane of a ray at normalized
// pupil height rho (meridional) and field fraction eta is, to third order,
//   eps_y = (1 / (2 w_K)) (S_I rho^3 + 3 S_II eta rho^2 + (3 S_III + S_IV) eta^2 rho + S_V eta^3)
// with w_K = n' u' the marginal ray's final reduced angle (tests/unit/test_seidel.cpp checks each
// term against real rays at small aperture and field). To first order in dn the chromatic sums
// give the axial colour (paraxial image distance, short wavelength less long) -C_I / (n' u'^2)
// and the lateral colour (chief-ray height on the image plane, short less long) C_II / w_K; the
// report gives both exactly, from paraxial traces at the two wavelengths.
#pragma once

#include <string>
#include <vector>

#include "lensopt/trace/system.h"

namespace lensopt {

struct SurfaceSeidel {
  double s1 = 0, s2 = 0, s3 = 0, s4 = 0, s5 = 0;  // S_I .. S_V (mm)
  double c1 = 0, c2 = 0;                          // C_I, C_II (mm)
};

struct FirstOrderData {
  double efl_mm = 0;               // paraxial, primary wavelength
  double bfl_mm = 0;               // last vertex to the paraxial focus of an object at infinity
  double image_distance_mm = 0;    // last vertex to the paraxial image of the system's object
  double epd_mm = 0;               // entrance pupil diameter
  double entrance_pupil_z_mm = 0;  // from the first vertex
  double exit_pupil_z_mm = 0;      // from the image plane (negative: in front of it)
  double exit_pupil_diameter_mm = 0;
  double image_f_number = 0;      // EFL / EPD
  double working_f_number = 0;    // 1 / (2 |n' u'|) of the marginal ray
  double magnification = 0;       // paraxial lateral magnification (0 for an object at infinity)
  double lagrange_invariant = 0;  // H (mm)
  double paraxial_image_height_mm = 0;  // the chief ray's on the paraxial image plane
  double total_track_mm = 0;            // first vertex to the image plane
  double max_field_deg = 0;             // the field the chief ray is traced at
  double short_nm = 0, long_nm = 0;     // the chromatic band
};

struct SeidelReport {
  FirstOrderData first_order;
  std::vector<SurfaceSeidel> surfaces;  // one per lens surface
  SurfaceSeidel sums;
  // Third-order transverse aberrations on the paraxial image plane, at full aperture and field
  // (mm; see the header): spherical S_I / (2 w_K), tangential coma 3 S_II / (2 w_K), ...
  double marginal_final_w = 0;   // w_K
  double axial_colour_mm = 0;    // paraxial image distance, short less long wavelength
  double lateral_colour_mm = 0;  // paraxial chief-ray height on the primary's paraxial image
                                 // plane, short less long wavelength
  double petzval_radius_mm = 0;  // -H^2 / (n' S_IV) (infinite: written as 0 when S_IV = 0)
};

// The report of `sys` (its primary wavelength, its largest field). Throws Error for a system
// whose paraxial rays are not finite (afocal, a pupil at infinity).
SeidelReport seidel_report(const TraceSystem<double>& sys);

// The text block of `lensopt analyze --prescription` (surface table, first-order data, Seidel
// sums per surface) and its JSON object.
std::string format_prescription_text(const Lens& lens, const TraceSystem<double>& sys,
                                     const SeidelReport& report);
std::string format_prescription_json(const Lens& lens, const TraceSystem<double>& sys,
                                     const SeidelReport& report);

}  // namespace lensopt
