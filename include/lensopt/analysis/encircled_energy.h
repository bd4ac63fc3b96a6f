// Encircled energy of each field: the fraction of the image's energy within a circle of radius r
// about the field's polychromatic centroid (ybar_h, xbar_h) (analysis/spot.h, the centre the RMS
// spot is taken about), geometric from the rays and diffraction from the wave-optics PSF.
//
// Geometric: the traced rays of field_optics.h's measure_fields (the one trace of a field), each
// ray of wavelength w weighing omega_w as in the RMS spot (spot.h):
//   EE_geo(r) = sum_{w,p: |p - c| <= r} omega_w / sum_{w,p} omega_w     (arrived rays)
// so that sum omega_w |p - c|^2 / sum omega_w is the RMS spot squared.
// Diffraction: each monochromatic PSF of analysis/wave.h (keep_psf) is a trigonometric
// polynomial: the M x M samples I_j of one period L = M d (d the sample spacing, per axis) are
// exactly interpolated by I(x) = (1 / M^2) sum_k Ihat_k exp(i 2 pi nu_k . (x - x_0)), Ihat the DFT
// of the samples, nu_k = (k_x / (M d_x), k_y / (M d_y)) (|k| <= M/2; no aliasing for M >= 2 n).
// Integrated over the disk |x - c| <= r:
//   int_disk exp(i 2 pi nu . (x - c)) dA = r J1(2 pi r |nu|) / |nu|     (pi r^2 at nu = 0)
// so that, with the window's energy |d_x d_y| Ihat_0,
//   EE_w(r) = sum_k Re(Ihat_k exp(i 2 pi nu_k . (c - x_0))) D(r, |nu_k|) / (M^2 |d_x d_y| Ihat_0)
// exact for r up to half the window (L / 2). The sum runs over |nu| binned on a fine grid
// (spacing 1 / (64 L), each term split linearly between its two nodes: error O((2 pi r dnu)^2)
// < 3e-4), with J1 from a table (cubic interpolation). Polychromatic: sum_w omega_w EE_w /
// sum_w omega_w (each PSF of unit energy, as the polychromatic MTF).
// For an aberration-free circular pupil EE(r) = 1 - J0(v)^2 - J1(v)^2, v = pi r / (lambda N_w)
// (Rayleigh; tests/unit/test_encircled_energy.cpp checks it).
// The radii holding 50, 80 and 90 % are interpolated linearly between samples.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "lensopt/analysis/wave.h"
#include "lensopt/trace/system.h"

namespace lensopt {

struct EncircledEnergyOptions {
  std::vector<int> field_indices;  // into sys.fields_deg; empty: every field
  int radii = 101;                 // samples from 0 to the largest radius
  double max_radius_um = 0;        // 0: automatic (1.05 x the rays' extent; with the
                                   // diffraction curve >= 3 Airy radii, <= half the PSF window)
  bool diffraction = true;         // also the diffraction encircled energy
  WaveOptions wave;                // the PSFs' sampling (keep_psf is set here)

  void validate() const;  // throws Error
};

struct FieldEncircledEnergy {
  int field = 0;  // into sys.fields_deg
  double field_deg = 0;
  double centroid_x_mm = 0, centroid_y_mm = 0;  // the centre (image plane)
  std::vector<double> geometric;                // per radius
  // Per radius up to half the PSF window (EncircledEnergy::diffraction_window_um): it may hold
  // fewer values than radius_um; empty without diffraction.
  std::vector<double> diffraction;
  // Radii (um) holding 50, 80, 90 % (none if the curve does not reach it within the radii).
  std::optional<double> geometric_r50_um, geometric_r80_um, geometric_r90_um;
  std::optional<double> diffraction_r50_um, diffraction_r80_um, diffraction_r90_um;
  int rays = 0;  // arrived rays of the geometric curve
};

struct EncircledEnergy {
  std::vector<double> radius_um;
  std::vector<FieldEncircledEnergy> fields;
  double airy_radius_um = 0;               // 1.22 lambda_primary N (the wave report's N)
  double diffraction_window_um = 0;        // half the smallest PSF window (largest exact r)
  std::vector<std::string> warnings;       // radii beyond the PSF window, undersampling
  std::vector<std::string> wave_warnings;  // the wave report's
};

EncircledEnergy encircled_energy(const TraceSystem<double>& sys,
                                 const EncircledEnergyOptions& options);

// The diffraction encircled energy of one monochromatic PSF (MonoWave with its PSF kept) within
// `radii_um` of (centre_x_um, centre_y_um) relative to the wave reference point C (see the
// header); all zeros for a PSF that failed or was not kept.
std::vector<double> psf_encircled_energy(const MonoWave& mono, const std::vector<double>& radii_um,
                                         double centre_x_um, double centre_y_um);

// The radius where a non-decreasing curve first reaches `fraction` (linear between samples).
std::optional<double> radius_at_fraction(const std::vector<double>& radius_um,
                                         const std::vector<double>& curve, double fraction);

// A text table (radii holding 50/80/90 % per field) and a JSON object (the curves; no NaN).
std::string format_encircled_energy_text(const EncircledEnergy& ee,
                                         const std::vector<double>& field_values,
                                         const std::string& field_unit);
std::string format_encircled_energy_json(const EncircledEnergy& ee);

}  // namespace lensopt
