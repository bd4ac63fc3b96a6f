// The angular spot of an afocal lens (analysis/afocal.h), templated on the scalar: the one
// implementation that `analyze` (double) and the optimizer's afocal merit (double and Jets,
// optimize/design_loss.h) both evaluate, so the two report the same number.
//
// For the exit directions d_i = (l_i, m_i, n_i) of the arrived rays of one field, each with a
// weight omega_i >= 0 (its wavelength's, analysis/spot.h):
//   d_0 = normalize(sum_i omega_i d_i)                         (the centroid direction)
//   e_1 = normalize(x - (x.d_0) d_0),  e_2 = d_0 x e_1          (+y for d_0 = +z)
//   a_i = (d_i.e_1, d_i.e_2) / (d_i.d_0)                       (gnomonic projection: the tangents
//                                                               of the ray's angles from d_0)
//   abar = sum_i omega_i a_i / sum_i omega_i,
//   A^2  = sum_i omega_i |a_i - abar|^2 / sum_i omega_i        (rad^2; A the RMS angular spot)
// On a mirrored half pupil (the system traces x_p >= 0 and each ray stands for itself and its
// mirror (-l, m, n)) the x components of d_0 and abar are 0 by symmetry and the mirror's
// deviation has the same square, so the sums over the traced rays are the sums over the pupil.
#pragma once

#include <cmath>
#include <cstddef>

#include "lensopt/core/scalar.h"

namespace lensopt {

template <typename T>
struct AngularSpotMoments {
  T d0[3] = {K<T>(0.0), K<T>(0.0), K<T>(1.0)};  // the centroid direction
  T mean_x = K<T>(0.0), mean_y = K<T>(0.0);     // abar (sagittal, tangential)
  T variance = K<T>(0.0);                       // A^2 (rad^2)
  double weight_sum = 0.0;                      // sum_i omega_i
  int count = 0;                                // arrived rays
  bool ok = false;  // some arrived ray of positive weight and a centroid direction
};

// The moments of the header over `count` rays: directions (l, m, n), weights omega (>= 0),
// `arrived` (null: every ray arrived; a ray that did not is skipped). Writes the projections
// a_i into ax[i], ay[i] for the arrived rays (others untouched) when ok.
template <typename T>
AngularSpotMoments<T> angular_spot_moments(std::size_t count, const T* l, const T* m, const T* n,
                                           const double* omega, const char* arrived, bool mirror,
                                           T* ax, T* ay) {
  using std::sqrt;
  AngularSpotMoments<T> out;
  // The centroid direction: the weighted mean of the unit vectors (a mirror cancels l).
  T sl = K<T>(0.0), sm = K<T>(0.0), sn = K<T>(0.0);
  for (std::size_t i = 0; i < count; ++i) {
    if (arrived && !arrived[i]) continue;
    const T a = K<T>(omega[i]);
    if (!mirror) sl = sl + a * l[i];
    sm = sm + a * m[i];
    sn = sn + a * n[i];
    ++out.count;
  }
  if (out.count == 0) return out;
  const T norm = sqrt(sl * sl + sm * sm + sn * sn);
  if (!(norm > K<T>(0.0))) return out;
  const T d0[3] = {sl / norm, sm / norm, sn / norm};
  // e1: the x axis made normal to d0; e2 = d0 x e1.
  T e1[3] = {K<T>(1.0) - d0[0] * d0[0], -d0[0] * d0[1], -d0[0] * d0[2]};
  const T e1n = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
  for (T& v : e1) v = v / e1n;
  const T e2[3] = {d0[1] * e1[2] - d0[2] * e1[1], d0[2] * e1[0] - d0[0] * e1[2],
                   d0[0] * e1[1] - d0[1] * e1[0]};
  double sum_a = 0.0;
  T mean_x = K<T>(0.0), mean_y = K<T>(0.0);
  for (std::size_t i = 0; i < count; ++i) {
    if (arrived && !arrived[i]) continue;
    const T c = l[i] * d0[0] + m[i] * d0[1] + n[i] * d0[2];
    ax[i] = (l[i] * e1[0] + m[i] * e1[1] + n[i] * e1[2]) / c;
    ay[i] = (l[i] * e2[0] + m[i] * e2[1] + n[i] * e2[2]) / c;
    const T a = K<T>(omega[i]);
    sum_a += omega[i];
    if (!mirror) mean_x = mean_x + a * ax[i];  // the mirror's x is -ax: a mean of 0
    mean_y = mean_y + a * ay[i];
  }
  if (!(sum_a > 0.0)) return out;
  mean_x = mean_x / K<T>(sum_a);
  mean_y = mean_y / K<T>(sum_a);
  T sum_sq = K<T>(0.0);
  for (std::size_t i = 0; i < count; ++i) {
    if (arrived && !arrived[i]) continue;
    const T dx = ax[i] - mean_x, dy = ay[i] - mean_y;
    sum_sq = sum_sq + K<T>(omega[i]) * (dx * dx + dy * dy);
  }
  for (int j = 0; j < 3; ++j) out.d0[j] = d0[j];
  out.mean_x = mean_x;
  out.mean_y = mean_y;
  out.variance = sum_sq / K<T>(sum_a);
  out.weight_sum = sum_a;
  out.ok = true;
  return out;
}

}  // namespace lensopt
