// Paraxial (first-order) optics of a TraceLens, templated so Jets carry derivatives.
//
// Mirrors follow the sign convention of reflection as refraction into n' = -n (the medium after
// an odd number of mirrors has a negative index, TraceLens::index, and OpticStudio's negative
// thicknesses there), so every formula below holds unchanged. 3D placements (decenters, tilts,
// coordinate breaks; trace/kernel.h) are ignored: the paraxial data are those of the system
// unfolded about its surfaces' own axes, which for fold mirrors and off-axis sections of a
// parent surface (an off-axis parabola) are the parent system's first-order data.
//
// A paraxial ray is (y, w) with height y (mm) and reduced angle w = n u. At surface k with
// curvature c_k between media n (before) and n' (after):
//   refraction  w' = w - y c_k (n' - n)
//   transfer    y' = y + t_k w' / n'
// c_k is the paraxial curvature of the profile, c + 2 a2 (TraceLens::paraxial_curvature): the
// conic constant and the r^4..r^16 terms add no paraxial power (their sag is O(r^4) beyond the
// vertex sphere's), the r^2 term a2 (Zemax EVENASPH PARM 1) does, as a curvature 2 a2.
// Equivalently each surface is the ABCD matrix [[1, 0], [-c (n'-n), 1]] followed by
// [[1, t/n'], [0, 1]] acting on (y, w).
//   EFL = -y_0 / w_K for a ray entering parallel (y_0 = 1, w_0 = 0), w_K after the last surface;
//   BFL = -y_{K-1} / w_K (last vertex to paraxial focus);
//   entrance pupil: with (y_s, w_s) at the stop = M (y_0, u_0) from the first vertex plane,
//   y_s = A y_0 + B u_0, a ray through the pupil centre at z_EP has y_0 = -z_EP u_0, so
//   z_EP = B / A (mm, from the first vertex, positive to the right).
#pragma once

#include <cmath>
#include <vector>

#include "lensopt/core/constants.h"
#include "lensopt/core/scalar.h"
#include "lensopt/lens/trace_lens.h"

namespace lensopt {

// A paraxial ray state.
template <typename T>
struct ParaxialRay {
  T y;  // height, mm
  T w;  // reduced angle n u
};

// Traces a paraxial ray from the first vertex plane (object space, n = 1) through surfaces
// [0, end) at `wavelength_nm`. If `end` == K the ray ends at the last surface after refraction,
// i.e. (y at the last vertex, w in image space). Transfers happen between surfaces only.
template <typename T>
ParaxialRay<T> paraxial_trace(const TraceLens<T>& lens, ParaxialRay<T> ray, int end,
                              double wavelength_nm) {
  for (int k = 0; k < end; ++k) {
    if (k > 0) {
      // Transfer from surface k-1 to k through medium k-1.
      ray.y = ray.y + lens.thickness_mm[k - 1] * ray.w / lens.index_at_nm(k - 1, wavelength_nm);
    }
    const T n_before = lens.index_at_nm(k - 1, wavelength_nm);
    const T n_after = lens.index_at_nm(k, wavelength_nm);
    ray.w = ray.w - ray.y * lens.paraxial_curvature(k) * (n_after - n_before);
  }
  return ray;
}

// First-order data at one wavelength.
template <typename T>
struct ParaxialData {
  T efl_mm;               // effective focal length
  T bfl_mm;               // last vertex to paraxial focus
  T entrance_pupil_z_mm;  // entrance pupil from the first vertex (positive: to the right)
  T stop_magnification;   // A: stop height per object-space marginal height (y_s = A y_0)
};

template <typename T>
ParaxialData<T> paraxial_data(const TraceLens<T>& lens, double wavelength_nm) {
  const int k_count = lens.surface_count();
  ParaxialData<T> out;
  const ParaxialRay<T> marginal =
      paraxial_trace(lens, ParaxialRay<T>{K<T>(1.0), K<T>(0.0)}, k_count, wavelength_nm);
  out.efl_mm = -K<T>(1.0) / marginal.w;
  out.bfl_mm = -marginal.y / marginal.w;
  // After an odd number of mirrors the image space is traversed backwards (index -n'): the
  // focus lies at -y n' / w, a negative distance, as OpticStudio writes the thickness there.
  if (lens.reflected(k_count - 1)) out.bfl_mm = -out.bfl_mm;
  // Stop plane: trace up to the stop's refraction (a flat stop does not refract), then the ray
  // sits at the stop vertex. A from (1, 0), B from (0, 1).
  const int s = lens.stop;
  const ParaxialRay<T> ray_a =
      paraxial_trace(lens, ParaxialRay<T>{K<T>(1.0), K<T>(0.0)}, s + 1, wavelength_nm);
  const ParaxialRay<T> ray_b =
      paraxial_trace(lens, ParaxialRay<T>{K<T>(0.0), K<T>(1.0)}, s + 1, wavelength_nm);
  out.stop_magnification = ray_a.y;
  out.entrance_pupil_z_mm = ray_b.y / ray_a.y;
  return out;
}

// Defocus of the image plane from the paraxial focus (mm): delta = t_{K-1} - BFL, t_{K-1} the
// last surface's thickness (its distance to the image plane), BFL from `par` (paraxial_data of
// the same lens).
template <typename T>
T paraxial_defocus_mm(const TraceLens<T>& lens, const ParaxialData<T>& par) {
  return lens.thickness_mm.back() - par.bfl_mm;
}

// The last thickness (mm) that puts the image plane `defocus_mm` behind the paraxial focus:
// t_{K-1} = BFL + delta, the inverse of paraxial_defocus_mm.
template <typename T>
T image_distance_for_defocus_mm(const ParaxialData<T>& par, const T& defocus_mm) {
  return par.bfl_mm + defocus_mm;
}

// The factor that scales a prescription's lengths to the spec focal length: s = f_spec / EFL.
template <typename T>
T spec_scale(double spec_focal_length_mm, const T& efl_mm) {
  return K<T>(spec_focal_length_mm) / efl_mm;
}

// Paraxial image height (mm) on the actual image plane (thickness of the last surface) of the
// chief ray at field angle tan_theta through the entrance pupil centre.
template <typename T>
T paraxial_image_height(const TraceLens<T>& lens, const T& entrance_pupil_z_mm, const T& tan_theta,
                        double wavelength_nm) {
  const int k_count = lens.surface_count();
  ParaxialRay<T> ray{-entrance_pupil_z_mm * tan_theta, tan_theta};
  ray = paraxial_trace(lens, ray, k_count, wavelength_nm);
  // Image space is air (n = 1; -1 after an odd number of mirrors).
  if (lens.reflected(k_count - 1)) return ray.y - lens.thickness_mm[k_count - 1] * ray.w;
  return ray.y + lens.thickness_mm[k_count - 1] * ray.w;
}

// Curvature of the last surface that gives focal length `efl_mm` with all else fixed:
// w_K = w - y c (1 - n) must equal -1/f for the ray (1, 0), so c = (w + 1/f) / (y (1 - n)).
// Needs a glass before the last surface (n != 1) and y != 0. With an r^2 term a2 on the last
// surface the solved paraxial curvature is c + 2 a2, and c = solved - 2 a2 is returned.
template <typename T>
T solve_last_curvature(const TraceLens<T>& lens, const T& efl_mm, double wavelength_nm) {
  const int k_count = lens.surface_count();
  ParaxialRay<T> ray =
      paraxial_trace(lens, ParaxialRay<T>{K<T>(1.0), K<T>(0.0)}, k_count - 1, wavelength_nm);
  const int last = k_count - 1;
  ray.y = ray.y + lens.thickness_mm[last - 1] * ray.w / lens.index_at_nm(last - 1, wavelength_nm);
  const T n_before = lens.index_at_nm(last - 1, wavelength_nm);
  const T paraxial = (ray.w + K<T>(1.0) / efl_mm) / (ray.y * (K<T>(1.0) - n_before));
  return lens.asphere.empty() ? paraxial : paraxial - K<T>(2.0) * lens.asphere_term(last, 0);
}

// Paraxial clear semi-aperture (mm) of every surface of `lens` for `specs` (paper sampling):
//   h_k = |y_marginal,k| + |y_chief,k|,
// the marginal ray from the entrance-pupil edge r_EP = EFL / (2 N), the chief ray through the
// entrance-pupil centre at the largest field hfov (y_0 = -z_EP tan hfov, w_0 = tan hfov): the
// heights the rays reach. Non-finite where the paraxial rays are (an afocal lens, an entrance
// pupil at infinity): each caller says what it makes of that.
template <typename T>
std::vector<T> paraxial_clear_semi_apertures_or_nonfinite(const TraceLens<T>& lens,
                                                          const Specs& specs) {
  using std::abs;
  const int k_count = lens.surface_count();
  std::vector<T> out(k_count, K<T>(0.0));
  const ParaxialData<T> par = paraxial_data(lens, lens.reference_nm());
  const T r_ep = par.efl_mm / K<T>(specs.f_number) / K<T>(2.0);
  const double tan_field = std::tan(specs.half_field_deg * kPi / 180.0);
  for (int k = 0; k < k_count; ++k) {
    const ParaxialRay<T> marginal =
        paraxial_trace(lens, ParaxialRay<T>{r_ep, K<T>(0.0)}, k + 1, lens.reference_nm());
    const ParaxialRay<T> chief = paraxial_trace(
        lens, ParaxialRay<T>{-par.entrance_pupil_z_mm * K<T>(tan_field), K<T>(tan_field)}, k + 1,
        lens.reference_nm());
    out[k] = abs(marginal.y) + abs(chief.y);
  }
  return out;
}

}  // namespace lensopt
