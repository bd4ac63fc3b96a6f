// Wave-optics charts (analysis/wave.h) on a Canvas: MTF curves against frequency, through-focus
// MTF, wavefront (OPD) maps and diffraction PSFs. Each draws into a rectangle of the page.
#pragma once

#include <string>
#include <vector>

#include "lensopt/analysis/wave.h"
#include "lensopt/plot/axes.h"

namespace lensopt::plot {

// Diffraction MTF of each field of `mtf` (frequencies 0..cutoff): tangential solid, sagittal
// dashed, coloured by field, with the aberration-free curve in black. `field_labels` (one per
// field, plot_data.h field_label) name the fields in the legend; empty: their angles.
void draw_mtf_curves(Canvas& canvas, Rect area, const WaveReport& mtf, const std::string& title,
                     double font_px = 12, const std::vector<std::string>& field_labels = {});

// MTF at one frequency against the focus shift, per field (T solid, S dashed).
void draw_through_focus(Canvas& canvas, Rect area, const ThroughFocus& data, double font_px = 12,
                        const std::vector<std::string>& field_labels = {});

// One false-colour OPD map (waves, piston and tilt kept as traced) per entry, side by side.
struct WavefrontPanel {
  std::string label;
  int n = 0;                      // grid size
  std::vector<double> opd_waves;  // n x n, row 0 = pupil +y; NaN outside the pupil
  double rms_waves = 0;
  double pv_waves = 0;
};
void draw_wavefront_maps(Canvas& canvas, Rect area, const std::vector<WavefrontPanel>& panels,
                         double font_px = 12);

// Polychromatic diffraction PSFs, one tile per entry, each `spacing_um` per pixel (log scale).
struct PsfPanel {
  std::string label;
  int pixels = 0;
  std::vector<float> psf;  // pixels x pixels, row 0 = +y, peak 1
};
void draw_diffraction_psfs(Canvas& canvas, Rect area, const std::vector<PsfPanel>& panels,
                           double spacing_um, double font_px = 12);

}  // namespace lensopt::plot
