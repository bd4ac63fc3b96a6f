// Per-field reference heights, relative illumination and distortion, templated on the scalar so
// `lensopt analyze` (double) and the joint optimization (Jets) compute them with one code.
//
// Reference height: y_ref,h = the paraxial chief ray's height on the image plane at 587.6 nm, the
// chief ray entering through the entrance pupil's centre at slope tan theta_h.
// Relative illumination (Rimmer): R_h = A_h / A_0, A_h the image-space projected solid angle of
// field h's aimed, vignetted pupil at 587.6 nm: the area its rays' direction cosines (L, M) cover.
// The pupil's rim (K = 64 rays at equal azimuths on the unit circle of normalized pupil
// coordinates, mapped by start_rays through the vignetting factors and the aimed pupil map) and
// its centre ray c are traced without clear apertures, and A_h is the area of the rim's image
// polygon, by Green's theorem the integral of det d(L, M)/d(x_p, y_p) over the pupil:
//   A_h = s / 2 sum_i [(L_i - L_c)(M_i+1 - M_c) - (L_i+1 - L_c)(M_i - M_c)],
// s = sign(scale_x scale_y) of the aimed map (a map that flips the pupil traces the same pupil).
// A real or a virtual image maps the pupil to direction space without turning it over
// ((L, M) ~ -+k (x, y): det > 0), so every triangle (c, i, i+1) of the sum is positive. Where one
// is not, the pupil's image folds (the rim rays cross: strong pupil aberration at the edge of a
// fast lens's field) or is mirrored, and neither this polygon nor any ellipse through a few rays
// measures the projected solid angle: R_h is then unknown (not a number, and never negative), as
// where an edge ray fails. (Before issue 29 A_h was the ellipse through the upper, lower and
// sagittal rays, dM L: it agrees with this polygon to 0.2 % on the Cooke at 25 deg and 0.7 % on
// the Tessar, is 1.2 % low at 23 deg on an f/1.2 Gauss and has the wrong sign once its meridional
// rays cross; the polygon agrees with a dense integration of |det| over the pupil to 1e-4 where
// the image does not fold, tests/unit/test_reference_illumination.cpp.) A fold inside the rim
// that does not reach it is not seen: there A_h, the signed integral, is low by twice the folded
// share (0.4 % at 24 deg on that f/1.2 lens, where 0.2 % of the pupil's image folds).
// Clear apertures: R_h is multiplied by the share of the field's pupil rays that pass them,
// relative to the axis (relative_illuminations).
// Distortion (paper Eq. distortion): D_h = (ybar_h - y_ref,h) / y_ref,last, ybar_h the
// polychromatic spot centroid (0 if y_ref,last = 0).
#pragma once

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "lensopt/core/scalar.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/system.h"

namespace lensopt {

// y_ref,h of every field of `sys` (mm).
template <typename T>
std::vector<T> reference_heights(const TraceSystem<T>& sys) {
  std::vector<T> y(sys.fields_deg.size());
  for (std::size_t h = 0; h < y.size(); ++h) {
    const double tan_theta = std::tan(sys.fields_deg[h] * kPi / 180.0);
    y[h] = paraxial_image_height(sys.lens, sys.entrance_pupil_z_mm, K<T>(tan_theta),
                                 sys.lens.reference_nm());
  }
  return y;
}

// The pupil rim of the relative illumination: kRimRays normalized pupil points at equal
// azimuths on the unit circle, counterclockwise from +x, then the pupil's centre.
inline constexpr int kRimRays = 64;
inline const PupilSamples& pupil_rim_samples() {
  static const PupilSamples samples = [] {
    PupilSamples s;
    for (int i = 0; i < kRimRays; ++i) {
      const double a = 2.0 * kPi * i / kRimRays;
      s.x.push_back(std::cos(a));
      s.y.push_back(std::sin(a));
    }
    s.x.push_back(0.0);
    s.y.push_back(0.0);
    return s;
  }();
  return samples;
}

// A_h of the header: the image-space projected solid angle of field h's aimed, vignetted pupil
// (reference wavelength, clear apertures left out). Returns false, with the reason in `why` (if
// not null), when a rim ray fails or the pupil's image folds or is mirrored.
template <typename T>
bool projected_pupil_area(const TraceSystem<T>& sys, int h, T& area, std::string* why = nullptr) {
  const int w = sys.wavelength_count;  // reference wavelength
  RayBundle<T> rays;
  start_rays(sys, h, w, rays, &pupil_rim_samples());
  // Rim rays are geometry here: clear apertures are accounted for by the transmitted fraction.
  TraceLens<T> open_lens = sys.lens;
  open_lens.semi_diameter_mm.clear();
  trace_bundle(open_lens, w, open_lens.surface_count(), true, rays,
               static_cast<RayRecord<T>*>(nullptr));
  for (int i = 0; i <= kRimRays; ++i) {
    if (rays.status[i] != kRayOk) {
      if (why) *why = "a ray on the rim of its pupil fails";
      return false;
    }
  }
  const PupilMap<T>& map = sys.pupil_map(h, w);
  const double s = value_of(map.scale_x) * value_of(map.scale_y) < 0.0 ? -1.0 : 1.0;
  const T cl = rays.l[kRimRays], cm = rays.m[kRimRays];
  T twice = K<T>(0.0);
  bool turned = false;
  for (int i = 0; i < kRimRays; ++i) {
    const int j = (i + 1) % kRimRays;
    const T t = (rays.l[i] - cl) * (rays.m[j] - cm) - (rays.l[j] - cl) * (rays.m[i] - cm);
    turned = turned || !(s * value_of(t) > 0.0);
    twice += t;
  }
  if (turned) {
    if (why)
      *why =
          "its pupil's image in image space folds or is mirrored (rim rays cross), so no "
          "projected solid angle of the pupil can be measured";
    return false;
  }
  area = K<T>(0.5 * s) * twice;
  return true;
}

// R_h of every field of `sys` (0 where unavailable, see the header). With `known`, also whether
// each R_h is available (1) or not (0: a rim ray of the field or of the axis fails, the pupil's
// image folds, or no on-axis ray passes the clear apertures); with `why`, the reason per field
// (empty where known).
template <typename T>
std::vector<T> relative_illuminations(const TraceSystem<T>& sys, std::vector<char>* known = nullptr,
                                      std::vector<std::string>* why = nullptr) {
  const int field_count = static_cast<int>(sys.fields_deg.size());
  std::vector<T> ri(field_count, K<T>(0.0));
  if (known) known->assign(field_count, 0);
  if (why) why->assign(field_count, std::string());
  T axis_area = K<T>(0.0), area = K<T>(0.0);
  std::string reason;
  if (!projected_pupil_area(sys, 0, axis_area, &reason) || !(value_of(axis_area) > 0.0)) {
    if (why) why->assign(field_count, "on axis, " + (reason.empty() ? "no pupil" : reason));
    return ri;
  }
  for (int h = 0; h < field_count; ++h) {
    if (!projected_pupil_area(sys, h, area, &reason)) {
      if (why) (*why)[h] = reason;
      continue;
    }
    ri[h] = area / axis_area;
    if (known) (*known)[h] = 1;
  }
  // Clear apertures: times the fraction of the field's pupil rays (reference wavelength) that
  // pass every aperture, relative to the axis (the pupil samples are uniform in area).
  if (!sys.lens.semi_diameter_mm.empty()) {
    const int w = sys.wavelength_count;
    RayBundle<T> rays;
    auto passed = [&](int h) {
      start_rays(sys, h, w, rays);
      trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                   static_cast<RayRecord<T>*>(nullptr));
      int n = 0;
      for (std::size_t i = 0; i < rays.size(); ++i) n += rays.status[i] == kRayVignetted ? 0 : 1;
      return static_cast<double>(n) / static_cast<double>(rays.size());
    };
    const double axis = passed(0);
    for (int h = 0; h < field_count; ++h)
      ri[h] = axis > 0.0 ? ri[h] * K<T>(passed(h) / axis) : K<T>(0.0);
    if (!(axis > 0.0)) {
      if (known) known->assign(field_count, 0);
      if (why) why->assign(field_count, "no on-axis ray passes the clear apertures");
    }
  }
  return ri;
}

// D_h = (ybar_h - y_ref,h) / y_ref,last (0 if y_ref,last = 0).
template <typename T>
T field_distortion(const T& centroid_y_mm, const T& reference_y_mm, const T& reference_last_mm) {
  if (value_of(reference_last_mm) == 0.0) return K<T>(0.0);
  return (centroid_y_mm - reference_y_mm) / reference_last_mm;
}

}  // namespace lensopt
