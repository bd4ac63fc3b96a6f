// Quantities against field on a grid of field angles from the axis to a lens's largest field:
// the RMS spot, distortion and MTF (tangential and sagittal at chosen frequencies) of each field,
// as OpticStudio's RMS vs Field, Field Curvature/Distortion and FFT MTF vs Field show them.
//
// field_sweep_system prepares the traced (already scaled) lens of `sys` again with `fields`
// angle fields, field_angles_deg(theta_max, fields), theta_max the largest chief-ray angle of
// `sys`, in the lens's own setup (aperture, object distance, wavelengths; an aperture that
// floats by the stop keeps the stop radius of `sys`; field weights and vignetting factors are
// dropped). field_sweep then reads every quantity from the functions analyze reads it from:
// measure_fields (analysis/field_optics.h) for the spot S_h and distortion D_h, analyze_wave
// (analysis/wave.h) for the polychromatic diffraction MTF. On analyze's own system it gives
// analyze's numbers (tests/unit/test_consistency.cpp).
#pragma once

#include <vector>

#include "lensopt/analysis/wave.h"
#include "lensopt/lens/lens.h"
#include "lensopt/trace/system.h"

namespace lensopt {

TraceSystem<double> field_sweep_system(const Lens& lens, const TraceSystem<double>& sys,
                                       const TraceOptions& trace, int fields);

struct FieldSweep {
  std::vector<double> field_deg;
  std::vector<double> rms_spot_um;  // 0 where no ray arrived (spot_valid)
  std::vector<char> spot_valid;
  std::vector<double> distortion_percent;  // analyze's D_h * 100
  std::vector<double> frequencies_cyc_mm;
  std::vector<std::vector<double>> mtf_t, mtf_s;  // [frequency][field] (empty without the MTF)
  std::vector<std::string> warnings;              // the wave report's
};

// The sweep over every field of `sys`; with `mtf` also the MTF at `frequencies_cyc_mm` (with the
// wave options' sampling and wavelength weights).
FieldSweep field_sweep(const TraceSystem<double>& sys, const WaveOptions& wave,
                       const std::vector<double>& frequencies_cyc_mm, bool mtf = true);

// One JSON object (no NaN).
std::string format_field_sweep_json(const FieldSweep& sweep);

}  // namespace lensopt
