// `lensopt analyze`: first-order data, RMS spot per field, distortion, relative illumination,
// ray failures and ray-aiming error of a lens at the paper's sampling.
//
// Distortion (paper Eq. distortion): D_h = (ybar_h - y_ref,h) / y_ref,last with ybar_h the
// polychromatic centroid and y_ref,h the paraxial chief-ray height on the image plane (587.6 nm).
// Relative illumination (Rimmer): the image-space projected solid angle of the aimed pupil,
// approximated by the ellipse through the upper, lower and sagittal rays in direction-cosine
// space, R_h = (dM_h L_h) / (dM_0 L_0) with dM = (M_top - M_bottom) / 2 and L the sagittal ray's
// x direction cosine, at the primary wavelength; with clear apertures, times the fraction of the
// field's pupil rays that pass them, relative to the axis (vignetting).
// Clear apertures: rays outside a surface's semi-diameter are vignetted, counted per field and
// surface apart from failures; the mean RMS spot weighs fields by their weights.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "lensopt/analysis/wave.h"
#include "lensopt/lens/lens.h"
#include "lensopt/trace/system.h"

namespace lensopt {

struct AnalyzeOptions {
  TraceOptions trace;
  std::optional<DispersionModel> dispersion;  // overrides the lens's [specs] dispersion
  // Wave optics (analysis/wave.h): RMS wavefront, Strehl ratio and MTF at these frequencies.
  bool wave = false;
  WaveOptions wave_options;
  std::vector<double> mtf_frequencies_cyc_mm{10, 30, 50};
};

struct FieldReport {
  double field_deg = 0;    // chief-ray angle in object space
  double field_value = 0;  // as written (deg or mm, AnalysisReport::field_unit)
  double weight = 1;
  int vignetted_rays = 0;             // clipped by a clear aperture (not failures)
  std::optional<double> rms_spot_um;  // none if no ray reached the image
  double centroid_y_mm = 0;
  double centroid_x_mm = 0;   // 0 unless the system traces full pupils (VDX or VAN)
  double reference_y_mm = 0;  // paraxial chief-ray height
  double distortion_percent = 0;
  std::optional<double> relative_illumination;  // none if unknown (field_maps.h): then
  std::string relative_illumination_unknown;    // why: a rim ray fails, or its pupil image folds
  int traced_rays = 0;
  int failed_rays = 0;
  double aiming_error = 0;  // largest |stop coord - target| / R_stop over wavelengths
  // The field point and its image in the object's and image's own x, y (TraceSystem::
  // field_azimuth_deg): centroid_*, reference_y_mm above are in the field's frame (the field on
  // +y); these turn them back. On the y axis field_x = 0, field_y = field_value and the image
  // coordinates are the centroids.
  double azimuth_deg = 0;
  double field_x = 0, field_y = 0;  // as written (deg or mm)
  double image_centroid_x_mm = 0, image_centroid_y_mm = 0;
  double image_reference_x_mm = 0, image_reference_y_mm = 0;
};

struct AnalysisReport {
  std::string lens_name;
  std::string source_path;
  double scale = 1;
  double efl_mm = 0;    // negative for a diverging lens (its image is virtual)
  double bfl_mm = 0;    // last vertex to the paraxial image (negative: before the last vertex)
  double f_number = 0;  // EFL / EPD, signed as the EFL (OpticStudio's image-space F/#)
  // Last vertex to the image plane as written (mm); negative: a virtual image plane, reached by
  // tracing the rays backwards (a diverging lens's image, as OpticStudio traces it).
  double image_distance_mm = 0;
  // The paraxial image of an object at infinity lies before the last vertex (BFL < 0): rays
  // leave the lens diverging, as from a diverging lens.
  bool virtual_image = false;
  // Paraxial chief-ray angle in image space over that in object space (tan u' / tan u through
  // the entrance-pupil centre): OpticStudio's angular magnification.
  double angular_magnification = 0;
  double epd_mm = 0;
  double entrance_pupil_z_mm = 0;
  double stop_radius_mm = 0;
  double total_track_mm = 0;
  int rings = 0;
  int rays_per_field_wavelength = 0;  // sys.pupil: the half pupil, or the full one (full_pupil)
  bool full_pupil = false;            // a field's VDX or VAN is set (trace/system.h)
  int wavelength_count = 0;
  bool ray_aiming = true;
  std::string dispersion;
  std::vector<FieldReport> fields;
  std::optional<double> mean_rms_spot_um;
  int ray_failures = 0;
  std::vector<int> failures_by_surface;  // 0-based surface index
  int vignetted_rays = 0;
  std::vector<int> vignetted_by_surface;  // 0-based surface index
  std::string field_kind = "angle";       // angle, object height, paraxial / real image height
  std::string field_unit = "deg";         // deg or mm
  std::string spec_mode = "paper";        // paper or as-written
  std::string aperture = "f-number";
  double object_distance_mm = 0;  // 0: at infinity
  double primary_wavelength_nm = 0;
  double max_aiming_error = 0;     // fraction of the stop radius
  std::optional<WaveReport> wave;  // with AnalyzeOptions::wave
};

AnalysisReport analyze_lens(const Lens& lens, const AnalyzeOptions& options);

// A readable multi-line table.
std::string format_report_text(const AnalysisReport& report);
// One JSON object (no NaN: missing values are null).
std::string format_report_json(const AnalysisReport& report);

}  // namespace lensopt
