// The mean RMS spot and its gradient by reverse mode (adjoint): the same derivative as
// analysis/gradient.h (forward-mode Jets through everything) at the cost of a few double traces.
//
// Split of the pipeline:
//   1. Lens level, in Jets (few rays): the prescription seeded with the variables, scaling to the
//      spec focal length, paraxial pupil and stop radius (prepare_system on ceres::Jet<double, N>
//      without the ray aiming, whose maps and adjoint come from one taped trace in double:
//      trace/aiming_adjoint.h). It gives every parameter the ray trace reads as a Jet over the
//      variables: per surface k, c_k and t_k; per surface and wavelength mu_{k,w} = n_{k-1}/n_k;
//      per field h and wavelength w the ray start x = s_x p_x, y = o_y + s_y p_y, z = z_EP with
//      s_x = R_EP sx_hw, o_y = R_EP oy_hw, s_y = R_EP sy_hw (system.h's pupil map: R_EP and z_EP
//      as Jets, the map entries as doubles with their adjoint from the taped aiming).
//   2. Every ray in double: field by field, a forward trace of all wavelengths gives the field's
//      spot S_h, centroid ybar_h and weight sum M_h (analysis/spot.h's weighted definition); then
//      per wavelength a taped forward trace and the backward pass (trace/adjoint.h) with the
//      seeds of L = sum_h phi_h S_h / sum_h phi_h (omega_w, phi_h the normalized weights):
//        dL/dY_i = phi_h omega_w (Y_i - ybar_h) / (Phi M_h S_h),   dL/dX_i = phi_h omega_w (X_i -
//        xbar_h) / (...)
//      (Phi = sum_h phi_h; xbar_h = 0 on a mirrored half pupil; the centroids' own derivatives
//      drop out: sum_i omega_w (Y_i - ybar_h) = 0), 0 for failed rays and for fields with S_h = 0.
//      The backward pass sums the adjoints a_c, a_t, a_mu per surface and, with the field's
//      vignetted pupil point (px', py') = VignettingFactors::pupil_point(p_x, p_y) (x0 = s_x px',
//      y0 = o_y + s_y py', start_rays), a_sx = sum_i a_x0,i px'_i, a_oy = sum_i a_y0,i, a_sy =
//      sum_i a_y0,i py'_i, a_zEP = sum_i a_z0,i per (field, wavelength). Per-field sums are added
//      in field order (deterministic).
//   3. Chain rule with the Jets of step 1: dL/dv_j = sum over parameters P of a_P dP/dv_j, the
//      map entries' a_P passed on by aim_pupil_maps_adjoint to the parameters of the aiming
//      trace (the scaled lens, R_EP, z_EP, R_s), which are Jets of step 1.
// Supported: spherical, conic and even-asphere surfaces (the kernel of trace/kernel.h and the
// profiles of trace/profile.h; the profile's backward step in trace/adjoint.h), with clear
// apertures, obscurations, mirrors, 3D placements, coordinate breaks and fields off the y axis
// (the placed path's backward steps in trace/adjoint.h); adjoint_supported() says when, and
// mean_spot_gradient_fast falls back to the Jet path otherwise. A placed lens's decenters scale
// with the prescription (spec scaling), so their adjoints are chained like the radii's; the tilts
// and the aperture centres are constants. The conic constant and the asphere terms are parameters
// like c_k (their adjoints a_k, a_a2i per surface, chained through their Jets in step 3).
#pragma once

#include <ceres/jet.h>

#include <vector>

#include "lensopt/analysis/gradient.h"
#include "lensopt/trace/adjoint.h"
#include "lensopt/trace/aiming_adjoint.h"

namespace lensopt {

// Adjoints of a scalar of the traced rays with respect to the double parameters of a system.
struct SystemAdjoint {
  double value = 0.0;             // the scalar (mean spot, mm)
  std::vector<double> curvature;  // K
  std::vector<double> thickness;  // K
  std::vector<double> mu;         // [w * K + k], w < W (the spec wavelengths)
  std::vector<double> start;      // [(h * W + w) * 4 + j]: j = s_x, o_y, s_y, z_EP
  std::vector<double> conic;      // K (0 at spheres)
  std::vector<double> asphere;    // K * kAsphereTerms
  std::vector<double> decenter;   // K * 2: a placed surface's decenter x, y (0 elsewhere)

  void reset(int surfaces, int wavelengths, int fields);
  // Adds the bundle adjoint of field h, wavelength w started from `pupil` samples under the
  // field's vignetting factors `v` (start_rays).
  void add_bundle(const BundleAdjoint& bundle, int h, int w, int wavelengths,
                  const PupilSamples& pupil, const VignettingFactors& v = VignettingFactors{});
  void add(const SystemAdjoint& other);
};

// A finite object's rays start in the direction from the object point through their start point
// (detail::field_ray_direction in trace/system.h), so their start position also moves their
// direction: adds the direction adjoints (bundle.l0, m0, n0) to the position's (x0, y0, z0),
//   u = d / |d|,  d = (x0, y0 - y_obj, z0 + D):   a_d = (a_u - (a_u . u) u) / |d|.
// Nothing for an object at infinity (the direction is the field's constant). `samples` as for
// start_rays (null: the system's pupil).
void chain_start_direction(const TraceSystem<double>& sys, int h, int w, BundleAdjoint& bundle,
                           const PupilSamples* samples = nullptr);

// True when the adjoint kernel traces this lens exactly as the forward kernel does.
bool adjoint_supported(const TraceLens<double>& lens);

// The mean RMS spot of a prepared double system and its adjoints (step 2).
SystemAdjoint mean_spot_adjoint(const TraceSystem<double>& sys, int threads);

// The double values of a system prepared on Jets.
template <typename J>
TraceSystem<double> system_values(const TraceSystem<J>& in) {
  TraceSystem<double> out;
  auto v = [](const std::vector<J>& a) {
    std::vector<double> r(a.size());
    for (std::size_t i = 0; i < a.size(); ++i) r[i] = value_of(a[i]);
    return r;
  };
  out.lens.curvature_per_mm = v(in.lens.curvature_per_mm);
  out.lens.thickness_mm = v(in.lens.thickness_mm);
  out.lens.nd = v(in.lens.nd);
  out.lens.vd = v(in.lens.vd);
  out.lens.is_glass = in.lens.is_glass;
  out.lens.model_dpgf = in.lens.model_dpgf;
  out.lens.catalog_offset = in.lens.catalog_offset;
  out.lens.wavelengths_nm = in.lens.wavelengths_nm;
  out.lens.stop = in.lens.stop;
  out.lens.profile = in.lens.profile;
  out.lens.conic = v(in.lens.conic);
  out.lens.asphere = v(in.lens.asphere);
  out.lens.semi_diameter_mm = in.lens.semi_diameter_mm;
  out.lens.geometry =
      in.lens.geometry.template convert<double>([](const J& x) { return value_of(x); });
  out.scale = value_of(in.scale);
  out.efl_mm = value_of(in.efl_mm);
  out.bfl_mm = value_of(in.bfl_mm);
  out.epd_mm = value_of(in.epd_mm);
  out.entrance_pupil_z_mm = value_of(in.entrance_pupil_z_mm);
  out.stop_radius_mm = value_of(in.stop_radius_mm);
  out.fields_deg = in.fields_deg;
  out.field_azimuth_deg = in.field_azimuth_deg;
  out.field_values = in.field_values;
  out.field_type = in.field_type;
  out.field_weights = in.field_weights;
  out.vignetting = in.vignetting;
  out.object_distance_mm = in.object_distance_mm;
  out.field_object_y_mm = in.field_object_y_mm;
  out.wavelength_weights = in.wavelength_weights;
  out.pupil_maps.resize(in.pupil_maps.size());
  for (std::size_t i = 0; i < in.pupil_maps.size(); ++i) {
    out.pupil_maps[i] = {value_of(in.pupil_maps[i].scale_x), value_of(in.pupil_maps[i].offset_y),
                         value_of(in.pupil_maps[i].scale_y)};
  }
  out.wavelength_count = in.wavelength_count;
  out.pupil = in.pupil;
  out.full_pupil = in.full_pupil;
  return out;
}

// Step 3: gradient[j] += sum_P a_P dP/dv_j for the Jet directions j < count of `sys`, a system
// prepared without ray aiming (its maps the identity), `values` its double values with the aimed
// maps (aim_pupil_maps) and `aiming` the adjoint through those maps (aim_pupil_maps_adjoint;
// null without ray aiming). A ray start S = R_EP m (m a map entry) gives
//   a_S dS/dv = a_S m dR_EP/dv + (a_S R_EP) dm/dv,
// the second term the aiming's: sum over its parameters P (the scaled lens, R_EP, z_EP, R_s) of
// a_P dP/dv.
template <typename J>
void chain_system_adjoint(const TraceSystem<J>& sys, const TraceSystem<double>& values,
                          const SystemAdjoint& adj, const AimingAdjoint* aiming, int count,
                          double* gradient) {
  const int k_count = sys.lens.surface_count();
  const int wl = sys.wavelength_count;
  const int fields = static_cast<int>(sys.fields_deg.size());
  auto add = [&](const J& p, double a) {
    if (a == 0.0) return;
    for (int j = 0; j < count; ++j) gradient[j] += a * p.v[j];
  };
  auto add_all = [&](const std::vector<J>& p, const std::vector<double>& a) {
    for (std::size_t i = 0; i < p.size() && i < a.size(); ++i) add(p[i], a[i]);
  };
  for (int k = 0; k < k_count; ++k) {
    add(sys.lens.curvature_per_mm[k], adj.curvature[k]);
    add(sys.lens.thickness_mm[k], adj.thickness[k]);
  }
  if (sys.lens.has_profiles()) {
    for (int k = 0; k < k_count; ++k) {
      add(sys.lens.conic[k], adj.conic[k]);
      for (int j = 0; j < kAsphereTerms; ++j) {
        const std::size_t i = static_cast<std::size_t>(k) * kAsphereTerms + j;
        add(sys.lens.asphere[i], adj.asphere[i]);
      }
    }
  }
  // The decenters of a placed lens scale with the prescription (TraceLens::scale_lengths).
  if (sys.lens.geometry.placed()) {
    for (int k = 0; k < k_count; ++k) {
      add(sys.lens.geometry.value(k, 0), adj.decenter[2 * k]);
      add(sys.lens.geometry.value(k, 1), adj.decenter[2 * k + 1]);
    }
  }
  for (int w = 0; w < wl; ++w)
    for (int k = 0; k < k_count; ++k)
      add(sys.lens.index(k - 1, w) / sys.lens.index(k, w),
          adj.mu[static_cast<std::size_t>(w) * k_count + k]);
  double a_r_ep = 0.0, a_z_ep = 0.0;
  for (int h = 0; h < fields; ++h)
    for (int w = 0; w < wl; ++w) {
      const PupilMap<double>& map = values.pupil_map(h, w);
      const double* a = &adj.start[(static_cast<std::size_t>(h) * wl + w) * 4];
      a_r_ep += a[0] * map.scale_x + a[1] * map.offset_y + a[2] * map.scale_y;
      a_z_ep += a[3];
    }
  if (aiming) {
    add_all(sys.lens.curvature_per_mm, aiming->curvature);
    add_all(sys.lens.thickness_mm, aiming->thickness);
    add_all(sys.lens.nd, aiming->nd);
    add_all(sys.lens.vd, aiming->vd);
    add_all(sys.lens.conic, aiming->conic);
    add_all(sys.lens.asphere, aiming->asphere);
    add_all(sys.lens.geometry.placement, aiming->placement);
    add(sys.stop_radius_mm, aiming->stop_radius);
    a_r_ep += aiming->entrance_pupil_radius;
    a_z_ep += aiming->entrance_pupil_z;
  }
  add(sys.epd_mm / K<J>(2.0), a_r_ep);
  add(sys.entrance_pupil_z_mm, a_z_ep);
}

// The mean spot and its gradient with respect to `variables` by the adjoint (steps 1-3), the
// Jet preparation (without the ray aiming, whose derivatives come from aim_pupil_maps_adjoint)
// in chunks of N variables.
template <int N = 24>
SpotGradient mean_spot_gradient_adjoint(const TraceLens<double>& lens_in, const Specs& specs,
                                        const std::vector<PrescriptionVariable>& variables,
                                        const TraceOptions& options) {
  using J = ceres::Jet<double, N>;
  // Every chunk with the same profiles (gradient.h): the adjoint traces the first one's lens.
  const TraceLens<double> lens = with_profile_variables(lens_in, variables);
  SpotGradient out;
  out.gradient.assign(variables.size(), 0.0);
  const int count = static_cast<int>(variables.size());
  // prepare_system(lens, specs, options)'s setup, without the aiming on Jets.
  const SystemSetup setup = specs_setup(specs, options, !lens.geometry.placed());
  TraceOptions unaimed = options;
  unaimed.ray_aiming = false;
  SystemAdjoint adj;
  TraceSystem<double> values;
  AimingAdjoint aiming;
  for (int first = 0; first < count || first == 0; first += N) {
    const int chunk = std::min(N, count - first);
    const TraceLens<J> lens_j = convert_trace_lens<J>(lens, variables, first, chunk,
                                                      [](double v, int j) { return J(v, j); });
    const TraceSystem<J> sys = prepare_system(lens_j, setup, unaimed);
    if (first == 0) {
      values = system_values(sys);
      if (options.ray_aiming) aim_pupil_maps(values, setup);
      adj = mean_spot_adjoint(values, options.threads);
      out.mean_rms_spot_mm = adj.value;
      if (options.ray_aiming) aiming = aim_pupil_maps_adjoint(values, setup, adj.start);
    }
    if (chunk > 0)
      chain_system_adjoint(sys, values, adj, options.ray_aiming ? &aiming : nullptr, chunk,
                           out.gradient.data() + first);
    if (count == 0) break;
  }
  return out;
}

// mean_spot_gradient_adjoint on the widths of core/jet_width.h is compiled once, in
// src/analysis/spot_adjoint.cpp.
#define LENSOPT_MEAN_SPOT_GRADIENT_ADJOINT_JET(N)                                       \
  extern template SpotGradient mean_spot_gradient_adjoint<N>(                           \
      const TraceLens<double>&, const Specs&, const std::vector<PrescriptionVariable>&, \
      const TraceOptions&);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_MEAN_SPOT_GRADIENT_ADJOINT_JET)
#undef LENSOPT_MEAN_SPOT_GRADIENT_ADJOINT_JET

// The fastest exact gradient: the adjoint where supported, else the Jet path.
SpotGradient mean_spot_gradient_fast(const TraceLens<double>& lens, const Specs& specs,
                                     const std::vector<PrescriptionVariable>& variables,
                                     const TraceOptions& options);

}  // namespace lensopt
