// Automatic semi-diameters, as OpticStudio computes them for a surface without a fixed one: the
// largest ray height sqrt(x^2 + y^2) at each surface over the marginal and chief rays of every
// field and wavelength (the chief ray and `edge_rays` rays on the edge of the field's pupil,
// with the system's aimed pupil map and vignetting factors). Rays vignetted before a surface do
// not count there; where one of them misses a surface (or is totally reflected) at or before
// it, the height is unknown: NaN (OpticStudio's marginal ray would fail there too; the .zmx
// writer then writes no DIAM). Heights are in the lens's own units (the system's scale is
// divided out), one per surface.
#pragma once

#include <vector>

#include "lensopt/trace/system.h"

namespace lensopt {

std::vector<double> automatic_semi_diameters(const TraceSystem<double>& sys, int edge_rays = 33);

// The same for a lens traced in its own spec mode (prepare_lens_system, ray aiming on).
std::vector<double> automatic_semi_diameters(const Lens& lens);

}  // namespace lensopt
