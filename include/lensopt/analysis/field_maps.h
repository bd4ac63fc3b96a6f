// Per-field reference heights, relative illumination and distortion, templated on the scalar so
// `lensopt analyze` (double) and the joint optimization (Jets) compute them with one code.
//
// Reference height: y_ref,h = the paraxial chief ray's height on the image plane at 587.6 nm, the
// chief ray entering through the entrance pupil's centre at slope tan theta_h.
// Relative illumination (Rimmer): the image-space projected solid angle of the aimed pupil,
// approximated by the ellipse through the upper, lower and sagittal rays in direction-cosine
// space: A_h = dM_h L_h, dM = (M_top - M_bottom) / 2, L the sagittal ray's x direction cosine, at
// 587.6 nm; R_h = A_h / A_0 (0 where a ray fails or A_0 <= 0).
// Distortion (paper Eq. distortion): D_h = (ybar_h - y_ref,h) / y_ref,last, ybar_h the
// polychromatic spot centroid (0 if y_ref,last = 0).
#pragma once

#include <array>
#include <cmath>
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
    y[h] =
        paraxial_image_height(sys.lens, sys.entrance_pupil_z_mm, K<T>(tan_theta), kWavelengthD_nm);
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
  const PupilMap<T>& map = sys.pupil_map(h, w);
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  const T r_ep = sys.epd_mm / K<T>(2.0);
  RayBundle<T> rays;
  rays.resize(3);
  const T px[3] = {K<T>(0.0), K<T>(0.0), map.scale_x};
  const T py[3] = {map.offset_y + map.scale_y, map.offset_y - map.scale_y, map.offset_y};
  for (int i = 0; i < 3; ++i) {
    rays.x[i] = r_ep * px[i];
    rays.y[i] = r_ep * py[i];
    rays.z[i] = sys.entrance_pupil_z_mm;
    rays.l[i] = K<T>(0.0);
    rays.m[i] = K<T>(sin(theta));
    rays.n[i] = K<T>(cos(theta));
  }
  trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
               static_cast<RayRecord<T>*>(nullptr));
  for (int i = 0; i < 3; ++i)
    if (rays.status[i] != kRayOk) return false;
  out = {rays.m[0], rays.m[1], rays.l[2]};
  return true;
}

// R_h of every field of `sys` (0 where unavailable, see the header).
template <typename T>
std::vector<T> relative_illuminations(const TraceSystem<T>& sys) {
  const int field_count = static_cast<int>(sys.fields_deg.size());
  std::vector<T> ri(field_count, K<T>(0.0));
  std::array<T, 3> d;
  if (!pupil_edge_directions(sys, 0, d)) return ri;
  const T axis_area = K<T>(0.5) * (d[0] - d[1]) * d[2];
  if (!(value_of(axis_area) > 0.0)) return ri;
  for (int h = 0; h < field_count; ++h) {
    if (!pupil_edge_directions(sys, h, d)) continue;
    ri[h] = K<T>(0.5) * (d[0] - d[1]) * d[2] / axis_area;
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
