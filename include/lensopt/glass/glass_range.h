// A glass's validity range (the AGF LD line) and why its formula gives no index.
#pragma once

#include <string>

#include "lensopt/glass/glass.h"

namespace lensopt {

// Whether the wavelength (nm) lies in the formula's validity range (the AGF LD line); true when
// the catalog gives no range.
bool glass_in_range(const Glass& glass, double wavelength_nm);

// Why glass.index() gives no usable value at this wavelength, or "" if it does: "unsupported
// dispersion formula ...", "the ... formula gives no real index at ... nm (... outside ...)".
std::string missing_index_reason(const Glass& glass, double wavelength_nm);

}  // namespace lensopt
