// Afocal image space (OpticStudio's "Afocal Image Space"; Specs::afocal): a lens whose image is
// at infinity (a telescope, a beam expander, an eyepiece with its objective) is measured in
// angle, not on an image plane.
//
// First-order data (paraxial y-nu trace, primary wavelength; object space n = 1, image-space
// index n'):
//   * the angular magnification M = u'_c / u_c of the chief ray through the entrance-pupil centre
//     (y_0 = -z_EP, w_0 = 1, so u_c = 1 and u'_c = w' / n'): OpticStudio's AMAG, tan u' / tan u
//     paraxially (a Keplerian telescope f1, f2: M = -f1 / f2; a Galilean one: +f1 / |f2|);
//   * the exit pupil where that chief ray crosses the axis, z_XP = -y'_c / u'_c from the last
//     vertex (positive: after it), and its diameter 2 |y'_m + u'_m z_XP| from the axial marginal
//     ray through the entrance pupil's rim (collimated at height EPD / 2, or from the axial object
//     point): for an exactly afocal lens EPD / |M|;
//   * the residual power of the lens, -1000 w'_m / y_m of the collimated marginal ray in
//     diopters (0 when the lens is exactly afocal; 1000 / EFL), and the marginal output slope.
// No EFL, BFL or F-number: they do not exist for an afocal lens.
//
// Per field, from the rays of the one trace of the field products (trace_fields through
// measure_fields, analysis/field_optics.h; AfocalRayDirections keeps their exit directions):
//   * the angular spot: the exit directions d_i (wavelength-weighted as the spot, spot.h) about
//     their centroid direction d_0 = normalize(sum_i omega_i d_i), each ray projected on the
//     plane normal to d_0 (gnomonic: a_i = (d_i.e_1, d_i.e_2) / (d_i.d_0), e_1 the x axis made
//     normal to d_0, e_2 = d_0 x e_1: the tangents of the ray's angles from d_0, sagittal and
//     tangential); the RMS radius sqrt(mean |a_i - abar|^2) in mrad (and arcmin);
//   * the output chief-ray angle u'_h = atan2(m, n) of the real chief ray (pupil centre, primary
//     wavelength) in the meridional plane, against the paraxial atan(M tan u_h): the angular
//     distortion 100 (tan u'_h - M tan u_h) / (M tan u_h) % (0 on axis);
//   * the wavefront error against a plane wave: the optical path to the plane normal to the
//     primary chief ray through its exit-pupil point (the reference sphere at infinity,
//     analysis/wavefront.h ReferenceSphere::plane), minus the chief ray's, piston and tilt removed
//     (tilt is a pointing error, the output angle above); RMS and P-V in waves, the Strehl ratio
//     S = |sum_i a_i exp(2 pi i W_i)|^2 / (sum_i a_i)^2 over the arrived pupil cells (a_i their
//     area weights: the far-field peak on the tilt-removed direction relative to a perfect plane
//     wave of the same pupil), polychromatic with the lens's wavelength weights (RMS: sqrt of the
//     weighted mean square; Strehl: the weighted mean; P-V: the largest), and optionally the
//     Zernike fit of the primary wavelength's wavefront (analysis/zernike.h).
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/analysis/zernike.h"
#include "lensopt/lens/lens.h"
#include "lensopt/trace/system.h"

namespace lensopt {

struct AfocalFirstOrder {
  double angular_magnification = 0;  // M = u'_c / u_c (paraxial)
  double entrance_pupil_diameter_mm = 0;
  double entrance_pupil_z_mm = 0;  // from the first vertex
  double exit_pupil_diameter_mm = 0;
  double exit_pupil_z_mm = 0;          // from the last vertex (positive: after it)
  double residual_power_diopters = 0;  // 1000 / EFL (0: exactly afocal)
  double marginal_output_slope = 0;    // u'_m of the axial marginal ray (rad)
  double image_space_index = 1;        // n' at the primary wavelength
};

// The paraxial first-order data of the header.
AfocalFirstOrder afocal_first_order(const TraceSystem<double>& sys);

// The on_rays reader of measure_fields / trace_fields: keeps every arrived ray's exit direction
// cosines and wavelength index per field (each field is written by the one thread tracing it).
class AfocalRayDirections {
 public:
  explicit AfocalRayDirections(const TraceSystem<double>& sys);
  void operator()(int h, int w, const RayBundle<double>& rays);

  struct Rays {
    std::vector<double> l, m, n;
    std::vector<int> wavelength;
  };
  std::size_t size() const { return rays_.size(); }
  const Rays& rays(int h) const { return rays_[h]; }

 private:
  std::vector<Rays> rays_;
};

// The angular spot of one field (see the header): the rays' projected angles from the centroid
// direction (mrad; the half-pupil's mirrors included when the system traces half pupils).
struct AngularSpot {
  double centroid_l = 0, centroid_m = 0, centroid_n = 1;  // d_0
  double rms_mrad = 0;
  int count = 0;                       // arrived rays traced (mirrors not counted)
  std::vector<double> x_mrad, y_mrad;  // a_i - abar (sagittal, tangential), every ray
  std::vector<int> wavelength;         // per point
};
AngularSpot angular_spot(const TraceSystem<double>& sys, const AfocalRayDirections::Rays& rays,
                         bool keep_points = false);

struct AfocalOptions {
  int threads = 0;                         // <= 0: all cores
  bool wavefront = true;                   // the plane-wave wavefront, Strehl (and Zernike)
  int pupil_samples = 64;                  // cells across the pupil for the wavefront
  std::vector<double> wavelength_weights;  // per spec wavelength; empty: the system's
  int zernike_terms = 0;                   // 0: no Zernike fit
  ZernikeOrdering zernike_ordering = ZernikeOrdering::kFringe;
  bool keep_points = false;  // AfocalField::spot keeps its points (a spot plot in angle)

  // Throws Error for out-of-range values.
  void validate() const;
};

struct AfocalField {
  double field_deg = 0;    // object-space chief-ray angle
  double field_value = 0;  // as written (deg or mm)
  double weight = 1;
  int traced_rays = 0;
  int failed_rays = 0;
  int vignetted_rays = 0;
  bool chief_ok = false;                        // the real chief ray (primary wavelength) arrived
  double output_chief_angle_deg = 0;            // atan2(m, n) of the real chief ray
  double paraxial_output_angle_deg = 0;         // atan(M tan u)
  double angular_distortion_percent = 0;        // 0 on axis
  std::optional<double> rms_angular_spot_mrad;  // none if no ray arrived
  AngularSpot spot;                             // its centroid (and points, keep_points)
  std::optional<double> rms_wavefront_waves;    // none without the wavefront or its chief ray
  std::optional<double> pv_wavefront_waves;
  std::optional<double> strehl;
  std::vector<double> zernike_waves;  // primary wavelength, AfocalOptions::zernike_terms
};

struct AfocalReport {
  std::string lens_name;
  std::string source_path;
  AfocalFirstOrder first_order;
  std::vector<AfocalField> fields;
  std::optional<double> mean_rms_angular_spot_mrad;  // field-weighted; none if a field failed
  std::string field_unit = "deg";
  std::string field_kind = "angle";
  double object_distance_mm = 0;  // 0: at infinity
  double primary_wavelength_nm = 0;
  int wavelength_count = 0;
  int rays_per_field_wavelength = 0;
  int rings = 0;
  bool full_pupil = false;
  int ray_failures = 0;
  int vignetted_rays = 0;
  bool wavefront = false;
  int pupil_samples = 0;
  int zernike_terms = 0;
  ZernikeOrdering zernike_ordering = ZernikeOrdering::kFringe;
};

// The report from the rays measure_fields traced (`directions` read them, `spots` their counts:
// FieldOptics::spots) and, with options.wavefront, one wavefront trace per field and wavelength
// (analysis/wavefront.h compute_wavefront against the plane).
AfocalReport analyze_afocal(const TraceSystem<double>& sys, const AfocalRayDirections& directions,
                            const SpotResult<double>& spots, const AfocalOptions& options);
// Traces the fields itself (measure_fields without the maps) and reports.
AfocalReport analyze_afocal(const TraceSystem<double>& sys, const AfocalOptions& options);
// A lens with Specs::afocal: prepare_lens_system, the lens's wavelength weights, the report with
// its name and file. Throws Error naming the file for a lens that is not afocal.
AfocalReport analyze_afocal_lens(const Lens& lens, const TraceOptions& trace,
                                 AfocalOptions options);
// `lensopt analyze`'s options (CLI and Python): its trace, dispersion override, pupil samples,
// wavelength weights and Zernike fit; the plane-wave wavefront is always on.
AfocalReport analyze_afocal_lens(const Lens& lens, const AnalyzeOptions& options);

// The one policy for what an afocal lens (Specs::afocal) cannot take: `what` (a command such as
// "render", or a Python function such as "lensopt.spots") measures an image plane, which the lens
// does not have. Throws Error naming the lens file, `what` and `why` (default: "it needs an image
// plane with a sensor on it"), and what measures the lens instead (analyze in angle, plot --kind
// spot). Does nothing for a lens with an image plane.
void refuse_afocal(const Lens& lens, std::string_view what, std::string_view why = {});

// The plane-wave reference of field h (ReferenceSphere::plane; wavefront.h), primary wavelength.
ReferenceSphere<double> afocal_reference_plane(const TraceSystem<double>& sys, int h);

// `lensopt analyze` text and JSON (one object; units in the key names; no NaN: null).
std::string format_afocal_text(const AfocalReport& report);
std::string format_afocal_json(const AfocalReport& report);

}  // namespace lensopt
