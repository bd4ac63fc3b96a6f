// Diffraction PSFs for image formation (`render --psf diffraction|auto`, `export --diffraction`),
// on the geometric PSFs' grid (render/psf.h) so the Renderer uses them unchanged.
//
// Field h, colour channel k: the monochromatic diffraction PSFs of analysis/wave.h (FFT of the
// pupil function, OPD to the exit-pupil reference sphere about the chief ray's image point C_h)
// of the wavelengths w feeding channel k (channel_wavelengths), each integrated over the G x G
// bins of D um centred on the geometric grid's centre (0, ybar_h) (psf_cell_energies: each bin
// holds its fraction of that PSF's energy), summed with the lens's wavelength weights omega_w:
//   P_k = sum_w omega_w E_w / sum_w omega_w,   energy_share_k = sum of P_k over the grid,
// then divided by its sum so it sums to 1 (as the geometric PSFs). Sampling: WaveOptions
// (pupil grid n, padding Q: sample spacing ~ lambda N / Q, window n lambda N); a wavefront
// that changes by more than half a wave between pupil cells is undersampled (a warning).
// Auto (the paper's geometric PSF holds for strongly aberrated lenses, diffraction for
// well-corrected ones): per field and channel the PSF with the larger blur, the RMS radius
// about its own centroid, sqrt(sum P (u^2 + v^2)) over the bins.
#pragma once

#include <string>
#include <vector>

#include "lensopt/analysis/wave.h"
#include "lensopt/lens/lens.h"
#include "lensopt/render/render.h"

namespace lensopt {

enum class PsfKind { kGeometric, kDiffraction, kAuto };

// "geometric", "diffraction", "auto"; throws Error otherwise.
PsfKind parse_psf_kind(const std::string& name);
std::string psf_kind_name(PsfKind kind);

struct DiffractionPsfs {
  PsfSet<double> psfs;                // same options, fields and centres as the geometric set
  std::vector<double> strehl;         // per field, polychromatic
  std::vector<std::string> warnings;  // from the wave analysis (undersampling)
  int pupil_samples = 0, fft_n = 0;
};

// The diffraction PSFs of every field of `sys` (fields as in `geometric`). `weights`: one per
// spec wavelength, or empty for equal weights.
DiffractionPsfs diffraction_psfs(const TraceSystem<double>& sys, const std::vector<int>& channels,
                                 const std::vector<double>& weights,
                                 const PsfSet<double>& geometric, const WaveOptions& wave);

// The RMS radius (um) of one channel's G x G grid about its centroid (0 for an empty grid).
double psf_rms_radius_um(const std::vector<double>& grid, const PsfOptions& options);

// What apply_psf_kind did.
struct PsfChoice {
  PsfKind kind = PsfKind::kGeometric;
  int diffraction_channels = 0;  // (field, channel) pairs that use the diffraction PSF
  int channels = 0;              // all (field, channel) pairs
  std::vector<std::string> warnings;
};

// Replaces the model's PSFs as `kind` asks (kGeometric: no change at all). `lens` is the lens
// the model was built from (build_imaging_model, same trace options).
PsfChoice apply_psf_kind(ImagingModel& model, const Lens& lens, PsfKind kind,
                         const WaveOptions& wave = {});

// The diffraction PSFs of a model's lens (the same system as build_imaging_model's).
DiffractionPsfs model_diffraction_psfs(const ImagingModel& model, const Lens& lens,
                                       const WaveOptions& wave = {});

}  // namespace lensopt
