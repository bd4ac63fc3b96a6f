// Pickups and thickness solves of a lens (issue 31; lens.h Pickup, ThicknessSolve), evaluated on
// a TraceLens<T> so that the optimizer's Jets carry derivatives through them: a picked-up or
// solved value is a function of its sources, never a free variable.
//
// Evaluation order (OpticStudio's solves are "forward only": no solve changes what an earlier
// one used), surface by surface k = 0..K-1:
//   curvature pickup   c_k = scale * c_s                      (s < k)
//   thickness pickup   t_k = scale * t_s + offset             (s < k)
//   marginal height    t_k = (h - y_k) n_k / w_k
// where (y_k, w_k) is the paraxial marginal ray after refraction at surface k (paraxial.h:
// height y, reduced angle w = n u) at the primary wavelength and n_k the index after surface k,
// so the ray meets the tangent plane of surface k+1 at height h. The marginal ray starts at the
// axial object point through the edge of the entrance pupil: for an object at infinity
// (y, w) = (EPD/2, 0) at the first vertex; for an object at distance d before the first vertex,
// u = (EPD/2) / (d + z_EP) and (y, w) = (u d, u). A height h = 0 does not depend on the ray's
// scale (the ray crosses the axis where any axial-object ray does), so it needs no pupil: the
// last thickness with h = 0 is the paraxial image distance of the object as written (for an
// object at infinity the BFL). A nonzero height scales with EPD/2 (aperture types as
// trace/system.h computes the EPD), which no solve may change: it is accepted on the last
// thickness only (Lens::validate refuses it elsewhere).
// `length_unit` converts the lens file's millimetres (offsets, heights, the object distance, an
// EPD aperture) into the TraceLens's length unit: 1 for a lens as written, 1 / f for the
// optimizer's normalized (f = 1) lens.
#pragma once

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"

namespace lensopt {

// The solves of a lens and the system data the marginal ray needs.
struct LensSolves {
  std::vector<Pickup> curvature, thickness;
  std::vector<ThicknessSolve> solve;
  double object_distance_mm = std::numeric_limits<double>::infinity();
  ApertureType aperture_type = ApertureType::kFNumber;
  double f_number = 2.0, aperture_value = 0.0, stop_semi_diameter_mm = 0.0;

  bool any() const {
    for (std::size_t k = 0; k < solve.size(); ++k)
      if (curvature[k].active() || thickness[k].active() || solve[k].active()) return true;
    return false;
  }
  static LensSolves of(const Lens& lens) {
    LensSolves out;
    for (const Surface& s : lens.surfaces) {
      out.curvature.push_back(s.curvature_pickup);
      out.thickness.push_back(s.thickness_pickup);
      out.solve.push_back(s.thickness_solve);
      if (s.is_stop) out.stop_semi_diameter_mm = s.semi_diameter_mm;
    }
    out.object_distance_mm = lens.specs.object_distance_mm;
    out.aperture_type = lens.specs.aperture_type;
    out.f_number = lens.specs.f_number;
    out.aperture_value = lens.specs.aperture_value;
    return out;
  }
};

namespace detail {

// The paraxial marginal ray at the first vertex with entrance-pupil radius r (lens units).
template <typename T>
ParaxialRay<T> marginal_ray_start(const T& r, const T& entrance_pupil_z, double object_distance) {
  if (!std::isfinite(object_distance)) return {r, K<T>(0.0)};
  const T u = r / (K<T>(object_distance) + entrance_pupil_z);
  return {u * K<T>(object_distance), u};
}

// The entrance-pupil radius of `lens` (its current values) for the aperture of `s`.
template <typename T>
T entrance_pupil_radius(const TraceLens<T>& lens, const LensSolves& s, double length_unit) {
  const ParaxialData<T> par = paraxial_data(lens, lens.reference_nm());
  T epd = K<T>(0.0);
  switch (s.aperture_type) {
    case ApertureType::kFNumber:
      epd = par.efl_mm / K<T>(s.f_number);
      break;
    case ApertureType::kEntrancePupilDiameter:
      epd = K<T>(s.aperture_value * length_unit);
      break;
    case ApertureType::kObjectNA:
      epd = K<T>(2.0 * std::tan(std::asin(s.aperture_value))) *
            (par.entrance_pupil_z_mm + K<T>(s.object_distance_mm * length_unit));
      break;
    case ApertureType::kFloatByStop:
      epd = K<T>(2.0 * s.stop_semi_diameter_mm * length_unit) / par.stop_magnification;
      break;
  }
  return epd < K<T>(0.0) ? -epd / K<T>(2.0) : epd / K<T>(2.0);
}

}  // namespace detail

// The thickness after surface k that brings the paraxial marginal ray to height `height` (lens
// units) on the tangent plane of surface k+1 (header). Non-finite when the ray leaves surface k
// parallel to the axis (no such thickness).
template <typename T>
T marginal_height_thickness(const TraceLens<T>& lens, int k, const LensSolves& s, double height,
                            double length_unit) {
  const double object = s.object_distance_mm * length_unit;
  T r = K<T>(1.0), z_ep = K<T>(0.0);
  if (height != 0.0 || std::isfinite(object)) {
    const ParaxialData<T> par = paraxial_data(lens, lens.reference_nm());
    z_ep = par.entrance_pupil_z_mm;
    if (height != 0.0) r = detail::entrance_pupil_radius(lens, s, length_unit);
  }
  const double nm = lens.reference_nm();
  const ParaxialRay<T> ray =
      paraxial_trace(lens, detail::marginal_ray_start(r, z_ep, object), k + 1, nm);
  return (K<T>(height) - ray.y) * lens.index_at_nm(k, nm) / ray.w;
}

// Applies the pickups and marginal-height solves of surfaces [begin, end) to `lens` in the
// header's order; (0, K) applies everything.
template <typename T>
void apply_pickups_and_solves(TraceLens<T>& lens, const LensSolves& s, double length_unit,
                              int begin, int end) {
  const int k_count = std::min(lens.surface_count(), static_cast<int>(s.solve.size()));
  end = std::min(end, k_count);
  for (int k = std::max(begin, 0); k < end; ++k) {
    if (s.curvature[k].active())
      lens.curvature_per_mm[k] =
          K<T>(s.curvature[k].scale) * lens.curvature_per_mm[s.curvature[k].source];
    if (s.thickness[k].active())
      lens.thickness_mm[k] = K<T>(s.thickness[k].scale) * lens.thickness_mm[s.thickness[k].source] +
                             K<T>(s.thickness[k].offset_mm * length_unit);
    if (s.solve[k].kind == ThicknessSolve::Kind::kMarginalHeight) {
      const T t =
          marginal_height_thickness(lens, k, s, s.solve[k].height_mm * length_unit, length_unit);
      if (std::isfinite(value_of(t))) lens.thickness_mm[k] = t;
    }
  }
}

// The lens with its pickups and solves evaluated (double), curvatures and thicknesses written
// back (a lens without any is returned as it is). Throws Error naming the surface when a
// marginal-height solve has no solution (the marginal ray leaves the surface parallel to the
// axis).
inline Lens with_solves(const Lens& lens) {
  if (!lens.has_solves()) return lens;
  const LensSolves s = LensSolves::of(lens);
  TraceLens<double> tl = make_trace_lens(lens);
  const int k_count = tl.surface_count();
  for (int k = 0; k < k_count; ++k) {
    if (s.solve[k].active()) {
      apply_pickups_and_solves(tl, s, 1.0, 0, k);
      const double t = marginal_height_thickness(tl, k, s, s.solve[k].height_mm, 1.0);
      if (!std::isfinite(t))
        throw Error(SourceLocation{lens.source_path.empty() ? lens.name : lens.source_path},
                    fmt::format("surface {}: the marginal-ray-height solve has no solution (the "
                                "paraxial marginal ray leaves the surface parallel to the axis)",
                                k + 1));
    }
  }
  apply_pickups_and_solves(tl, s, 1.0, 0, k_count);
  Lens out = lens;
  for (int k = 0; k < k_count; ++k) {
    out.surfaces[k].curvature_per_mm = tl.curvature_per_mm[k];
    out.surfaces[k].thickness_mm = tl.thickness_mm[k];
  }
  return out;
}

}  // namespace lensopt
