// A lens prepared for real-ray tracing at the paper's sampling: scaled to the spec focal
// length, with its paraxial entrance pupil, the real stop radius and the ray-aiming pupil maps.
//
// Pupil sampling (paper, "Geometrical PSFs"): R rings (32) on the half pupil x >= 0; ring
// i = 0..R-1 has 2i+1 rays at azimuths a_j = ((j + 1/2) / (2i+1) - 1/2) pi and normalized radius
//   r = 2i / (2R-1) + ((k + i) mod 2) / (2R-1),
// k the ray's running index over all rings; (x_p, y_p) = r (cos a, sin a). R^2 rays (1024),
// mirrored across the y axis to 2 R^2 by symmetry. When a field's vignetting factors break that
// symmetry (VDX or VAN set, lens.h), the system traces the full pupil instead: the R^2 samples and
// their mirrors (-x_p, y_p), 2 R^2 rays of equal weight (TraceSystem::full_pupil), every field.
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
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "lensopt/core/constants.h"
#include "lensopt/core/jet_width.h"
#include "lensopt/core/scalar.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/kernel.h"

namespace lensopt {

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

// The full pupil of half-pupil samples: the samples, then their mirrors (-x, y) in the same order
// (2 N samples; a sample on x = 0 appears twice, as in the mirrored half pupil).
PupilSamples mirrored_pupil(const PupilSamples& half);

// True when some field's vignetting factors are not mirror-symmetric about the meridional plane
// (VDX or VAN set): the system then traces full pupils (TraceSystem::full_pupil).
bool needs_full_pupil(const std::vector<VignettingFactors>& vignetting);

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
  TraceLens<T> lens;  // scaled prescription
  T scale;            // scale factor applied to the prescription
  T efl_mm;           // at the reference wavelength (587.6 nm)
  T bfl_mm;
  T epd_mm;                        // entrance pupil diameter = EFL / N
  T entrance_pupil_z_mm;           // from the first vertex
  T stop_radius_mm;                // real on-axis marginal ray height at the stop
  std::vector<double> fields_deg;  // chief-ray angle in object space per field
  // Per field, the angle (deg, from +y towards +x) of the field point in the object's x-y plane
  // (FieldPoint::azimuth_deg), or empty: every field on the y axis. Every field is traced in its
  // own frame, the lens frame turned about z by this angle so that the field lies on +y, and
  // every traced coordinate (spots, centroids, references) is in that frame: a rotationally
  // symmetric lens is traced as in the y-z plane (the same bits), a lens with 3D placements
  // turns its rays into the lens frame and back (RayBundle::frame_cos, set by start_rays and
  // set_field_frame). field_to_lens turns a field-frame point into the lens (image) frame.
  std::vector<double> field_azimuth_deg;
  double field_azimuth(int h) const {
    return h < static_cast<int>(field_azimuth_deg.size()) ? field_azimuth_deg[h] : 0.0;
  }
  // (u, v) in field h's frame -> (x, y) in the lens frame: x = u c + v s, y = v c - u s.
  void field_to_lens(int h, double u, double v, double& x, double& y) const {
    const double a = field_azimuth(h);
    if (a == 0.0) {
      x = u;
      y = v;
      return;
    }
    const double c = std::cos(a * kPi / 180.0), s = std::sin(a * kPi / 180.0);
    x = u * c + v * s;
    y = v * c - u * s;
  }
  // The fields as written (deg or mm, field_type), their weights and vignetting factors.
  std::vector<double> field_values;
  FieldType field_type = FieldType::kAngle;
  std::vector<double> field_weights;
  std::vector<VignettingFactors> vignetting;
  // Object distance from surface 1 (infinite: collimated fields) and, for a finite object, the
  // object point's height per field (rays start on the entrance pupil aimed from it).
  double object_distance_mm = std::numeric_limits<double>::infinity();
  std::vector<double> field_object_y_mm;
  bool object_at_infinity() const { return !std::isfinite(object_distance_mm); }
  // Empty, or why a field given by real image height has no chief-ray angle (the real chief ray
  // cannot reach that height: see prepare_system). prepare_lens_system throws it naming the file;
  // the system keeps the angle of the closest height reached.
  std::string field_solve_failure;
  // Aimed pupils, [field * (W + 1) + w]; w = W is the reference wavelength (587.6 nm).
  std::vector<PupilMap<T>> pupil_maps;
  int wavelength_count = 0;  // W: the spec wavelengths (the reference one is extra)
  // The spec wavelengths' weights as written (W values), or empty: equal weights.
  std::vector<double> wavelength_weights;

  const PupilMap<T>& pupil_map(int h, int w) const {
    return pupil_maps[static_cast<std::size_t>(h) * (wavelength_count + 1) + w];
  }
  // The pupil samples every field is traced with: the half pupil x_p >= 0 (each ray standing for
  // itself and its mirror (-x_p, y_p), whose image is the mirror (-x, y)), or, when full_pupil,
  // the full pupil (mirrored_pupil: the half and its mirror, each ray for itself).
  PupilSamples pupil;
  bool full_pupil = false;
  // Half-pupil samples as this system traces them: `half`, or its mirrored_pupil when full_pupil.
  PupilSamples samples_for(const PupilSamples& half) const {
    return full_pupil ? mirrored_pupil(half) : half;
  }
};

namespace detail {

// Direction cosines of a ray from field h's object point through (x, y, z_ep): collimated at the
// chief angle for an object at infinity, else from the object point (0, y_obj, -d).
template <typename T>
void field_ray_direction(double object_distance_mm, double sin_theta, double cos_theta,
                         double object_y_mm, const T& x, const T& y, const T& z_ep, T& l, T& m,
                         T& n) {
  using std::sqrt;
  if (!std::isfinite(object_distance_mm)) {
    l = K<T>(0.0);
    m = K<T>(sin_theta);
    n = K<T>(cos_theta);
    return;
  }
  const T dx = x;
  const T dy = y - K<T>(object_y_mm);
  const T dz = z_ep + K<T>(object_distance_mm);
  const T inv = K<T>(1.0) / sqrt(dx * dx + dy * dy + dz * dz);
  l = dx * inv;
  m = dy * inv;
  n = dz * inv;
}

}  // namespace detail

// Sets the frame of a bundle of field h's rays (RayBundle::frame_cos): turned by the field's
// azimuth on a lens with 3D placements, else none (the symmetric path needs no turn).
template <typename System, typename Bundle>
void set_field_frame(const System& sys, int h, Bundle& rays) {
  const double a = sys.field_azimuth(h);
  if (a == 0.0 || !sys.lens.geometry.placed()) {
    rays.frame_cos = 1.0;
    rays.frame_sin = 0.0;
    return;
  }
  rays.frame_cos = std::cos(a * kPi / 180.0);
  rays.frame_sin = std::sin(a * kPi / 180.0);
}

// The one pupil-ray constructor: ray i of `rays` starts at the entrance-pupil point (x, y, z_ep)
// (mm) in the direction of a field, (0, sin theta, cos theta) for an object at infinity, else
// from the object point (0, object_y, -d) through the pupil point (detail::field_ray_direction).
template <typename T>
void start_pupil_ray(RayBundle<T>& rays, std::size_t i, const T& x, const T& y, const T& z_ep,
                     double object_distance_mm, double sin_theta, double cos_theta,
                     double object_y_mm) {
  rays.x[i] = x;
  rays.y[i] = y;
  rays.z[i] = z_ep;
  detail::field_ray_direction(object_distance_mm, sin_theta, cos_theta, object_y_mm, rays.x[i],
                              rays.y[i], rays.z[i], rays.l[i], rays.m[i], rays.n[i]);
}

namespace detail {

// Traces the upper, lower and sagittal pupil rays of field h and wavelength w to the stop,
// returning stop coordinates and their derivatives with respect to the pupil coordinate.
template <typename T, typename System>
void trace_aiming_rays(const TraceLens<ceres::Jet<T, 1>>& lens_a, int w, const System& sys, int h,
                       const T& r_ep, const T& z_ep, const PupilMap<T>& map, T stop_coord[3],
                       T stop_derivative[3], RayBundle<ceres::Jet<T, 1>>* scratch = nullptr) {
  using J = ceres::Jet<T, 1>;
  RayBundle<J> local;
  RayBundle<J>& rays = scratch ? *scratch : local;  // a reused bundle allocates nothing
  rays.resize(3);
  // Pupil coordinates (x_p, y_p) as inner Jets: top and bottom seed y_p, the sagittal x_p.
  const J top_y(map.offset_y + map.scale_y, 0);
  const J bottom_y(map.offset_y - map.scale_y, 0);
  const J side_x(map.scale_x, 0);
  const J zero = K<J>(0.0);
  const J r(r_ep);
  const J x[3] = {zero, zero, r * side_x};
  const J y[3] = {r * top_y, r * bottom_y, r * J(map.offset_y)};
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  for (int i = 0; i < 3; ++i)
    start_pupil_ray(rays, i, x[i], y[i], J(z_ep), sys.object_distance_mm, std::sin(theta),
                    std::cos(theta), sys.field_object_y_mm[h]);
  set_field_frame(sys, h, rays);
  trace_bundle(lens_a, w, lens_a.stop + 1, false, rays, static_cast<RayRecord<J>*>(nullptr));
  stop_coord[0] = rays.y[0].a;
  stop_derivative[0] = rays.y[0].v[0];
  stop_coord[1] = rays.y[1].a;
  stop_derivative[1] = rays.y[1].v[0];
  stop_coord[2] = rays.x[2].a;
  stop_derivative[2] = rays.x[2].v[0];
}

// On the Jets of core/jet_width.h, trace_aiming_rays is specialized in src/trace/system_jet.cpp.in
// (the aiming on nested duals, trace/aiming_jet.h: the same bits); declared here so that no file
// instantiates the template above on them.
#define LENSOPT_AIMING_RAYS_JET(N)                                                   \
  template <>                                                                        \
  void trace_aiming_rays<ceres::Jet<double, N>, TraceSystem<ceres::Jet<double, N>>>( \
      const TraceLens<ceres::Jet<ceres::Jet<double, N>, 1>>&, int,                   \
      const TraceSystem<ceres::Jet<double, N>>&, int, const ceres::Jet<double, N>&,  \
      const ceres::Jet<double, N>&, const PupilMap<ceres::Jet<double, N>>&,          \
      ceres::Jet<double, N>[3], ceres::Jet<double, N>[3],                            \
      RayBundle<ceres::Jet<ceres::Jet<double, N>, 1>>*);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_AIMING_RAYS_JET)
#undef LENSOPT_AIMING_RAYS_JET

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
  (void)theta;
  detail::trace_aiming_rays<T>(lens_a, w, sys, h, sys.epd_mm / K<T>(2.0), sys.entrance_pupil_z_mm,
                               sys.pupil_map(h, w), coord, deriv);
  return {coord[0], coord[1], coord[2]};
}

namespace detail {

// The chief-ray slope t = tan(theta) whose real image height height(t) equals v (v != 0), from
// the paraxial estimate t_guess. height(0) = 0 and height is taken increasing in |t| up to where
// the ray fails (height returns NaN there). Secant steps, kept inside the bracket [lo, hi] of a
// sign change once one is known (a step outside it bisects), and, before one is known, extended
// outwards (doubling, halving back towards lo where the ray fails). Converged when
// |height(t) - v| <= 1e-13 |v| or when the bracket has shrunk to a few ulps. Returns false if no
// slope reaches v before the ray fails or 89 deg; `t` is then the slope of the closest height
// reached and `best_height` that height.
template <typename Height>
bool solve_real_image_height(const Height& height, double v, double t_guess, double& t,
                             double& best_height) {
  const double s = v < 0.0 ? -1.0 : 1.0;  // work with g(u) = s (height(s u) - v), u >= 0
  const double target = std::abs(v);
  const double tol = 1e-13 * target;
  const double u_max = std::tan(89.0 * kPi / 180.0);
  double lo = 0.0;    // g(lo) < 0 (g(0) = -|v|)
  double hi = u_max;  // g(hi) > 0 when have_hi
  bool have_hi = false;
  double fail_u = std::numeric_limits<double>::infinity();  // smallest slope seen to fail
  double u = std::abs(t_guess) > 0.0 ? std::abs(t_guess) : 1e-3;
  double u_prev = 0.0, g_prev = -target;  // last finite point (secant)
  double best_u = 0.0, best_g = -target;
  for (int it = 0; it < 200; ++it) {
    const double y = height(s * u);
    if (!std::isfinite(y)) {
      fail_u = std::min(fail_u, u);
      hi = std::min(hi, u);
      u = 0.5 * (lo + u);  // back towards the last slope below the target
      continue;
    }
    const double g = s * y - target;
    if (std::abs(g) < std::abs(best_g)) {
      best_u = u;
      best_g = g;
    }
    if (std::abs(g) <= tol) break;
    if (g < 0.0) {
      lo = u;
    } else {
      hi = u;
      have_hi = true;
    }
    if (have_hi && hi - lo <= 4.0 * std::numeric_limits<double>::epsilon() * hi) break;
    double next = g != g_prev ? u - g * (u - u_prev) / (g - g_prev) : -1.0;
    u_prev = u;
    g_prev = g;
    if (have_hi) {
      if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);  // bisect the bracket
    } else if (!(next > lo) || !(next < fail_u) || !std::isfinite(next)) {
      next = std::isfinite(fail_u) ? 0.5 * (lo + fail_u) : 2.0 * lo;
    }
    if (!(next < u_max)) next = 0.5 * (lo + u_max);
    if (next == u) break;  // no representable progress
    u = next;
  }
  t = s * best_u;
  best_height = s * (best_g + target);
  return std::abs(best_g) <= tol ||
         (have_hi && hi - lo <= 4.0 * std::numeric_limits<double>::epsilon() * hi &&
          std::abs(best_g) <= 1e-9 * std::max(target, 1.0));
}

}  // namespace detail

// What prepare_system sets up: the paper's mode (scale to a focal length, EPD = EFL / N,
// fields 0..hfov) or a lens's own system data (SpecMode::kAsWritten, see lens.h).
struct SystemSetup {
  bool scale = true;  // scale the prescription to focal_length_mm
  double focal_length_mm = 0.0;
  ApertureType aperture_type = ApertureType::kFNumber;
  double f_number = 2.0;               // kFNumber
  double aperture_value = 0.0;         // EPD (mm) or object NA
  double stop_semi_diameter_mm = 0.0;  // kFloatByStop
  double object_distance_mm = std::numeric_limits<double>::infinity();
  FieldType field_type = FieldType::kAngle;
  std::vector<double> field_values;  // deg or mm, as the type says
  std::vector<double> field_weights;
  std::vector<VignettingFactors> vignetting;  // per field, or empty
  std::vector<double> wavelength_weights;     // per spec wavelength, or empty: equal
  std::vector<double> field_azimuth_deg;  // per field (TraceSystem::field_azimuth_deg), or empty
};

// The paper's setup: scale to f, EPD = f / N, `field_count` angles from 0 to hfov.
SystemSetup paper_setup(double focal_length_mm, double f_number, double half_field_deg,
                        int field_count);
// The setup of a lens's specs: the paper's in SpecMode::kPaper, else the written system data
// (fields as written, sorted by value; without written fields 0 and half_field_deg sampled as
// the paper does). `scale_to_spec` = false turns the paper's scaling off.
SystemSetup lens_setup(const Lens& lens, const TraceOptions& options);

// The number of systems prepare_system has prepared in this process (any scalar): a debug
// counter, so tests can check that a command prepares its system once (a render: once per lens).
inline std::atomic<long> prepared_system_count{0};

// Prepares a lens for tracing with a setup (see SystemSetup).
template <typename T>
TraceSystem<T> prepare_system(const TraceLens<T>& lens_in, const SystemSetup& setup,
                              const TraceOptions& options) {
  prepared_system_count.fetch_add(1, std::memory_order_relaxed);
  using std::atan;
  using std::cos;
  using std::sin;
  using std::tan;
  TraceSystem<T> sys;
  sys.lens = lens_in;
  const int reference_w = static_cast<int>(lens_in.wavelengths_nm.size()) - 1;  // primary
  const double reference_nm = lens_in.wavelengths_nm[reference_w];
  ParaxialData<T> par = paraxial_data(sys.lens, reference_nm);
  sys.scale = setup.scale ? spec_scale(setup.focal_length_mm, par.efl_mm) : K<T>(1.0);
  if (setup.scale) {
    sys.lens.scale_lengths(sys.scale);
    for (double& r : sys.lens.semi_diameter_mm) r *= value_of(sys.scale);
    par = paraxial_data(sys.lens, reference_nm);
  }
  sys.efl_mm = par.efl_mm;
  sys.bfl_mm = par.bfl_mm;
  sys.entrance_pupil_z_mm = par.entrance_pupil_z_mm;
  sys.object_distance_mm = setup.object_distance_mm;
  const double z_ep = value_of(par.entrance_pupil_z_mm);
  switch (setup.aperture_type) {
    case ApertureType::kFNumber:
      sys.epd_mm = par.efl_mm / K<T>(setup.f_number);
      break;
    case ApertureType::kEntrancePupilDiameter:
      sys.epd_mm = K<T>(setup.aperture_value);
      break;
    case ApertureType::kObjectNA: {
      const double u = std::asin(setup.aperture_value);
      sys.epd_mm =
          K<T>(2.0 * std::tan(u)) * (par.entrance_pupil_z_mm + K<T>(setup.object_distance_mm));
      break;
    }
    case ApertureType::kFloatByStop:
      sys.epd_mm =
          K<T>(2.0 * setup.stop_semi_diameter_mm * value_of(sys.scale)) / par.stop_magnification;
      break;
  }
  using std::abs;
  if (value_of(sys.epd_mm) < 0.0) sys.epd_mm = -sys.epd_mm;
  const T r_ep = sys.epd_mm / K<T>(2.0);
  sys.wavelength_count = reference_w;
  if (static_cast<int>(setup.wavelength_weights.size()) == reference_w)
    sys.wavelength_weights = setup.wavelength_weights;
  // A lens without rotational symmetry (3D placements, decentred apertures) has no mirror
  // symmetry about the meridional plane either: the full pupil, every field.
  sys.full_pupil = needs_full_pupil(setup.vignetting) || sys.lens.geometry.placed();
  sys.pupil = sys.samples_for(paper_pupil_samples(options.rings));

  // Fields: every written value as the chief-ray angle in object space (and, for a finite
  // object, the object point). Heights on the image are solved for: paraxially (linear in
  // tan(theta)), or on the real chief ray through the pupil centre, traced without clear
  // apertures (detail::solve_real_image_height: safeguarded secant to 1e-13 relative).
  const int field_count = static_cast<int>(setup.field_values.size());
  sys.field_values = setup.field_values;
  sys.field_type = setup.field_type;
  sys.field_weights = setup.field_weights;
  sys.vignetting = setup.vignetting;
  if (setup.field_azimuth_deg.size() == setup.field_values.size())
    sys.field_azimuth_deg = setup.field_azimuth_deg;
  if (sys.field_weights.size() != setup.field_values.size())
    sys.field_weights.assign(setup.field_values.size(), 1.0);
  if (sys.vignetting.size() != setup.field_values.size())
    sys.vignetting.assign(setup.field_values.size(), VignettingFactors{});
  const double d_obj = setup.object_distance_mm;
  const bool finite = std::isfinite(d_obj);
  const double paraxial_per_tan =
      value_of(paraxial_image_height(sys.lens, par.entrance_pupil_z_mm, K<T>(1.0), reference_nm));
  // Real chief-ray image height at tan(theta) (finite or not), reference wavelength, traced
  // without clear apertures: the chief ray through the pupil's centre defines the field whatever
  // vignetting does to it (a semi-diameter that clips it must not stop the solve).
  TraceLens<T> open_lens;
  if (setup.field_type == FieldType::kRealImageHeight) {
    open_lens = sys.lens;
    open_lens.semi_diameter_mm.clear();
  }
  int solving_field = 0;
  auto real_height = [&](double tan_theta) {
    RayBundle<T> chief;
    chief.resize(1);
    const double theta = std::atan(tan_theta);
    // Collimated at theta whatever the object distance: the field's direction is being solved.
    start_pupil_ray(chief, 0, K<T>(0.0), K<T>(0.0), par.entrance_pupil_z_mm,
                    std::numeric_limits<double>::infinity(), std::sin(theta), std::cos(theta), 0.0);
    set_field_frame(sys, solving_field, chief);
    trace_bundle(open_lens, reference_w, open_lens.surface_count(), true, chief,
                 static_cast<RayRecord<T>*>(nullptr));
    const double y = value_of(chief.y[0]);
    return chief.status[0] == kRayOk && std::isfinite(y) ? y : std::nan("");
  };
  sys.fields_deg.assign(field_count, 0.0);
  sys.field_object_y_mm.assign(field_count, 0.0);
  for (int h = 0; h < field_count; ++h) {
    const double v = setup.field_values[h];
    solving_field = h;
    double tan_theta = 0.0;
    switch (setup.field_type) {
      case FieldType::kAngle:
        tan_theta = std::tan(v * kPi / 180.0);
        break;
      case FieldType::kObjectHeight:
        tan_theta = finite ? v / (d_obj + z_ep) : 0.0;
        break;
      case FieldType::kParaxialImageHeight:
        tan_theta = paraxial_per_tan != 0.0 ? v / paraxial_per_tan : 0.0;
        break;
      case FieldType::kRealImageHeight: {
        tan_theta = paraxial_per_tan != 0.0 ? v / paraxial_per_tan : 0.0;
        if (v == 0.0) break;
        double reached = 0.0;
        if (!detail::solve_real_image_height(real_height, v, tan_theta, tan_theta, reached) &&
            sys.field_solve_failure.empty())
          sys.field_solve_failure = fmt::format(
              "field {} (real image height {:g} mm): no chief ray reaches that height; the "
              "closest is {:.6g} mm at {:.4f} deg (the chief ray fails or turns back beyond it)",
              h + 1, v, reached, std::atan(tan_theta) * 180.0 / kPi);
        break;
      }
    }
    // An angle field keeps its written value exactly.
    sys.fields_deg[h] =
        setup.field_type == FieldType::kAngle ? v : std::atan(tan_theta) * 180.0 / kPi;
    sys.field_object_y_mm[h] = finite ? -(d_obj + z_ep) * tan_theta : 0.0;
  }

  // Stop radius: the stop's semi-diameter (float by stop size), else the height at the stop of
  // the real on-axis marginal ray at the reference wavelength.
  {
    RayBundle<T> marginal;
    marginal.resize(1);
    start_pupil_ray(marginal, 0, K<T>(0.0), r_ep, sys.entrance_pupil_z_mm, d_obj, 0.0, 1.0, 0.0);
    trace_bundle(sys.lens, reference_w, sys.lens.stop + 1, false, marginal,
                 static_cast<RayRecord<T>*>(nullptr));
    sys.stop_radius_mm = marginal.y[0];
    if (setup.aperture_type == ApertureType::kFloatByStop)
      sys.stop_radius_mm = K<T>(setup.stop_semi_diameter_mm * value_of(sys.scale));
  }

  const int wl = sys.wavelength_count + 1;  // aim the reference wavelength too
  const PupilMap<T> identity{K<T>(1.0), K<T>(0.0), K<T>(1.0)};
  sys.pupil_maps.assign(static_cast<std::size_t>(field_count) * wl, identity);
  if (!options.ray_aiming) return sys;

  using J = ceres::Jet<T, 1>;
  const TraceLens<J> lens_a =
      convert_trace_lens<J>(sys.lens, {}, 0, 0, [](double v, int) { return K<J>(v); });
  const T r_s = sys.stop_radius_mm;
  RayBundle<J> aiming_rays;
  for (int h = 0; h < field_count; ++h) {
    // On axis the pupil of a rotationally symmetric lens is not aberrated by the definition of
    // R_s (unless R_s is given): the map stays the identity at every wavelength. A lens with 3D
    // placements (a decentred or tilted element) is not symmetric on axis: its upper and lower
    // rays meet the stop at different heights. Its axial field takes the map aimed at the
    // reference wavelength, the one R_s is defined at, for every wavelength: with zero
    // placements that map is the identity (to rounding), so a toleranced lens's merit is
    // continuous at its nominal, and the chromatic part stays unaimed as on a symmetric lens.
    const bool axial =
        sys.fields_deg[h] == 0.0 && setup.aperture_type != ApertureType::kFloatByStop;
    if (axial && !sys.lens.geometry.placed()) continue;
    for (int w = axial ? wl - 1 : 0; w < wl; ++w) {
      T coord[3], deriv[3];
      detail::trace_aiming_rays<T>(lens_a, w, sys, h, r_ep, sys.entrance_pupil_z_mm, identity,
                                   coord, deriv, &aiming_rays);
      const T top = K<T>(1.0) + (r_s - coord[0]) / deriv[0];
      const T bottom = K<T>(-1.0) + (-r_s - coord[1]) / deriv[1];
      const T side = K<T>(1.0) + (r_s - coord[2]) / deriv[2];
      PupilMap<T>& map = sys.pupil_maps[static_cast<std::size_t>(h) * wl + w];
      map.scale_x = side;
      map.offset_y = (top + bottom) / K<T>(2.0);
      map.scale_y = (top - bottom) / K<T>(2.0);
      if (axial) {
        // The sagittal ray on both sides (-x through the mirrored map): the map has no x
        // offset, so aiming +x alone would make it odd in an x decenter, and the merit with it.
        const PupilMap<T> mirrored{K<T>(-1.0), K<T>(0.0), K<T>(1.0)};
        detail::trace_aiming_rays<T>(lens_a, w, sys, h, r_ep, sys.entrance_pupil_z_mm, mirrored,
                                     coord, deriv, &aiming_rays);
        const T side_minus = K<T>(-1.0) + (-r_s - coord[2]) / deriv[2];
        map.scale_x = (side - side_minus) / K<T>(2.0);
      }
      if (axial)
        for (int v = 0; v + 1 < wl; ++v) sys.pupil_maps[static_cast<std::size_t>(h) * wl + v] = map;
    }
  }
  return sys;
}

// The paper's prepare_system: `focal_length_mm` is the spec focal length (used when scaling),
// `f_number` the spec f-number, options.fields angles from 0 to `half_field_deg`.
template <typename T>
TraceSystem<T> prepare_system(const TraceLens<T>& lens_in, double focal_length_mm, double f_number,
                              double half_field_deg, const TraceOptions& options) {
  SystemSetup setup = paper_setup(focal_length_mm, f_number, half_field_deg, options.fields);
  setup.scale = options.scale_to_spec;
  return prepare_system(lens_in, setup, options);
}

// Fills `rays` with rays of field h and wavelength w at the entrance pupil, for normalized pupil
// samples `pupil` (default: the system's pattern, sys.pupil) under the field's vignetting factors
// (px', py') = VignettingFactors::pupil_point(px, py) (lens.h) and then the aimed pupil map:
//   x = R_EP scale_x px',   y = R_EP (offset_y + scale_y py').
// This is the one place where pupil points get the vignetting factors. Without VDX and VAN the
// same map is taken factored (x = [R_EP scale_x (1 - VCX)] px, y = R_EP (offset_y + scale_y VDY)
// + [R_EP scale_y (1 - VCY)] py), as before those two were traced (the same bits).
template <typename T>
void start_rays(const TraceSystem<T>& sys, int h, int w, RayBundle<T>& rays,
                const PupilSamples* samples = nullptr) {
  const PupilSamples& pupil = samples ? *samples : sys.pupil;
  const std::size_t count = pupil.size();
  rays.resize(count);
  set_field_frame(sys, h, rays);
  const PupilMap<T>& map = sys.pupil_map(h, w);
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  const double sin_t = std::sin(theta), cos_t = std::cos(theta);
  const VignettingFactors v =
      h < static_cast<int>(sys.vignetting.size()) ? sys.vignetting[h] : VignettingFactors{};
  const T r_ep = sys.epd_mm / K<T>(2.0);
  const double object_y = sys.field_object_y_mm.empty() ? 0.0 : sys.field_object_y_mm[h];
  if (v.asymmetric()) {
    const T ax = r_ep * map.scale_x;
    const T ay = r_ep * map.scale_y;
    const T oy0 = r_ep * map.offset_y;
    double qx = 0.0, qy = 0.0;
    for (std::size_t i = 0; i < count; ++i) {
      v.pupil_point(pupil.x[i], pupil.y[i], qx, qy);
      start_pupil_ray(rays, i, ax * K<T>(qx), oy0 + ay * K<T>(qy), sys.entrance_pupil_z_mm,
                      sys.object_distance_mm, sin_t, cos_t, object_y);
    }
    return;
  }
  const T sx = r_ep * map.scale_x * K<T>(1.0 - v.vcx);
  const T sy = r_ep * map.scale_y * K<T>(1.0 - v.vcy);
  const T oy = r_ep * (map.offset_y + map.scale_y * K<T>(v.vdy));
  for (std::size_t i = 0; i < count; ++i)
    start_pupil_ray(rays, i, sx * K<T>(pupil.x[i]), oy + sy * K<T>(pupil.y[i]),
                    sys.entrance_pupil_z_mm, sys.object_distance_mm, sin_t, cos_t, object_y);
}

}  // namespace lensopt

namespace lensopt {

// The setup of specs alone (no stop semi-diameter: kFloatByStop needs lens_setup).
// A field off the y axis (FieldPoint::x != 0) keeps its azimuth; on a lens without rotational
// symmetry (`rotational` false) so does a field on -y (azimuth 180 deg), which a rotationally
// symmetric lens traces as the field on +y.
SystemSetup specs_setup(const Specs& specs, const TraceOptions& options, bool rotational = true);

// prepare_system with the specs of a lens (its spec mode, see lens.h).
template <typename T>
TraceSystem<T> prepare_system(const TraceLens<T>& lens, const Specs& specs,
                              const TraceOptions& options) {
  return prepare_system(lens, specs_setup(specs, options, !lens.geometry.placed()), options);
}

// The one way from a Lens to a traced system: make_trace_lens and its spec mode. Throws Error
// naming the lens's file when a field by real image height cannot be reached
// (TraceSystem::field_solve_failure).
TraceSystem<double> prepare_lens_system(const Lens& lens, const TraceOptions& options);

// The scale prepare_lens_system applies to a lens (TraceSystem::scale): f_spec / EFL at the
// primary wavelength in the paper's spec mode, 1 in the as-written mode. NaN or infinite for a
// lens without power.
double lens_spec_scale(const Lens& lens);

// prepare_system on the Jets of core/jet_width.h is compiled once per width, in a translation unit
// of its own (src/trace/system_jet.cpp.in).
#define LENSOPT_PREPARE_SYSTEM_JET(N)                                                       \
  extern template TraceSystem<ceres::Jet<double, N>> prepare_system<ceres::Jet<double, N>>( \
      const TraceLens<ceres::Jet<double, N>>&, const SystemSetup&, const TraceOptions&);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_PREPARE_SYSTEM_JET)
#undef LENSOPT_PREPARE_SYSTEM_JET
// prepare_system on double (with its ray aiming and field solves) is compiled once, in
// src/trace/system_double.cpp, not in each of the 40-odd objects that prepare a system.
extern template TraceSystem<double> prepare_system<double>(const TraceLens<double>&,
                                                           const SystemSetup&, const TraceOptions&);

}  // namespace lensopt
