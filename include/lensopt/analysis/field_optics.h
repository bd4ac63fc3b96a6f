// The field-optics product: the one place where traced rays become the measured quantities of
// each field, templated on the scalar (double for analyze, render, export, plot and Python; Jets
// for the joint optimization's exact gradients).
//
// measure_fields traces every field and spec wavelength once (trace_fields, analysis/spot.h) and
// returns, per field h:
//   * the spot: the wavelength-weighted RMS radius S_h about the wavelength-weighted centroid
//     (ybar_h, xbar_h), traced, failed and vignetted ray counts (spot.h states the formulas);
//   * the reference height y_ref,h: the paraxial chief ray's image height (field_maps.h);
//   * the distortion D_h = (ybar_h - y_ref,h) / y_ref,last (a fraction; paper Eq. distortion);
//   * the relative illumination R_h (field_maps.h: projected pupil solid angle relative to the
//     axis, times the fraction of pupil rays that pass the clear apertures), with whether it is
//     known (an edge ray that fails leaves it unknown: never reported as a number).
// Every consumer reads these numbers from here: `lensopt analyze` (analyze_lens), the render and
// export imaging model (render/render.h build_imaging_model), the joint optimization's optics
// sampling, plot data and the Python bindings. The geometric PSFs (render/psf.h) are built from
// the same traced rays through `on_rays` and are centred on this centroid, so PSF, distortion
// warp and spot never disagree about where a field's image is.
#pragma once

#include <string>
#include <vector>

#include "lensopt/analysis/field_maps.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/core/scalar.h"
#include "lensopt/trace/system.h"

namespace lensopt {

struct FieldOpticsOptions {
  bool maps = true;  // reference heights, distortion and relative illumination
  int threads = 0;   // <= 0: all cores
};

template <typename T>
struct FieldOptics {
  std::vector<double> fields_deg;     // the traced field angles (deg)
  std::vector<double> field_values;   // in the lens's field type (deg or mm)
  std::vector<double> field_weights;  // as the lens gives them (spot.h normalizes)
  SpotResult<T> spots;                // spot sizes, centroids, ray counts
  // With options.maps (else empty):
  std::vector<T> reference_y_mm;         // y_ref,h
  std::vector<T> distortion;             // D_h, a fraction (0 for a field no ray reaches)
  std::vector<T> relative_illumination;  // R_h (0 where unknown)
  std::vector<char> relative_illumination_known;
  std::vector<std::string> relative_illumination_unknown;  // why, where it is unknown
  std::size_t size() const { return fields_deg.size(); }
};

// The product of the header. `on_rays(h, w, rays)` sees every traced bundle (see trace_fields).
template <typename T, typename OnRays>
FieldOptics<T> measure_fields(const TraceSystem<T>& sys, const FieldOpticsOptions& options,
                              OnRays&& on_rays) {
  FieldOptics<T> out;
  out.fields_deg = sys.fields_deg;
  out.field_values = sys.field_values;
  out.field_weights = sys.field_weights;
  out.spots = trace_fields(sys, options.threads, on_rays);
  if (!options.maps) return out;
  const std::size_t field_count = sys.fields_deg.size();
  out.reference_y_mm = reference_heights(sys);
  out.relative_illumination = relative_illuminations(sys, &out.relative_illumination_known,
                                                     &out.relative_illumination_unknown);
  out.distortion.assign(field_count, K<T>(0.0));
  const T y_ref_last = out.reference_y_mm.empty() ? K<T>(0.0) : out.reference_y_mm.back();
  for (std::size_t h = 0; h < field_count; ++h)
    if (out.spots.traced_rays[h] > 0)
      out.distortion[h] =
          field_distortion(out.spots.centroid_y_mm[h], out.reference_y_mm[h], y_ref_last);
  return out;
}

template <typename T>
FieldOptics<T> measure_fields(const TraceSystem<T>& sys, const FieldOpticsOptions& options = {}) {
  return measure_fields(sys, options, [](int, int, const RayBundle<T>&) {});
}

}  // namespace lensopt
