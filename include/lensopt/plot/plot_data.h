// The numbers behind the plots, computed from traced rays before anything is drawn, so tests can
// check them against the tracer. All of it is at the analysis sampling: the prescription scaled
// to the spec focal length, 21 fields from 0 to hfov, ray aiming on (TraceOptions defaults).
//
// Spot diagram of field h: the image-plane points (x, y) of every traced ray over all spec
// wavelengths, mirrored to the full pupil (x -> -x), relative to the polychromatic centroid
// (0, ybar_h); its RMS radius is analyze's S_h = sqrt(mean((y - ybar)^2 + x^2)) at full sampling.
// A lens with VDX or VAN (traced on the full pupil, no mirror) is drawn relative to (xbar_h,
// ybar_h).
//
// Ray fans about the chief ray of the reference wavelength (587.6 nm) at field h, pupil
// coordinate p in [-1, 1] on the aimed pupil of wavelength w:
//   tangential  e_y(p) = y(0, p) - y_chief       sagittal  e_x(p) = x(p, 0)
// where (x_p, y_p) -> pupil point (R_EP s_x x_p, R_EP (o_y + s_y y_p)) with the aimed map.
//
// Field curvature from close rays about the aimed chief ray (pupil offset +-delta), traced to the
// image plane (z = 0) with image-space slopes m/n and l/n:
//   tangential focus  dz_T = -(y_+ - y_-) / (m_+/n_+ - m_-/n_-)    (meridional pair +-delta)
//   sagittal focus    dz_S = -x_s / (l_s / n_s)                     (sagittal ray, x_p = delta)
// both in mm along z from the image plane (positive: behind it).
// Distortion is analyze's D_h = (ybar_h - y_ref,h) / y_ref,last in percent, at analyze's fields
// and on the focus curves' field grid (the same measure_fields on a finer system,
// analysis/field_sweep.h).
#pragma once

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "lensopt/analysis/analyze.h"
#include "lensopt/lens/lens.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/system.h"

namespace lensopt::plot {

// A lens prepared once for every plot: the traced system and analyze's report of it.
struct PlotContext {
  Lens lens;
  TraceOptions trace;
  TraceSystem<double> sys;
  AnalysisReport report;
  // Wavelength number of the middle wavelength of the R, G and B channels (-1: no such channel).
  std::array<int, 3> channel_wavelength{-1, -1, -1};
  // The spec wavelengths' channel (0 R, 1 G, 2 B), one per wavelength.
  std::vector<int> wavelength_channel;
};

// A ray that reached where it was traced to with finite numbers (a broken ray-aiming map can
// start rays at NaN without a failure flag).
inline bool ray_ok(const RayBundle<double>& rays, std::size_t i) {
  return rays.status[i] == kRayOk && std::isfinite(rays.x[i]) && std::isfinite(rays.y[i]) &&
         std::isfinite(rays.z[i]) && std::isfinite(rays.l[i]) && std::isfinite(rays.m[i]) &&
         std::isfinite(rays.n[i]);
}

// Ray i of `rays`: field h of `sys` starting on the entrance pupil at normalized (already aimed)
// pupil coordinates (x_norm, y_norm), in the field's direction (start_pupil_ray: collimated for
// an object at infinity, from the object point for a finite one).
inline void set_pupil_ray(const TraceSystem<double>& sys, int h, double x_norm, double y_norm,
                          RayBundle<double>& rays, std::size_t i) {
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  const double r_ep = sys.epd_mm / 2.0;
  const double object_y = sys.field_object_y_mm.empty() ? 0.0 : sys.field_object_y_mm[h];
  start_pupil_ray(rays, i, r_ep * x_norm, r_ep * y_norm, sys.entrance_pupil_z_mm,
                  sys.object_distance_mm, std::sin(theta), std::cos(theta), object_y);
  set_field_frame(sys, h, rays);
}

// Traces the lens at `trace` (analysis defaults) and analyzes it.
PlotContext make_plot_context(const Lens& lens, const TraceOptions& trace = {});

// The field numbers (into sys.fields_deg) nearest to fractions of the half field, each field
// once, in increasing order: a lens's own fields (as written) are never repeated, so a lens with
// 3 fields plots those 3 whatever the number of fractions.
std::vector<int> field_indices(const PlotContext& ctx, const std::vector<double>& fractions);

// Field h of `sys` labelled in the lens's own field type, with its written value: "14.0°"
// (angle), "object 12.00 mm" (object height), "image 21.60 mm" (paraxial or real image height).
std::string field_label(const TraceSystem<double>& sys, int h);
std::vector<std::string> field_labels(const TraceSystem<double>& sys,
                                      const std::vector<int>& fields);

// A short label of a lens's glass for annotations: the catalog name or "nd/vd".
std::string glass_label(const Material& material);

// ---- spot diagrams ----------------------------------------------------------------------------

struct SpotField {
  int field = 0;  // into sys.fields_deg
  double field_deg = 0;
  std::string label;         // field_label
  double centroid_y_mm = 0;  // polychromatic centroid (full sampling)
  double centroid_x_mm = 0;  // its x (0 but on a full pupil: VDX or VAN)
  double rms_um = 0;         // analyze's RMS spot radius
  // Points relative to the centroid, um, with their wavelength number.
  std::vector<double> x_um, y_um;
  std::vector<int> wavelength;
  double max_radius_um = 0;  // largest distance of a drawn point from the centroid
  int failed_rays = 0;
  // The label under the field's name; empty: the centroid's height "(y ... mm)". An afocal
  // lens's spots (in angle) give the output chief-ray angle here.
  std::string position_label;
};

struct SpotData {
  std::string lens_name;
  std::vector<double> wavelengths_nm;
  std::vector<int> wavelength_channel;  // 0 R, 1 G, 2 B per wavelength
  std::vector<SpotField> fields;
  double mean_rms_um = 0;   // over analyze's fields
  int analyzed_fields = 0;  // how many: the lens's own, or the paper's 21
  // The unit of x_um, y_um, rms_um, max_radius_um and mean_rms_um as drawn: micrometres on an
  // image plane, or microradians for an afocal lens's angular spot (plot/afocal_plot.h).
  std::string unit = "\u00b5m";
};

struct SpotOptions {
  std::vector<double> field_fractions{0.0, 0.25, 0.5, 0.75, 1.0};
  int draw_rings = 12;  // pupil rings of the drawn points (the RMS uses the full sampling)
  void validate() const;
};

SpotData compute_spots(const PlotContext& ctx, const SpotOptions& options = {});

// ---- ray fans ---------------------------------------------------------------------------------

struct FanCurve {
  int channel = 0;  // 0 R, 1 G, 2 B
  double wavelength_nm = 0;
  std::vector<double> pupil;     // normalized pupil coordinate, -1..1
  std::vector<double> error_um;  // e_y (tangential) or e_x (sagittal)
  std::vector<char> valid;       // the ray reached the image
};

struct FanField {
  int field = 0;
  double field_deg = 0;
  std::string label;  // field_label
  std::vector<FanCurve> tangential;
  std::vector<FanCurve> sagittal;
};

struct FanData {
  std::string lens_name;
  std::vector<FanField> fields;
  double max_abs_um = 0;  // over all valid points
};

struct FanOptions {
  std::vector<double> field_fractions{0.0, 0.25, 0.5, 0.75, 1.0};
  int samples = 61;  // pupil samples from -1 to 1
  void validate() const;
};

FanData compute_fans(const PlotContext& ctx, const FanOptions& options = {});

// ---- field curvature and distortion -------------------------------------------------------------

struct FocusCurve {
  int channel = 0;
  double wavelength_nm = 0;
  std::vector<double> tangential_mm;  // per field of FieldCurveData::field_deg
  std::vector<double> sagittal_mm;
  std::vector<char> valid;
};

struct FieldCurveData {
  std::string lens_name;
  std::vector<double> field_deg;             // fields of the focus curves (`fields` from 0 to hfov)
  std::vector<FocusCurve> focus;             // per channel
  std::vector<double> distortion_field_deg;  // analyze's fields
  std::vector<double> distortion_percent;    // analyze's, per field
  // Analyze's distortion (measure_fields, analysis/field_sweep.h) at every field of field_deg.
  std::vector<double> sweep_distortion_percent;
};

// `delta` is the close rays' offset in normalized pupil coordinates; the focus curves are traced
// at `fields` field angles (aimed like the analysis).
FieldCurveData compute_field_curves(const PlotContext& ctx, double delta = 1e-3, int fields = 51);

}  // namespace lensopt::plot
