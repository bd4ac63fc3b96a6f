// Diffraction PSF, MTF and Strehl ratio from the wavefront (analysis/wavefront.h), and the
// geometric MTF from the same rays.
//
// Pupil function of field h and wavelength lambda on the n x n grid: P(p) = a_p exp(i 2 pi W(p)),
// a_p = 1 for a cell whose centre lies in the unit circle and whose ray arrived, else 0 (the
// area-fraction weights of the grid serve the RMS; as amplitudes they would soften the edge and
// raise the MTF by ~5e-3 at n = 128), W in waves. Near the reference point C the
// image field is U(x) ~ sum_p P(p) exp(+i 2 pi u(p).x / lambda), u(p) the ray's image-space
// direction cosines, fitted as u = u0 + (du_x x_p, du_y y_p) (Wavefront::du_x/du_y): the wave
// that leaves the sphere point of p with the phase 2 pi W(p) reaches x after |C - p| + u.(x - C),
// so a path longer by W and a step x along u both delay the phase (the same sign). Hence a tilt
// W = c y_p moves the image by y0 = -c lambda / du_y (the rays of a wavefront converging on
// C + y0 have W = -du_y y0 y_p), and a ray's transverse aberration is -(lambda / du_y) dW/dy_p,
// so the PSF's centroid is the rays' mean image point (to first order in the aberration) and
// its coma flare lies on the side of the ray spot's. With the grid spacing 2/n, one DFT of size
// M >= Q n (Q = padding), F(k) = sum_j P_j exp(-i 2 pi j k / M), gives the PSF I = |F|^2 at
//   x = x0 + kx dx, y = y0 + ky dy,  dx = -lambda / (M du_x (2/n)),  dy = -lambda / (M du_y (2/n))
// (~ lambda N / Q on axis; positive for a positive lens, du < 0; (x0, y0) the tilt's shift),
// i.e. the sampling follows from the wavelength and the working f-number (du ~ 1/(2N)); Q = 2 is
// Nyquist for the incoherent cutoff 1/(lambda N). The PSF is normalized so that the
// aberration-free PSF of the same pupil amplitude peaks at 1: I / (sum_p a_p)^2.
// Strehl ratio: the peak of that PSF with the tilt removed from W (so a shifted peak counts),
// taken as the largest of the M x M samples.
// OTF: the pupil autocorrelation, OTF(s) = sum_p P(p + s) P*(p) / sum_p |P(p)|^2 for a shift of
// s cells, computed as the FFT of the PSF (no aliasing for M >= 2n). A shift of s cells is the
// spatial frequency nu = s |du| (2/n) / lambda; the cutoff is s = n: nu_c = 2 |du| / lambda
// (= 1/(lambda N)). Tangential: frequencies along y (the meridional plane); sagittal: along x.
// Values at arbitrary frequencies interpolate the complex OTF in s through its 4 nearest samples
// (cubic Lagrange, error O(cell^4); linear interpolation erred by up to ~0.03 at n = 64).
// Polychromatic: OTF = sum_w omega_w OTF_w / sum_w omega_w (each PSF of unit energy), MTF = |OTF|;
// the polychromatic Strehl is sum_w omega_w S_w / sum_w omega_w.
// Geometric MTF: the Fourier transform of the ray spot, G(nu) = |sum_p a_p exp(-i 2 pi nu y_p)|
// / sum_p a_p over the traced rays (y_p relative to C; x_p for sagittal), polychromatic as above.
#pragma once

#include <complex>
#include <string>
#include <vector>

#include "lensopt/analysis/wavefront.h"
#include "lensopt/analysis/zernike.h"
#include "lensopt/lens/lens.h"
#include "lensopt/trace/system.h"

namespace lensopt {

struct WaveOptions {
  int pupil_samples = 128;                 // n: grid cells across the pupil diameter
  int padding = 2;                         // Q: FFT size >= Q n (2 = Nyquist)
  std::vector<double> wavelength_weights;  // per spec wavelength; empty: equal weights
  double focus_shift_mm = 0;               // image plane moved away from the lens
  bool keep_psf = false;                   // keep each monochromatic PSF (plots, export)
  bool geometric = true;                   // also the geometric MTF
  int threads = 0;                         // fields in parallel; 0: all cores
  int zernike_terms = 0;                   // Zernike fit of each wavefront (0: none; Fringe <= 37)
  ZernikeOrdering zernike_ordering = ZernikeOrdering::kFringe;

  // Throws Error for out-of-range values.
  void validate(int wavelength_count) const;
};

// One field at one wavelength.
struct MonoWave {
  double wavelength_nm = 0;
  double weight = 1;
  double rms_waves = 0;  // piston and tilt removed
  double pv_waves = 0;
  double strehl = 0;
  double du_x = 0, du_y = 0;  // direction cosine per unit pupil coordinate
  double psf_dx_um = 0;       // PSF sample spacing (signed: negative when the axis is flipped,
  double psf_dy_um = 0;       // for a negative lens: du > 0)
  double psf_shift_x_um = 0;  // the removed tilt's image shift (where the PSF really lies)
  double psf_shift_y_um = 0;
  double cutoff_t_cyc_mm = 0;     // 2 |du_y| / lambda
  double cutoff_s_cyc_mm = 0;     // 2 |du_x| / lambda
  double max_step_waves = 0;      // largest |W| step between neighbouring cells (> 0.5: aliasing)
  double vignetted_fraction = 0;  // of the pupil weight that did not arrive
  bool ok = false;                // the chief ray arrived and some rays did
  std::vector<std::complex<double>> otf_t, otf_s;  // at the requested frequencies
  std::vector<std::complex<double>> geo_t, geo_s;
  std::vector<double>
      zernike_waves;  // WaveOptions::zernike_terms coefficients (analysis/zernike.h)
  double zernike_residual_rms_waves = 0;
  int fft_n = 0;
  std::vector<float> psf;  // fft_n x fft_n, centred (row 0 = most negative y), if kept
};

struct WaveField {
  double field_deg = 0;
  double reference_x_mm = 0, reference_y_mm = 0;  // C: the reference chief ray's image point
  std::vector<MonoWave> mono;                     // per spec wavelength
  double rms_waves = 0;                           // sqrt(sum omega RMS^2 / sum omega)
  double strehl = 0;                              // weighted mean
  std::vector<double> mtf_t, mtf_s;  // polychromatic diffraction MTF at the frequencies
  std::vector<double> geo_mtf_t, geo_mtf_s;
};

struct WaveReport {
  int pupil_samples = 0;
  int fft_n = 0;
  int padding = 0;
  double focus_shift_mm = 0;
  int zernike_terms = 0;
  ZernikeOrdering zernike_ordering = ZernikeOrdering::kFringe;
  std::vector<double> frequencies_cyc_mm;
  std::vector<double> wavelengths_nm;
  std::vector<double> weights;
  // 1 / (lambda_min N), lambda_min the shortest spec wavelength; for a finite object
  // 2 NA' / lambda_min, NA' = image_na, the paraxial image-space NA of the axial object point
  // (N = EFL / EPD is not the working F-number there: a 1:1 relay works at about 2 N).
  double cutoff_cyc_mm = 0;
  double image_na = 0;                 // finite object only (else 0)
  double reference_wavelength_nm = 0;  // the primary: its chief ray centres the reference sphere
  std::vector<WaveField> fields;
  double mean_rms_waves = 0;
  double mean_strehl = 0;
  std::vector<std::string> warnings;  // e.g. undersampled wavefronts
};

// The wavelength weights of a lens for the polychromatic sums: its [specs] wavelength_weights
// (a .zmx's WAVM weights) when it has one per traced wavelength, else empty (equal weights).
std::vector<double> lens_wavelength_weights(const Lens& lens, int wavelength_count);

// Wavefront, Strehl and MTFs of every field (or only `field_indices`, when not empty).
WaveReport analyze_wave(const TraceSystem<double>& sys, const WaveOptions& options,
                        const std::vector<double>& frequencies_cyc_mm,
                        const std::vector<int>& field_indices = {});

// The wave section of `lensopt analyze --wave`: sampling, then per field the polychromatic RMS
// wavefront, Strehl ratio and T/S diffraction and geometric MTF at the frequencies.
std::string format_wave_text(const WaveReport& report);
// The same as one JSON object (no NaN).
std::string format_wave_json(const WaveReport& report);

// The aberration-free MTF of a circular pupil: (2/pi)(phi - cos phi sin phi), phi = acos(nu/nu_c).
double diffraction_limited_mtf(double nu_over_cutoff);

// One monochromatic PSF (WaveOptions::keep_psf) integrated over the cells of a grid of `pixels`
// x `pixels` square cells of side `spacing_um` whose centre lies at (centre_x_um, centre_y_um)
// from the reference point C; row 0 is +y (top). Each cell holds the integral over it of the
// bilinear interpolation of the samples, exactly (the overlaps of the cell with the samples' hat
// functions, per axis), as a fraction of the whole PSF's energy (sum_k I_k): the cells sum to 1
// when they cover the FFT window (and a sample beyond); what lies outside is lost.
// All zeros for a PSF that failed (!ok) or was not kept.
std::vector<double> psf_cell_energies(const MonoWave& mono, int pixels, double spacing_um,
                                      double centre_x_um, double centre_y_um);

// A polychromatic diffraction PSF of one field on a common grid of `pixels` x `pixels` cells of
// `spacing_um`, centred on the reference point; row 0 is +y (top): sum_w omega_w
// psf_cell_energies(w), divided by its peak (for display). `field` must hold PSFs
// (WaveOptions::keep_psf).
std::vector<float> polychromatic_psf(const WaveField& field, int pixels, double spacing_um);

// Through-focus MTF at one frequency: for each focus shift, the field's tangential and sagittal
// polychromatic MTF.
struct ThroughFocus {
  double frequency_cyc_mm = 0;
  std::vector<double> focus_shift_mm;
  std::vector<double> field_deg;
  std::vector<std::vector<double>> mtf_t, mtf_s;  // [field][focus]
};
ThroughFocus through_focus_mtf(const TraceSystem<double>& sys, const WaveOptions& options,
                               double frequency_cyc_mm, const std::vector<double>& shifts_mm,
                               const std::vector<int>& field_indices);

}  // namespace lensopt
