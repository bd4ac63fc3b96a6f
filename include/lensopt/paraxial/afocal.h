// Paraxial first order of an afocal lens (image at infinity, analysis/afocal.h), templated so
// Jets carry derivatives (the optimizer's angular-magnification solve, optimize/variables.h).
//
// The chief ray through the entrance-pupil centre at unit object-space slope (n = 1):
//   y_0 = -z_EP, w_0 = 1  (z_EP from the first vertex, paraxial.h),
// traced through every surface (paraxial.h's refraction and transfer) gives the angular
// magnification (OpticStudio's AMAG, tan u' / tan u paraxially)
//   M = u'_c / u_c = w'_K / n',   n' the image-space index,
// exact for an afocal lens whatever the pupil; for a lens with residual power it is the chief
// ray's (the entrance pupil fixes which ray). Its solve on the last surface K-1 (curvature c,
// media n before, n' after): w'_K = w - y c (n' - n) = M n' gives
//   c = (w - M n') / (y (n' - n)),
// with (y, w) the chief ray at the last vertex before refraction; it needs a glass before the
// last surface (n != n') and a chief ray off the axis there (y != 0: a pupil imaged onto the last
// surface has no lever on M). An r^2 term a2 on the last surface adds 2 a2 to the paraxial
// curvature, as in solve_last_curvature.
#pragma once

#include "lensopt/paraxial/paraxial.h"

namespace lensopt {

// z_EP (mm, from the first vertex): paraxial_data's, without the focal length an afocal lens
// lacks.
template <typename T>
T paraxial_entrance_pupil_z_mm(const TraceLens<T>& lens, double wavelength_nm) {
  const int s = lens.stop;
  const ParaxialRay<T> ray_a =
      paraxial_trace(lens, ParaxialRay<T>{K<T>(1.0), K<T>(0.0)}, s + 1, wavelength_nm);
  const ParaxialRay<T> ray_b =
      paraxial_trace(lens, ParaxialRay<T>{K<T>(0.0), K<T>(1.0)}, s + 1, wavelength_nm);
  return ray_b.y / ray_a.y;
}

// The chief ray of the header at the last vertex, before its refraction.
template <typename T>
ParaxialRay<T> afocal_chief_at_last_vertex(const TraceLens<T>& lens, double wavelength_nm) {
  const int last = lens.surface_count() - 1;
  const T z_ep = paraxial_entrance_pupil_z_mm(lens, wavelength_nm);
  ParaxialRay<T> ray = paraxial_trace(lens, ParaxialRay<T>{-z_ep, K<T>(1.0)}, last, wavelength_nm);
  ray.y = ray.y + lens.thickness_mm[last - 1] * ray.w / lens.index_at_nm(last - 1, wavelength_nm);
  return ray;
}

// M of the header.
template <typename T>
T paraxial_angular_magnification(const TraceLens<T>& lens, double wavelength_nm) {
  const int k_count = lens.surface_count();
  const T z_ep = paraxial_entrance_pupil_z_mm(lens, wavelength_nm);
  const ParaxialRay<T> chief =
      paraxial_trace(lens, ParaxialRay<T>{-z_ep, K<T>(1.0)}, k_count, wavelength_nm);
  return chief.w / lens.index_at_nm(k_count - 1, wavelength_nm);
}

// The last surface's curvature that gives angular magnification `m` with all else fixed (header).
template <typename T>
T solve_last_curvature_for_angular_magnification(const TraceLens<T>& lens, const T& m,
                                                 double wavelength_nm) {
  const int last = lens.surface_count() - 1;
  const ParaxialRay<T> ray = afocal_chief_at_last_vertex(lens, wavelength_nm);
  const T n_before = lens.index_at_nm(last - 1, wavelength_nm);
  const T n_after = lens.index_at_nm(last, wavelength_nm);
  const T paraxial = (ray.w - m * n_after) / (ray.y * (n_after - n_before));
  return lens.asphere.empty() ? paraxial : paraxial - K<T>(2.0) * lens.asphere_term(last, 0);
}

}  // namespace lensopt
