// Validation of a lens against physical bounds: the one place every reader (TOML, the paper's
// YAML, .zmx) checks a lens's numbers, with file:line messages; Lens::validate() calls it too.
#pragma once

#include <string>
#include <vector>

#include "lensopt/lens/lens.h"

namespace lensopt {

// Lines of the source file a lens was read from (1-based; 0: unknown), for validation messages.
struct LensSourceLines {
  int f_number = 0, half_field_deg = 0, sensor_diagonal_mm = 0;
  std::vector<int> surfaces;  // one per surface (its table / SURF line)
};

// Throws Error if the lens cannot be traced or is not a lens a real camera can have: no
// surfaces, no stop or a curved stop, a non-finite number, or a number outside its physical
// bounds (the one place these are checked; every reader calls it):
//   f_number in [kMinFNumber, kMaxFNumber] in the paper's spec mode, in
//   [kMinParaxialFNumber, kMaxFNumber] for a lens traced as written (f_number_warnings);
//   half_field_deg in [kMinHalfFieldDeg, 89);
//   sensor_diagonal_mm in [kMinSensorDiagonalMm, kMaxSensorDiagonalMm] and the focal length
//   d / (2 tan hfov) in [kMinFocalLengthMm, kMaxFocalLengthMm];
//   glass nd in (1, kMaxIndex], vd in [kMinAbbe, kMaxAbbe];
//   relative to the lens's length L = sum of |thickness| but the last (or the largest |R|
//   for a lens of zero length): |R| >= kMinRadiusOfLength * L, each thickness
//   |t| <= kMaxThicknessOfLength * L, glass thicknesses >= 0 (0: a stop at a
//   curved surface's vertex).
// Messages read "file:line: surface N: ..." when `lines` has the line.
void validate_lens(const Lens& lens, const LensSourceLines& lines = {});

// One message per catalog glass of the lens that has a spec wavelength outside its formula's
// validity range (the AGF LD line), naming the glass, its surfaces, the wavelengths and the
// range: the index there is extrapolated. Empty when every glass covers every wavelength.
std::vector<std::string> glass_range_warnings(const Lens& lens);

// One message, naming the lens's file and its F-number, when a lens traced as written has a
// paraxial F-number EFL / EPD below kMinFNumber: in air its full aperture cannot satisfy the
// sine condition (h = EFL sin U' would need sin U' > 1), so it cannot be imaged sharply, and
// often its outer rays miss a surface (counted as failed). Empty otherwise.
std::vector<std::string> f_number_warnings(const Lens& lens);

// The physical bounds of Lens::validate.
// F-numbers. The real image-space working F-number 1 / (2 n' sin U') is at least 0.5 in air
// (NA <= 1); for a lens that satisfies the sine condition the paraxial F-number EFL / EPD equals
// it, so a requested F-number (the paper's spec mode, `search`) below kMinFNumber asks for a lens
// that cannot exist, and is refused. The paraxial F-number of a lens as written (a .zmx or TOML
// lens with its own aperture: FLOA, ENPD, OBNA or FNUM) is not bounded by physics: a stop imaged
// with a large magnification can give EFL / EPD < 0.5 (optiland's lens_floa.zmx: its outer rays
// miss a surface), and OpticStudio and optiland load such files. It is accepted with a warning
// (f_number_warnings); kMinParaxialFNumber only refuses nonsense (an entrance pupil more than ten
// focal lengths across: a unit slip in DIAM or ENPD, not a lens).
inline constexpr double kMinFNumber = 0.5, kMaxFNumber = 1000.0;
inline constexpr double kMinParaxialFNumber = 0.05;
inline constexpr double kMinHalfFieldDeg = 1e-3;
inline constexpr double kMinSensorDiagonalMm = 0.01, kMaxSensorDiagonalMm = 10000.0;
inline constexpr double kMinFocalLengthMm = 0.01, kMaxFocalLengthMm = 1e6;
inline constexpr double kMaxIndex = 5.0, kMinAbbe = 1.0, kMaxAbbe = 200.0;
inline constexpr double kMinRadiusOfLength = 1e-4, kMaxThicknessOfLength = 1e4;

}  // namespace lensopt
