// Chromatic focal shift and lateral colour of a traced system: the colour reports a lens
// designer reads beside the Seidel sums (`lensopt analyze --prescription`, `lensopt plot --kind
// chromatic`), in OpticStudio's conventions (Chromatic Focal Shift, Lateral Color).
//
// Chromatic focal shift: the paraxial image distance of the axial object point at wavelength
// lambda (last vertex to the focus: z(lambda) = -y_K n'(lambda) / w_K(lambda) of a paraxial ray
// from the object, paraxial/paraxial.h; for an object at infinity the back focal length),
// relative to the primary wavelength's:
//   dz(lambda) = z(lambda) - z(lambda_primary)      (mm; positive: focus further from the lens)
// sampled at the spec wavelengths, or at `samples` wavelengths evenly across a band [lo, hi].
// Its maximum range is max dz - min dz over the samples; the diffraction-limited depth beside it
// is 4 lambda_primary N_w^2 (N_w = 1 / (2 |n' u'|) the working F-number of the marginal ray):
// the full depth over which the defocus stays within lambda / 4 of optical path (Rayleigh).
// For a thin singlet dz(F) - dz(C) = f_F - f_C = -f / V to first order in the dispersion.
//
// Lateral colour: real chief rays (through the aimed stop centre of each wavelength, trace/
// system.h pupil maps) traced to the image plane at every field; per field the chief-ray image
// height at each spec wavelength relative to the primary's, and short less long wavelength (the
// extremes of the spec band): y_chief(lambda_short) - y_chief(lambda_long). Beside it the Airy
// radius 1.22 lambda_primary N_w (a lateral colour well inside it is not seen).
#pragma once

#include <string>
#include <vector>

#include "lensopt/lens/lens.h"
#include "lensopt/trace/system.h"

namespace lensopt {

struct ChromaticFocalShift {
  double primary_nm = 0;
  std::vector<double> wavelengths_nm;  // the samples, increasing
  std::vector<double> shift_mm;        // dz per sample
  double max_range_mm = 0;             // max dz - min dz
  double diffraction_depth_mm = 0;     // 4 lambda_primary N_w^2
  double working_f_number = 0;         // N_w at the primary
  bool band = false;                   // sampled across a band (else the spec wavelengths)
};

// The focal shift of `sys` (prepared from `lens`, whose glasses give the indices at a band's
// wavelengths). lo_nm = hi_nm = 0: at the spec wavelengths; else `samples` >= 2 wavelengths from
// lo_nm to hi_nm. Throws Error for a bad band, a wavelength outside a catalog glass's range, or a
// system whose paraxial focus is not finite (afocal).
ChromaticFocalShift chromatic_focal_shift(const Lens& lens, const TraceSystem<double>& sys,
                                          double lo_nm = 0, double hi_nm = 0, int samples = 41);

struct LateralColour {
  std::vector<double> field_deg;
  std::vector<double> field_values;    // as written (deg or mm)
  std::vector<double> wavelengths_nm;  // the spec wavelengths
  double primary_nm = 0;
  double short_nm = 0, long_nm = 0;
  // [field][spec wavelength]: chief-ray image height less the primary's (um).
  std::vector<std::vector<double>> relative_um;
  std::vector<double> lateral_colour_um;  // per field: short less long (0 where not valid)
  std::vector<char> valid;                // every chief ray of the field reached the image
  double airy_radius_um = 0;              // 1.22 lambda_primary N_w
};

// Real chief rays of every field of `sys` at every spec wavelength and the primary.
LateralColour lateral_colour(const TraceSystem<double>& sys);

// Text blocks and JSON objects (no NaN) of the two reports.
std::string format_chromatic_text(const ChromaticFocalShift& shift, const LateralColour& lateral,
                                  const std::string& field_unit);
std::string format_focal_shift_json(const ChromaticFocalShift& shift);
std::string format_lateral_colour_json(const LateralColour& lateral);

}  // namespace lensopt
