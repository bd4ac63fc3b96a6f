// `lensopt export LENS -o DIR`: what the renderer uses, as files.
//
//   psf/field_HH.exr       the sampled PSF of field HH (65 x 65, channels R G B, 32-bit float, each
//                          sums to 1; 4 um bins; row 0 at the top, +y (radially outward) up)
//   psf_sheet.png          all field PSFs side by side, each divided by its peak and shown with
//                          gamma 1/2.2 (for viewing only), labelled with its field angle
//   psf_grid.exr           the 9 x 9 patch PSFs at the image's pixel pitch (tiles of the largest
//                          kernel size, in image orientation: the axis is where the image's is)
//   psf_grid.png           the same, each tile divided by its peak, gamma 1/2.2
//   distortion.exr         per output pixel: channels dx, dy = where the warp samples the input,
//                          relative to the pixel (pixels), and D = D(r) at the sampled
//                          (undistorted) radius (fraction of y_ref,last)
//   relative_illumination.exr   per pixel, the factor R(r) (channel Y)
//   fields.json            per field: angle, y_ref, centroid, D_h, R_h, energy share per channel,
//                          traced and failed rays; the grid's pitch, patches, weights, azimuths
// With diffraction PSFs (`export --diffraction`, render/diffraction_psf.h), beside these:
//   psf/field_HH_diffraction.exr   the diffraction PSF of field HH on the same bins (sums to 1
//                          per channel), psf_sheet_diffraction.png its contact sheet, and in
//                          fields.json per field "psf_diffraction", "strehl" and
//                          "diffraction_energy_share_rgb" (the part of the PSF inside the grid)
// Every file is written atomically.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "lensopt/render/diffraction_psf.h"
#include "lensopt/render/render.h"

namespace lensopt {

struct ExportOptions {
  std::filesystem::path output_dir;
  int width = 1280;  // image size for the PSF grid and the maps
  int height = 720;
  int res_factor = 1;

  // Throws Error for a missing directory name or an out-of-range size or factor.
  void validate() const;
};

struct ExportSummary {
  std::vector<std::filesystem::path> files;  // every file written
  double pitch_um = 0;
  int kernel_size = 0;  // largest patch PSF (pixels)
  bool labels_drawn = false;
};

// `diffraction` (may be null): the model's diffraction PSFs (model_diffraction_psfs), written
// beside the geometric ones.
ExportSummary export_imaging_model(const ImagingModel& model, const ExportOptions& options,
                                   const DiffractionPsfs* diffraction = nullptr);

}  // namespace lensopt
