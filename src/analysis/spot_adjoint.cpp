// The mean spot's adjoint over every field, wavelength and pupil ray (analysis/spot_adjoint.h).
#include "lensopt/analysis/spot_adjoint.h"

#include <omp.h>

#include <cmath>

#include "lensopt/core/jet_width.h"
#include "lensopt/core/threads.h"

namespace lensopt {

void SystemAdjoint::reset(int surfaces, int wavelengths, int fields) {
  value = 0.0;
  curvature.assign(surfaces, 0.0);
  thickness.assign(surfaces, 0.0);
  mu.assign(static_cast<std::size_t>(wavelengths) * surfaces, 0.0);
  start.assign(static_cast<std::size_t>(fields) * wavelengths * 4, 0.0);
  conic.assign(surfaces, 0.0);
  asphere.assign(static_cast<std::size_t>(surfaces) * kAsphereTerms, 0.0);
  decenter.assign(static_cast<std::size_t>(surfaces) * 2, 0.0);
}

void SystemAdjoint::add_bundle(const BundleAdjoint& bundle, int h, int w, int wavelengths,
                               const PupilSamples& pupil, const VignettingFactors& v) {
  const int k_count = static_cast<int>(curvature.size());
  for (int k = 0; k < k_count; ++k) {
    curvature[k] += bundle.curvature[k];
    thickness[k] += bundle.thickness[k];
    mu[static_cast<std::size_t>(w) * k_count + k] += bundle.mu[k];
    conic[k] += bundle.conic[k];
  }
  for (std::size_t i = 0; i < asphere.size(); ++i) asphere[i] += bundle.asphere[i];
  for (std::size_t i = 0; i < decenter.size(); ++i) decenter[i] += bundle.decenter[i];
  double a_sx = 0.0, a_oy = 0.0, a_sy = 0.0, a_z = 0.0;
  if (!v.any()) {
    for (std::size_t i = 0; i < pupil.size(); ++i) {
      a_sx += bundle.x0[i] * pupil.x[i];
      a_oy += bundle.y0[i];
      a_sy += bundle.y0[i] * pupil.y[i];
      a_z += bundle.z0[i];
    }
  } else if (v.asymmetric()) {
    // The vignetted pupil point (start_rays): x0 = s_x px', y0 = o_y + s_y py', (px', py') =
    // VignettingFactors::pupil_point(px, py).
    double qx = 0.0, qy = 0.0;
    for (std::size_t i = 0; i < pupil.size(); ++i) {
      v.pupil_point(pupil.x[i], pupil.y[i], qx, qy);
      a_sx += bundle.x0[i] * qx;
      a_oy += bundle.y0[i];
      a_sy += bundle.y0[i] * qy;
      a_z += bundle.z0[i];
    }
  } else {
    // The vignetted pupil point (start_rays): px' = (1 - VCX) px, py' = VDY + (1 - VCY) py.
    for (std::size_t i = 0; i < pupil.size(); ++i) {
      a_sx += bundle.x0[i] * ((1.0 - v.vcx) * pupil.x[i]);
      a_oy += bundle.y0[i];
      a_sy += bundle.y0[i] * (v.vdy + (1.0 - v.vcy) * pupil.y[i]);
      a_z += bundle.z0[i];
    }
  }
  double* a = &start[(static_cast<std::size_t>(h) * wavelengths + w) * 4];
  a[0] += a_sx;
  a[1] += a_oy;
  a[2] += a_sy;
  a[3] += a_z;
}

void SystemAdjoint::add(const SystemAdjoint& other) {
  value += other.value;
  for (std::size_t i = 0; i < curvature.size(); ++i) curvature[i] += other.curvature[i];
  for (std::size_t i = 0; i < thickness.size(); ++i) thickness[i] += other.thickness[i];
  for (std::size_t i = 0; i < mu.size(); ++i) mu[i] += other.mu[i];
  for (std::size_t i = 0; i < start.size(); ++i) start[i] += other.start[i];
  for (std::size_t i = 0; i < conic.size(); ++i) conic[i] += other.conic[i];
  for (std::size_t i = 0; i < asphere.size(); ++i) asphere[i] += other.asphere[i];
  for (std::size_t i = 0; i < decenter.size(); ++i) decenter[i] += other.decenter[i];
}

void chain_start_direction(const TraceSystem<double>& sys, int h, int w, BundleAdjoint& bundle,
                           const PupilSamples* samples) {
  if (sys.object_at_infinity()) return;
  thread_local RayBundle<double> start;
  start_rays(sys, h, w, start, samples);
  const double y_object = sys.field_object_y_mm.empty() ? 0.0 : sys.field_object_y_mm[h];
  for (std::size_t i = 0; i < start.size(); ++i) {
    const double dx = start.x[i];
    const double dy = start.y[i] - y_object;
    const double dz = start.z[i] + sys.object_distance_mm;
    const double inv = 1.0 / std::sqrt(dx * dx + dy * dy + dz * dz);
    const double al = bundle.l0[i], am = bundle.m0[i], an = bundle.n0[i];
    const double dot = al * start.l[i] + am * start.m[i] + an * start.n[i];
    bundle.x0[i] += (al - dot * start.l[i]) * inv;
    bundle.y0[i] += (am - dot * start.m[i]) * inv;
    bundle.z0[i] += (an - dot * start.n[i]) * inv;
  }
}

bool adjoint_supported(const TraceLens<double>& lens) {
  // Spheres, conics and even aspheres; clear apertures, obscurations, mirrors and 3D placements
  // have their backward steps (trace/adjoint.h).
  if (lens.surface_count() == 0) return false;
  for (std::uint8_t kind : lens.profile)
    if (kind != kProfileSphere && kind != kProfileConic && kind != kProfileAsphere) return false;
  return true;
}

SystemAdjoint mean_spot_adjoint(const TraceSystem<double>& sys, int threads) {
  const int field_count = static_cast<int>(sys.fields_deg.size());
  const int k_count = sys.lens.surface_count();
  const int wl = sys.wavelength_count;
  // Per-field results, added in field order afterwards so the sum does not depend on threads.
  std::vector<SystemAdjoint> per_field(field_count);
  std::vector<double> field_rms(field_count, 0.0);
  const SpotWeights weights = spot_weights(sys);
  const int nthreads = thread_count(threads);
#pragma omp parallel num_threads(nthreads)
  {
    RayBundle<double> rays;
    AdjointTape tape;
    BundleAdjoint bundle;
    std::vector<double> seed_x, seed_y;
#pragma omp for schedule(dynamic, 1)
    for (int h = 0; h < field_count; ++h) {
      SystemAdjoint& adj = per_field[h];
      adj.reset(k_count, wl, 1);
      adj.start.assign(static_cast<std::size_t>(field_count) * wl * 4, 0.0);
      // Forward: the field's spot, centroid and count.
      SpotAccumulator<double> acc;
      acc.full_pupil = sys.full_pupil;
      for (int w = 0; w < wl; ++w) {
        start_rays(sys, h, w, rays);
        trace_bundle(sys.lens, w, k_count, true, rays, static_cast<RayRecord<double>*>(nullptr));
        acc.add(rays, weights.wavelength[w]);
      }
      const double rms = acc.rms();
      field_rms[h] = rms;
      if (!(rms > 0.0)) continue;
      const double ybar = acc.centroid();
      const double xbar = acc.centroid_x();  // 0 on a mirrored half pupil
      // d S_h / d Y_i = omega_w (Y_i - ybar_h) / (M_h S_h), times phi_h / Phi (spot.h); with
      // equal weights 1 / (F N_h S_h).
      const bool equal = weights.field[h] == 1.0 && weights.field_sum == field_count &&
                         acc.weight_sum == acc.count;
      const double field_scale =
          equal ? 1.0 / (static_cast<double>(field_count) * acc.count * rms)
                : weights.field[h] / (weights.field_sum * acc.weight_sum * rms);
      // Backward per wavelength from a taped forward trace.
      for (int w = 0; w < wl; ++w) {
        const double scale =
            weights.wavelength[w] == 1.0 ? field_scale : field_scale * weights.wavelength[w];
        start_rays(sys, h, w, rays);
        trace_bundle_taped(sys.lens, w, rays, nullptr, tape);
        seed_x.resize(rays.size());
        seed_y.resize(rays.size());
        for (std::size_t i = 0; i < rays.size(); ++i) {
          seed_x[i] = (sys.full_pupil ? rays.x[i] - xbar : rays.x[i]) * scale;
          seed_y[i] = (rays.y[i] - ybar) * scale;
        }
        AdjointSeeds seeds;
        seeds.x_image = seed_x.data();
        seeds.y_image = seed_y.data();
        bundle.reset(k_count);
        trace_bundle_adjoint(sys.lens, w, rays, tape, seeds, bundle);
        chain_start_direction(sys, h, w, bundle);
        adj.add_bundle(
            bundle, h, w, wl, sys.pupil,
            h < static_cast<int>(sys.vignetting.size()) ? sys.vignetting[h] : VignettingFactors{});
      }
    }
  }
  SystemAdjoint out;
  out.reset(k_count, wl, field_count);
  double sum = 0.0;
  for (int h = 0; h < field_count; ++h) {
    sum += weights.field[h] == 1.0 ? field_rms[h] : weights.field[h] * field_rms[h];
    if (per_field[h].curvature.empty()) continue;
    out.add(per_field[h]);
  }
  out.value = weights.field_sum > 0.0 ? sum / weights.field_sum : 0.0;
  return out;
}

// The gradients on every width (declared extern in analysis/gradient.h and spot_adjoint.h).
#define LENSOPT_SPOT_GRADIENTS_JET(N)                                                           \
  template SpotGradient mean_spot_gradient<N>(const TraceLens<double>&, const Specs&,           \
                                              const std::vector<PrescriptionVariable>&,         \
                                              const TraceOptions&);                             \
  template SpotGradient mean_spot_gradient_adjoint<N>(const TraceLens<double>&, const Specs&,   \
                                                      const std::vector<PrescriptionVariable>&, \
                                                      const TraceOptions&);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_SPOT_GRADIENTS_JET)
#undef LENSOPT_SPOT_GRADIENTS_JET

SpotGradient mean_spot_gradient_fast(const TraceLens<double>& lens, const Specs& specs,
                                     const std::vector<PrescriptionVariable>& variables,
                                     const TraceOptions& options) {
  if (!adjoint_supported(lens)) return mean_spot_gradient_auto(lens, specs, variables, options);
  return with_jet_width(static_cast<int>(variables.size()), [&](auto width) {
    return mean_spot_gradient_adjoint<decltype(width)::value>(lens, specs, variables, options);
  });
}

}  // namespace lensopt
