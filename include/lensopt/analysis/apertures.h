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

// Two surfaces that cross: elements through each other, or a glass of negative edge thickness.
// For each two consecutive surfaces i < j that are not dummies (a dummy is the stop, or a flat
// surface with air on both sides), the gap between them at height r is
//   g(r) = t_i + ... + t_(j-1) + sag_j(r) - sag_i(r)      (Surface::sag_mm)
// checked at r = 0 and r = m h / 8, m = 1..8, with h the smaller clear semi-aperture of the two
// (the written semi-diameters, else automatic_semi_diameters; unknown: r = 0 only). The first
// r where g < 0 is reported: there the second surface lies before the first, which no lens can
// be (a dummy may: a stop before the front vertex is traced as a virtual plane). Surfaces are
// 0-based; lengths in the lens's own units.
struct SurfaceCrossing {
  int first = 0, second = 0;
  double height_mm = 0;  // r where the gap is first below 0
  double gap_mm = 0;     // g(r) < 0
};
std::vector<SurfaceCrossing> crossing_surfaces(const Lens& lens);

}  // namespace lensopt
