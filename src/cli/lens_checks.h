// Checks of a lens that the commands share (lens_checks.cpp).
#pragma once

#include "lensopt/lens/lens.h"

namespace lensopt::cli {

// Prints glass_range_warnings(lens), f_number_warnings(lens) and crossing_surfaces(lens) as
// "lensopt <command>: warning: ..."; with `strict` a wavelength outside a glass's range is an
// Error instead.
void check_lens_warnings(const Lens& lens, const char* command, bool strict);

}  // namespace lensopt::cli
