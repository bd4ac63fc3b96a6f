// A lens prepared for real-ray tracing at the paper's sampling: scaled to the spec focal
// length, with its paraxial entrance pupil, the real stop radius and the ray-aiming pupil maps.
//
// Pupil sampling (paper, "Geometrical PSFs"): R rings (32) on the half pupil x >= 0; ring
// i = 0..R-1 has 2i+1 rays at azimuths a_j = ((j + 1/2) / (2i+1) - 1/2) pi and normalized radius
//   r = 2i / (2R-1) + ((k + i) mod 2) / (2R-1),
// k the ray's running index over all rings; (x_p, y_p) = r (cos a, sin a). R^2 rays (1024),
// mirrored across the y axis to 2 R^2 by symmetry.
// Fields: F equidistant angles 0..hfov in the y-z plane (21). A ray of field theta starts on the
// entrance-pupil plane z_EP at (R_EP x_p', R_EP y_p') with direction (0, sin theta, cos theta).
//
// Ray aiming (supplement "Ray Aiming"): the stop radius R_s is the height at the stop of the real
// on-axis marginal ray (reference wavelength 587.6 nm). For each field and wavelength the upper
// (0, +1), lower (0, -1) and sagittal (1, 0) pupil rays are traced to the stop; with their stop
// coordinates and d(stop)/d(pupil) from an inner Jet (so the aiming itself is differentiable):
//   top' = 1 + (R_s - y_top) / (dy/dy_p),  bottom' = -1 + (-R_s - y_bot) / (dy/dy_p),
//   side' = 1 + (R_s - x_side) / (dx/dx_p);
//   x_p' = side' x_p,  y_p' = (top' + bottom') / 2 + (top' - bottom') / 2 y_p.
// One iteration, as in the paper.
#pragma once

#include <ceres/jet.h>

#include <array>
#include <cmath>
#include <vector>

#include "lensopt/core/scalar.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/trace_lens.h"

namespace lensopt {

inline constexpr double kPi = 3.14159265358979323846;

// Sampling and tracing options (validated by validate()).
struct TraceOptions {
  int rings = 32;             // pupil rings; rings^2 rays on the half pupil
  int fields = 21;            // field angles from 0 to hfov
  bool ray_aiming = true;     // the paper's one-step ray aiming
  bool scale_to_spec = true;  // scale the prescription to the spec focal length
  int threads = 0;            // 0: all cores (OpenMP)

  // Throws Error for out-of-range values.
  void validate() const;
};

// Normalized half-pupil sample coordinates.
struct PupilSamples {
  std::vector<double> x, y;
  std::size_t size() const { return x.size(); }
};
PupilSamples paper_pupil_samples(int rings);

// `count` samples on the edge of the half pupil (r = 1), azimuths from -90 to +90 deg inclusive:
// the meridional top and bottom rays and the sagittal ray are among them for odd counts.
PupilSamples pupil_edge_samples(int count);

// Field angles (deg): count equidistant values from 0 to half_field_deg.
std::vector<double> field_angles_deg(double half_field_deg, int count);

// The aimed pupil of one field and wavelength: x_p' = scale_x x_p, y_p' = offset_y + scale_y y_p.
template <typename T>
struct PupilMap {
  T scale_x;
  T offset_y;
  T scale_y;
};

template <typename T>
struct TraceSystem {
  TraceLens<T> lens;      // scaled prescription
  T scale;                // scale factor applied to the prescription
  T efl_mm;               // at the reference wavelength (587.6 nm)
  T bfl_mm;
  T epd_mm;               // entrance pupil diameter = EFL / N
  T entrance_pupil_z_mm;  // from the first vertex
  T stop_radius_mm;       // real on-axis marginal ray height at the stop
  std::vector<double> fields_deg;
  // Aimed pupils, [field * (W + 1) + w]; w = W is the reference wavelength (587.6 nm).
  std::vector<PupilMap<T>> pupil_maps;
  int wavelength_count = 0;  // W: the spec wavelengths (the reference one is extra)

  const PupilMap<T>& pupil_map(int h, int w) const {
    return pupil_maps[static_cast<std::size_t>(h) * (wavelength_count + 1) + w];
  }
  PupilSamples pupil;
};

namespace detail {

// Traces the upper, lower and sagittal pupil rays of one field and wavelength to the stop,
// returning stop coordinates and their derivatives with respect to the pupil coordinate.
template <typename T>
void trace_aiming_rays(const TraceLens<ceres::Jet<T, 1>>& lens_a, int w, const T& sin_theta,
                       const T& cos_theta, const T& r_ep, const T& z_ep, const PupilMap<T>& map,
                       T stop_coord[3], T stop_derivative[3]) {
  using J = ceres::Jet<T, 1>;
  RayBundle<J> rays;
  rays.resize(3);
  // Pupil coordinates (x_p, y_p) as inner Jets: top and bottom seed y_p, the sagittal x_p.
  const J top_y(map.offset_y + map.scale_y, 0);
  const J bottom_y(map.offset_y - map.scale_y, 0);
  const J side_x(map.scale_x, 0);
  const J zero = K<J>(0.0);
  const J r(r_ep);
  rays.x[0] = zero;
  rays.y[0] = r * top_y;
  rays.x[1] = zero;
  rays.y[1] = r * bottom_y;
  rays.x[2] = r * side_x;
  rays.y[2] = r * J(map.offset_y);
  for (int i = 0; i < 3; ++i) {
    rays.z[i] = J(z_ep);
    rays.l[i] = zero;
    rays.m[i] = J(sin_theta);
    rays.n[i] = J(cos_theta);
  }
  trace_bundle(lens_a, w, lens_a.stop + 1, false, rays, static_cast<RayRecord<J>*>(nullptr));
  stop_coord[0] = rays.y[0].a;
  stop_derivative[0] = rays.y[0].v[0];
  stop_coord[1] = rays.y[1].a;
  stop_derivative[1] = rays.y[1].v[0];
  stop_coord[2] = rays.x[2].a;
  stop_derivative[2] = rays.x[2].v[0];
}

}  // namespace detail

// The three aimed rays (upper, lower, sagittal) of field h and wavelength w traced to the stop:
// their stop coordinates y_top, y_bottom, x_side (mm) under the system's pupil map.
template <typename T>
std::array<T, 3> aimed_stop_coordinates(const TraceSystem<T>& sys, int h, int w) {
  using std::cos;
  using std::sin;
  using J = ceres::Jet<T, 1>;
  const TraceLens<J> lens_a =
      convert_trace_lens<J>(sys.lens, {}, 0, 0, [](double v, int) { return K<J>(v); });
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  T coord[3], deriv[3];
  detail::trace_aiming_rays<T>(lens_a, w, K<T>(sin(theta)), K<T>(cos(theta)),
                               sys.epd_mm / K<T>(2.0), sys.entrance_pupil_z_mm, sys.pupil_map(h, w),
                               coord, deriv);
  return {coord[0], coord[1], coord[2]};
}

// Prepares a lens for tracing. `focal_length_mm` is the spec focal length (used when scaling),
// `f_number` the spec f-number, fields from 0 to `half_field_deg`.
template <typename T>
TraceSystem<T> prepare_system(const TraceLens<T>& lens_in, double focal_length_mm,
                              double f_number, double half_field_deg,
                              const TraceOptions& options) {
  using std::cos;
  using std::sin;
  TraceSystem<T> sys;
  sys.lens = lens_in;
  const int reference_w = static_cast<int>(lens_in.wavelengths_nm.size()) - 1;  // 587.6 nm
  const double reference_nm = lens_in.wavelengths_nm[reference_w];
  ParaxialData<T> par = paraxial_data(sys.lens, reference_nm);
  sys.scale = options.scale_to_spec ? K<T>(focal_length_mm) / par.efl_mm : K<T>(1.0);
  if (options.scale_to_spec) {
    sys.lens.scale_lengths(sys.scale);
    par = paraxial_data(sys.lens, reference_nm);
  }
  sys.efl_mm = par.efl_mm;
  sys.bfl_mm = par.bfl_mm;
  sys.entrance_pupil_z_mm = par.entrance_pupil_z_mm;
  sys.epd_mm = par.efl_mm / K<T>(f_number);
  const T r_ep = sys.epd_mm / K<T>(2.0);
  sys.wavelength_count = reference_w;
  sys.fields_deg = field_angles_deg(half_field_deg, options.fields);
  sys.pupil = paper_pupil_samples(options.rings);

  // Stop radius from the real on-axis marginal ray at the reference wavelength.
  {
    RayBundle<T> marginal;
    marginal.resize(1);
    marginal.x[0] = K<T>(0.0);
    marginal.y[0] = r_ep;
    marginal.z[0] = sys.entrance_pupil_z_mm;
    marginal.l[0] = K<T>(0.0);
    marginal.m[0] = K<T>(0.0);
    marginal.n[0] = K<T>(1.0);
    trace_bundle(sys.lens, reference_w, sys.lens.stop + 1, false, marginal,
                 static_cast<RayRecord<T>*>(nullptr));
    sys.stop_radius_mm = marginal.y[0];
  }

  const int field_count = static_cast<int>(sys.fields_deg.size());
  const int wl = sys.wavelength_count + 1;  // aim the reference wavelength too
  const PupilMap<T> identity{K<T>(1.0), K<T>(0.0), K<T>(1.0)};
  sys.pupil_maps.assign(static_cast<std::size_t>(field_count) * wl, identity);
  if (!options.ray_aiming) return sys;

  using J = ceres::Jet<T, 1>;
  const TraceLens<J> lens_a = convert_trace_lens<J>(
      sys.lens, {}, 0, 0, [](double v, int) { return K<J>(v); });
  const T r_s = sys.stop_radius_mm;
  for (int h = 0; h < field_count; ++h) {
    const double theta = sys.fields_deg[h] * kPi / 180.0;
    if (h == 0) continue;  // on axis the pupil is not aberrated by definition of R_s
    for (int w = 0; w < wl; ++w) {
      T coord[3], deriv[3];
      detail::trace_aiming_rays<T>(lens_a, w, K<T>(sin(theta)), K<T>(cos(theta)), r_ep,
                                   sys.entrance_pupil_z_mm, identity, coord, deriv);
      const T top = K<T>(1.0) + (r_s - coord[0]) / deriv[0];
      const T bottom = K<T>(-1.0) + (-r_s - coord[1]) / deriv[1];
      const T side = K<T>(1.0) + (r_s - coord[2]) / deriv[2];
      PupilMap<T>& map = sys.pupil_maps[static_cast<std::size_t>(h) * wl + w];
      map.scale_x = side;
      map.offset_y = (top + bottom) / K<T>(2.0);
      map.scale_y = (top - bottom) / K<T>(2.0);
    }
  }
  return sys;
}

// Fills `rays` with rays of field h and wavelength w at the entrance pupil, for normalized pupil
// samples `pupil` (default: the system's half-pupil pattern) under the aimed pupil map.
template <typename T>
void start_rays(const TraceSystem<T>& sys, int h, int w, RayBundle<T>& rays,
                const PupilSamples* samples = nullptr) {
  using std::cos;
  using std::sin;
  const PupilSamples& pupil = samples ? *samples : sys.pupil;
  const std::size_t count = pupil.size();
  rays.resize(count);
  const PupilMap<T>& map = sys.pupil_map(h, w);
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  const T r_ep = sys.epd_mm / K<T>(2.0);
  const T sx = r_ep * map.scale_x;
  const T sy = r_ep * map.scale_y;
  const T oy = r_ep * map.offset_y;
  const T m0 = K<T>(sin(theta));
  const T n0 = K<T>(cos(theta));
  const T l0 = K<T>(0.0);
  for (std::size_t i = 0; i < count; ++i) {
    rays.x[i] = sx * K<T>(pupil.x[i]);
    rays.y[i] = oy + sy * K<T>(pupil.y[i]);
    rays.z[i] = sys.entrance_pupil_z_mm;
    rays.l[i] = l0;
    rays.m[i] = m0;
    rays.n[i] = n0;
  }
}

}  // namespace lensopt

namespace lensopt {

// prepare_system with the specs of a lens (focal length, f-number, half field).
template <typename T>
TraceSystem<T> prepare_system(const TraceLens<T>& lens, const Specs& specs,
                              const TraceOptions& options) {
  return prepare_system(lens, specs.focal_length_mm(), specs.f_number, specs.half_field_deg,
                        options);
}

}  // namespace lensopt
