// Per-field reference heights, relative illumination and distortion, templated on the scalar so
// `lensopt analyze` (double) and the joint optimization (Jets) compute them with one code.
//
// Reference height: y_ref,h = the paraxial chief ray's height on the image plane at 587.6 nm, the
// chief ray entering through the entrance pupil's centre at slope tan theta_h.
// Relative illumination (Rimmer, as the paper and SPEC.md prescribe): the image-space projected
// solid angle of the aimed pupil, approximated by the ellipse through the upper, lower and
// sagittal rays in direction-cosine space: A_h = dM_h L_h s_h, dM = (M_top - M_bottom) / 2, L the
// sagittal ray's x direction cosine, at 587.6 nm, s_h = sign(scale_x scale_y) of the aimed pupil
// map (a map that flips the pupil traces the same pupil: without s_h its area came out negative);
// R_h = A_h / A_0. A field whose vignetted pupil is not mirror-symmetric (VDX or VAN, lens.h) has
// the ellipse spanned by its conjugate semi-diameters instead: the rays at normalized pupil points
// (+-1, 0) and (0, +-1) (start_rays maps them to c +- u, c +- v on the vignetted pupil) give
// d_u = ((L, M)(+1, 0) - (L, M)(-1, 0)) / 2 and d_v likewise, and A_h = |d_u,L d_v,M - d_u,M
// d_v,L|, the same area as dM L for a symmetric pupil (there d_u = (L, 0), d_v = (0, dM)). The
// ellipse assumes the pupil's image is an ellipse. Where it is not, R_h is unknown (0 with known =
// 0, and a reason), never a wrong number: the pupil's rim (kRimRays rays at equal azimuths, mapped
// like every pupil point) and its centre ray c are traced, and the rim's image polygon, whose area
// by Green's theorem is the integral of det d(L, M)/d(x_p, y_p) over the pupil,
//   P_h = s_h / 2 sum_i [(L_i - L_c)(M_i+1 - M_c) - (L_i+1 - L_c)(M_i - M_c)],
// must (1) turn one way: a real or virtual image maps the pupil to direction space without
// turning it over ((L, M) ~ -+k (x, y), det > 0), so every triangle (c, i, i+1) is positive; one
// that is not means the image folds (rim rays cross: strong pupil aberration at the edge of a fast
// lens's field, where dM L changes sign) or is mirrored; and (2) have the ellipse's area to
// kEllipseTolerance (5 %). The polygon agrees with a dense integration of |det| over the pupil to
// 1e-4 where the image does not fold; the ellipse with it to 0.2 % on the Cooke at 25 deg, 0.7 %
// on the Tessar, 1.2 % at 23 deg on an f/1.2 Gauss, 13 % at 25 deg where it is refused
// (tests/unit/test_reference_illumination.cpp). Clear apertures: R_h is multiplied by the share of
// the field's pupil rays that pass them, relative to the axis (relative_illuminations).
// Distortion (paper Eq. distortion): D_h = (ybar_h - y_ref,h) / y_ref,last, ybar_h the
// polychromatic spot centroid (0 if y_ref,last = 0).
#pragma once

#include <fmt/format.h>

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

// Image-space direction cosines (M_top, M_bottom, L_side) of the aimed upper, lower and sagittal
// rays of field h at the reference wavelength. Returns false if one of them fails.
template <typename T>
bool pupil_edge_directions(const TraceSystem<T>& sys, int h, std::array<T, 3>& out) {
  using std::cos;
  using std::sin;
  const int w = sys.wavelength_count;  // reference wavelength
  // (x, y) = r_EP (scale_x (1 - VCX) px, offset_y + scale_y (VDY + (1 - VCY) py)) at the top,
  // bottom and sagittal edge; the sagittal ray at the pupil's centre height.
  const VignettingFactors v =
      h < static_cast<int>(sys.vignetting.size()) ? sys.vignetting[h] : VignettingFactors{};
  const PupilMap<T>& map = sys.pupil_map(h, w);
  const T r_ep = sys.epd_mm / K<T>(2.0);
  const T half_y = map.scale_y * K<T>(1.0 - v.vcy);
  const T centre_y = map.offset_y + map.scale_y * K<T>(v.vdy);
  const T px[3] = {K<T>(0.0), K<T>(0.0), map.scale_x * K<T>(1.0 - v.vcx)};
  const T py[3] = {centre_y + half_y, centre_y - half_y, centre_y};
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  const double object_y = sys.field_object_y_mm.empty() ? 0.0 : sys.field_object_y_mm[h];
  RayBundle<T> rays;
  rays.resize(3);
  for (int i = 0; i < 3; ++i)
    start_pupil_ray(rays, i, r_ep * px[i], r_ep * py[i], sys.entrance_pupil_z_mm,
                    sys.object_distance_mm, sin(theta), cos(theta), object_y);
  set_field_frame(sys, h, rays);
  // Edge rays are geometry here: clear apertures are accounted for by the transmitted fraction.
  TraceLens<T> open_lens = sys.lens;
  open_lens.semi_diameter_mm.clear();
  trace_bundle(open_lens, w, open_lens.surface_count(), true, rays,
               static_cast<RayRecord<T>*>(nullptr));
  for (int i = 0; i < 3; ++i)
    if (rays.status[i] != kRayOk) return false;
  out = {rays.m[0], rays.m[1], rays.l[2]};
  return true;
}

// The pupil rim of the validity check: kRimRays normalized pupil points at equal azimuths on the
// unit circle, counterclockwise from +x, then the pupil's centre.
inline constexpr int kRimRays = 64;
// The largest relative difference between the ellipse's area and the rim polygon's.
inline constexpr double kEllipseTolerance = 0.05;
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

// P_h of the header (reference wavelength, clear apertures left out). Returns false, with the
// reason in `why` (if not null), when a rim ray fails or the rim's image turns over.
template <typename T>
bool pupil_rim_area(const TraceSystem<T>& sys, int h, double& area, std::string* why = nullptr) {
  const int w = sys.wavelength_count;
  RayBundle<T> rays;
  start_rays(sys, h, w, rays, &pupil_rim_samples());
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
  const double cl = value_of(rays.l[kRimRays]), cm = value_of(rays.m[kRimRays]);
  double twice = 0.0;
  bool turned = false;
  for (int i = 0; i < kRimRays; ++i) {
    const int j = (i + 1) % kRimRays;
    const double t = (value_of(rays.l[i]) - cl) * (value_of(rays.m[j]) - cm) -
                     (value_of(rays.l[j]) - cl) * (value_of(rays.m[i]) - cm);
    turned = turned || !(s * t > 0.0);
    twice += t;
  }
  if (turned) {
    if (why)
      *why =
          "its pupil's image in image space folds or is mirrored (rim rays cross), so no "
          "projected solid angle of the pupil can be measured";
    return false;
  }
  area = 0.5 * s * twice;
  return true;
}

// A_h of the header: the image-space projected solid angle of field h's aimed, vignetted pupil
// (reference wavelength, clear apertures left out). Returns false, with the reason in `why` (if
// not null), when an edge ray fails or the pupil's image is not the ellipse (see the header).
template <typename T>
bool projected_pupil_area(const TraceSystem<T>& sys, int h, T& area, std::string* why = nullptr) {
  const VignettingFactors v =
      h < static_cast<int>(sys.vignetting.size()) ? sys.vignetting[h] : VignettingFactors{};
  const int w = sys.wavelength_count;  // reference wavelength
  if (!v.asymmetric() && !sys.lens.geometry.placed()) {
    std::array<T, 3> d;
    if (!pupil_edge_directions(sys, h, d)) {
      if (why) *why = "an edge ray of its pupil fails";
      return false;
    }
    const PupilMap<T>& map = sys.pupil_map(h, w);
    const double s = value_of(map.scale_x) * value_of(map.scale_y) < 0.0 ? -0.5 : 0.5;
    area = K<T>(s) * (d[0] - d[1]) * d[2];
  } else {
    PupilSamples edge;
    edge.x = {1.0, -1.0, 0.0, 0.0};
    edge.y = {0.0, 0.0, 1.0, -1.0};
    RayBundle<T> rays;
    start_rays(sys, h, w, rays, &edge);
    TraceLens<T> open_lens = sys.lens;
    open_lens.semi_diameter_mm.clear();
    trace_bundle(open_lens, w, open_lens.surface_count(), true, rays,
                 static_cast<RayRecord<T>*>(nullptr));
    for (int i = 0; i < 4; ++i) {
      if (rays.status[i] != kRayOk) {
        if (why) *why = "an edge ray of its pupil fails";
        return false;
      }
    }
    const T half = K<T>(0.5);
    const T du_l = half * (rays.l[0] - rays.l[1]), du_m = half * (rays.m[0] - rays.m[1]);
    const T dv_l = half * (rays.l[2] - rays.l[3]), dv_m = half * (rays.m[2] - rays.m[3]);
    area = du_l * dv_m - du_m * dv_l;
    if (value_of(area) < 0.0) area = -area;
  }
  // The ellipse's area is pi A_h; the polygon of kRimRays points on it (an affine image of the
  // regular polygon inscribed in the unit circle) has (K / 2) sin(2 pi / K) A_h.
  double rim = 0.0;
  if (!pupil_rim_area(sys, h, rim, why)) return false;
  const double on_ellipse = 0.5 * kRimRays * std::sin(2.0 * kPi / kRimRays) * value_of(area);
  if (!(std::abs(on_ellipse - rim) <= kEllipseTolerance * rim)) {
    if (why)
      *why = fmt::format(
          "its pupil's image is not the ellipse the estimate assumes (the ellipse through the "
          "edge rays has {:.1f} % of the area the traced rim encloses)",
          100.0 * on_ellipse / rim);
    return false;
  }
  return true;
}

// R_h of every field of `sys` (0 where unavailable, see the header). With `known`, also whether
// each R_h is available (1) or not (0: an edge or rim ray of the field or of the axis fails, the
// pupil's image is not the ellipse, or no on-axis ray passes the clear apertures); with `why`,
// the reason per field (empty where known).
template <typename T>
std::vector<T> relative_illuminations(const TraceSystem<T>& sys, std::vector<char>* known = nullptr,
                                      std::vector<std::string>* why = nullptr) {
  const int field_count = static_cast<int>(sys.fields_deg.size());
  std::vector<T> ri(field_count, K<T>(0.0));
  if (known) known->assign(field_count, 0);
  if (why) why->assign(field_count, std::string());
  T axis_area = K<T>(0.0), area = K<T>(0.0);
  std::string reason;
  // R is relative to the axis: field 0 (the fields increase from it) must be on axis, or there
  // is nothing to normalize to (a lens whose fields are 5 and 10 deg only would read R = 1 at
  // 5 deg).
  if (field_count == 0) return ri;
  const double object_y0 = sys.field_object_y_mm.empty() ? 0.0 : sys.field_object_y_mm[0];
  if (sys.fields_deg[0] != 0.0 || object_y0 != 0.0) {
    if (why)
      why->assign(field_count, "the lens has no on-axis field to normalize to (add a field at 0)");
    return ri;
  }
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
