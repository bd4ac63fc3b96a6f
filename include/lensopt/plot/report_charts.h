// The designer's report charts on a Canvas: MTF and RMS spot against field (analysis/
// field_sweep.h), chromatic focal shift and lateral colour (analysis/chromatic.h), encircled
// energy (analysis/encircled_energy.h). Each draws into a rectangle of the page from the data the
// analysis functions return; nothing is computed here.
#pragma once

#include <string>
#include <vector>

#include "lensopt/analysis/chromatic.h"
#include "lensopt/analysis/encircled_energy.h"
#include "lensopt/analysis/field_sweep.h"
#include "lensopt/plot/axes.h"

namespace lensopt::plot {

// Two panels: the MTF against field angle at each frequency (tangential solid, sagittal dashed,
// coloured by frequency) and the RMS spot radius against field angle.
void draw_mtf_vs_field(Canvas& canvas, Rect area, const FieldSweep& sweep, double font_px = 12);

// Two panels: the focal shift (um) against wavelength, the spec wavelengths marked and the
// diffraction-limited depth shaded; the lateral colour (short less long, um) against field angle
// with the Airy radius dashed.
void draw_chromatic(Canvas& canvas, Rect area, const ChromaticFocalShift& shift,
                    const LateralColour& lateral, double font_px = 12);

// Encircled energy against radius per field (diffraction solid, geometric dashed, coloured by
// field), with the aberration-free circular pupil's 1 - J0^2 - J1^2 at the primary wavelength.
void draw_encircled_energy(Canvas& canvas, Rect area, const EncircledEnergy& ee, double primary_nm,
                           const std::vector<std::string>& field_labels, double font_px = 12);

// 1 - J0(v)^2 - J1(v)^2, v = pi r / (lambda N) = 1.2197 pi r / r_Airy: the encircled energy of
// the aberration-free circular pupil (Rayleigh) at radius r (um) for an Airy radius (um).
double airy_encircled_energy(double radius_um, double airy_radius_um);

}  // namespace lensopt::plot
