#include "lensopt/optimize/design_gradient.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "lensopt/analysis/spot_adjoint.h"
#include "lensopt/core/jet_width.h"
#include "lensopt/core/threads.h"
#include "lensopt/optimize/glass_elements.h"

namespace lensopt {
namespace {

template <int N>
void accumulate(const LensParameterization& param, const std::vector<double>& x, int first,
                GlassMode mode, const std::vector<int>& fixed_glasses, const TraceOptions& sampling,
                const DesignLossOptions& options, DesignValueGradient& out) {
  using J = ceres::Jet<double, N>;
  const int n = param.size();
  std::vector<J> xj(n);
  for (int i = 0; i < n; ++i) {
    xj[i] = J(x[i]);
    if (i >= first && i < first + N) xj[i].v[i - first] = 1.0;
  }
  DesignLoss<J> loss;
  out.finite = evaluate_design<J>(param, xj.data(), mode, fixed_glasses, sampling, options, nullptr,
                                  nullptr, &loss) &&
               out.finite;
  for (int i = first; i < std::min(n, first + N); ++i) out.gradient[i] = loss.total.v[i - first];
  if (first == 0) {
    out.loss.spot_mm = loss.spot_mm.a;
    out.loss.ray_path_mm = loss.ray_path_mm.a;
    out.loss.ray_angle = loss.ray_angle.a;
    out.loss.glass = loss.glass.a;
    out.loss.profile = loss.profile.a;
    out.loss.total = loss.total.a;
    out.loss.field_rms_mm.clear();
    for (const J& f : loss.field_rms_mm) out.loss.field_rms_mm.push_back(f.a);
    out.loss.merit = loss.merit;
    out.loss.wavefront_waves = loss.wavefront_waves.a;
    out.loss.field_wavefront_waves.clear();
    for (const J& f : loss.field_wavefront_waves) out.loss.field_wavefront_waves.push_back(f.a);
    out.loss.afocal = loss.afocal;
    out.loss.angular_spot_rad = loss.angular_spot_rad.a;
    out.loss.field_angular_spot_rad.clear();
    for (const J& f : loss.field_angular_spot_rad) out.loss.field_angular_spot_rad.push_back(f.a);
    out.loss.angular_unit_mm = loss.angular_unit_mm;
    out.loss.failed_rays = loss.failed_rays;
    out.loss.rays = loss.rays;
  }
}

// The constraint-field system of evaluate_design on Jets with x[first, first + N) seeded, prepared
// with `setup` and `topt` (the caller's: without ray aiming, see design_adjoint_gradient).
template <int N>
TraceSystem<ceres::Jet<double, N>> design_system(
    const LensParameterization& param, const std::vector<double>& x, int first, GlassMode mode,
    const std::vector<int>& fixed_glasses, const SystemSetup& setup, const TraceOptions& topt,
    const DesignLossOptions& options, ceres::Jet<double, N>& profile) {
  using J = ceres::Jet<double, N>;
  const int n = param.size();
  std::vector<J> xj(n);
  for (int i = 0; i < n; ++i) {
    xj[i] = J(x[i]);
    if (i >= first && i < first + N) xj[i].v[i - first] = 1.0;
  }
  const TraceLens<J> lens = param.to_trace_lens(xj.data(), mode, fixed_glasses);
  // The profile bounds (no rays: forward mode on these Jets, as evaluate_design).
  profile = profile_bound_loss(lens, param.structure().specs, options.max_surface_slope_deg);
  return prepare_system(lens, setup, topt);
}

// Step 2 of the header for the design loss: the loss terms of evaluate_design in double and the
// adjoints of l_lens (without the glass term) with respect to the system's parameters.
SystemAdjoint design_adjoint(const TraceSystem<double>& sys, const DesignSampling& sampled,
                             const Lens& structure, const TraceOptions& sampling,
                             const DesignLossOptions& options, DesignLoss<double>& loss) {
  const int all_fields = static_cast<int>(sys.fields_deg.size());
  const int field_count = sampled.spot_fields;
  const int wl = sys.wavelength_count;
  const int rays = static_cast<int>(sys.pupil.size());
  const int k_count = sys.lens.surface_count();
  const double n_r = static_cast<double>(field_count) * wl * rays;
  const PupilSamples edge = sys.samples_for(pupil_edge_samples(kEdgeRays));
  const double cos2_max = std::pow(std::cos(options.max_ray_angle_deg * kPi / 180.0), 2);
  // evaluate_design's bounds: a split glass element (glass_elements.h) on its summed travel.
  const std::vector<int> element_first = element_first_spaces(structure);
  std::vector<double> lower(k_count), upper(k_count);
  for (int k = 0; k < k_count; ++k) {
    if (!element_last_space(element_first, k)) {
      lower[k] = 0.0;  // a part of a split element: no ray travels backwards
      upper[k] = std::numeric_limits<double>::infinity();
    } else if (k == k_count - 1) {
      image_space_bounds(options, lower[k], upper[k]);
    } else if (stop_at_vertex_space(structure, k)) {
      lower[k] = -std::numeric_limits<double>::infinity();  // the stop on a vertex: no air gap
      upper[k] = std::numeric_limits<double>::infinity();
    } else if (sys.lens.is_glass[k]) {
      lower[k] = options.min_glass_mm;
      upper[k] = options.max_glass_mm;
    } else {
      lower[k] = options.min_air_mm;
      upper[k] = std::numeric_limits<double>::infinity();
    }
  }
  const double path_weight = options.weight_ray_path / n_r;
  const double angle_weight = options.weight_ray_angle / n_r;

  std::vector<double> field_rms(field_count, 0.0), path_linear(all_fields, 0.0),
      angle_linear(all_fields, 0.0);
  std::vector<int> failed(all_fields, 0);
  std::vector<SystemAdjoint> per_field(all_fields);
  // The spot's weights (analysis/spot.h, as evaluate_design): omega_w, and phi_h of the spot
  // fields; all exactly 1 when equal.
  const SpotWeights spot_w = spot_weights(sys);
  std::vector<double> phi(field_count, 1.0);
  for (int hf = 0; hf < all_fields; ++hf)
    if (sampled.spot_field[hf] >= 0) phi[sampled.spot_field[hf]] = spot_w.field[hf];
  double phi_sum = 0.0;
  for (int h = 0; h < field_count; ++h) phi_sum += phi[h];
  if (!(phi_sum > 0.0)) {
    phi.assign(field_count, 1.0);
    phi_sum = field_count;
  }
  const int nthreads = thread_count(sampling.threads);
#pragma omp parallel num_threads(nthreads)
  {
    RayBundle<double> bundle;
    RayRecord<double> record;
    AdjointTape tape;
    BundleAdjoint adjoint;
    std::vector<std::vector<double>> travel_seed, zeta_seed, zeta_prime_seed;
    std::vector<double> ys, xs, seed_x, seed_y;
    std::vector<char> ok;
#pragma omp for schedule(dynamic, 1)
    for (int hf = 0; hf < all_fields; ++hf) {
      SystemAdjoint& adj = per_field[hf];
      adj.reset(k_count, wl, 0);
      adj.start.assign(static_cast<std::size_t>(all_fields) * wl * 4, 0.0);
      const int h = sampled.spot_field[hf];
      const bool spot_field = h >= 0;
      // The spot of field h (evaluate_design's formula) and its seed scale.
      double y_mean = 0.0, x_mean = 0.0, spot_scale = 0.0;
      if (spot_field) {
        ys.assign(static_cast<std::size_t>(wl) * rays, 0.0);
        xs.assign(static_cast<std::size_t>(wl) * rays, 0.0);
        ok.assign(static_cast<std::size_t>(wl) * rays, 0);
        for (int w = 0; w < wl; ++w) {
          start_rays(sys, hf, w, bundle);
          trace_bundle(sys.lens, w, k_count, true, bundle,
                       static_cast<RayRecord<double>*>(nullptr));
          for (int p = 0; p < rays; ++p) {
            const std::size_t i = static_cast<std::size_t>(w) * rays + p;
            ok[i] = bundle.status[p] == kRayOk;
            if (ok[i]) {
              ys[i] = bundle.y[p];
              xs[i] = bundle.x[p];
            }
          }
        }
        // The centroids (evaluate_design); x's is 0 on the mirrored half pupil.
        int count = 0;
        double y_sum = 0.0, x_sum = 0.0, weight_sum = 0.0;
        for (std::size_t i = 0; i < ys.size(); ++i)
          if (ok[i]) {
            const double o = spot_w.wavelength[i / rays];
            y_sum += o == 1.0 ? ys[i] : o * ys[i];
            x_sum += o == 1.0 ? xs[i] : o * xs[i];
            ++count;
            weight_sum += o;
          }
        const bool any = count > 0 && weight_sum > 0.0;
        y_mean = any ? y_sum / weight_sum : 0.0;
        x_mean = sys.full_pupil && any ? x_sum / weight_sum : 0.0;
        double s2 = 0.0;
        for (std::size_t i = 0; i < ys.size(); ++i)
          if (ok[i]) {
            const double o = spot_w.wavelength[i / rays];
            const double dy = ys[i] - y_mean;
            const double dx = xs[i] - x_mean;
            s2 += o == 1.0 ? dy * dy + dx * dx : o * (dy * dy + dx * dx);
          }
        const double var = any ? s2 / weight_sum : 0.0;
        field_rms[h] = var > 0.0 ? std::sqrt(var) : 0.0;
        // d sqrt(s2 / M) / dY_i = omega_w (Y_i - ybar) / (M S); l_S = sum_h phi_h S_h / Phi
        // (omega_w applied per wavelength in `backward`).
        if (field_rms[h] > 0.0)
          spot_scale =
              phi_sum == field_count && weight_sum == count
                  ? options.weight_spot / (static_cast<double>(field_count) * count * field_rms[h])
                  : options.weight_spot * phi[h] / (phi_sum * weight_sum * field_rms[h]);
      }
      double path_sum = 0.0, angle_sum = 0.0;
      // The penalties of a traced bundle and their seeds (evaluate_design's add_constraints).
      auto constraint_seeds = [&](const RayBundle<double>& b) {
        const std::size_t count = b.size();
        for (auto* seeds : {&travel_seed, &zeta_seed, &zeta_prime_seed}) {
          seeds->resize(k_count);
          for (auto& v : *seeds) v.assign(count, 0.0);
        }
        for (std::size_t p = 0; p < count; ++p) {
          const bool traced = b.status[p] == kRayOk;
          const int last_valid = traced ? k_count - 1 : b.failed_surface[p];
          double element_dz = 0.0;  // the travel so far in a split element
          for (int k = 0; k <= last_valid && k < k_count; ++k) {
            if (traced || k < last_valid) {
              const bool split = element_first[k] != k;
              const double dz = (split ? element_dz : 0.0) + record.axial_travel_mm[k][p];
              element_dz = dz;
              const double below = lower[k] - dz;
              const double above = std::isfinite(upper[k]) ? dz - upper[k] : 0.0;
              path_sum += (below > 0.0 ? below : 0.0) + (above > 0.0 ? above : 0.0);
              const double seed =
                  path_weight * ((above > 0.0 ? 1.0 : 0.0) - (below > 0.0 ? 1.0 : 0.0));
              // The summed travel's seed reaches every space of the element.
              for (int j = element_first[k]; j <= k; ++j) travel_seed[j][p] = seed;
            }
            const double va = cos2_max - record.cos2_incidence[k][p];
            const double vb = cos2_max - record.cos2_refraction[k][p];
            angle_sum += (va > 0.0 ? va : 0.0) + (vb > 0.0 ? vb : 0.0);
            // The slope of a tie (within kHingeTie of the bound) is halved: detail::tied_hinge.
            const double zi = record.cos2_incidence[k][p], zo = record.cos2_refraction[k][p];
            zeta_seed[k][p] = zi < cos2_max - detail::kHingeTie   ? -angle_weight
                              : zi < cos2_max + detail::kHingeTie ? -0.5 * angle_weight
                                                                  : 0.0;
            zeta_prime_seed[k][p] = zo < cos2_max - detail::kHingeTie   ? -angle_weight
                                    : zo < cos2_max + detail::kHingeTie ? -0.5 * angle_weight
                                                                        : 0.0;
          }
        }
      };
      auto backward = [&](int w, const PupilSamples& pupil, bool spot) {
        AdjointSeeds seeds;
        seeds.travel = &travel_seed;
        seeds.zeta = &zeta_seed;
        seeds.zeta_prime = &zeta_prime_seed;
        if (spot && spot_scale > 0.0) {
          const double o = spot_w.wavelength[w];
          const double scale = o == 1.0 ? spot_scale : spot_scale * o;
          seed_x.resize(bundle.size());
          seed_y.resize(bundle.size());
          for (std::size_t i = 0; i < bundle.size(); ++i) {
            seed_x[i] = (bundle.x[i] - x_mean) * scale;
            seed_y[i] = (bundle.y[i] - y_mean) * scale;
          }
          seeds.x_image = seed_x.data();
          seeds.y_image = seed_y.data();
        }
        adjoint.reset(k_count);
        trace_bundle_adjoint(sys.lens, w, bundle, tape, seeds, adjoint);
        chain_start_direction(sys, hf, w, adjoint, &pupil);
        adj.add_bundle(adjoint, hf, w, wl, pupil,
                       hf < static_cast<int>(sys.vignetting.size()) ? sys.vignetting[hf]
                                                                    : VignettingFactors{});
      };
      for (int w = 0; w < wl; ++w) {
        if (spot_field) {
          start_rays(sys, hf, w, bundle);
          record.resize(k_count, bundle.size());
          trace_bundle_taped(sys.lens, w, bundle, &record, tape);
          for (std::size_t p = 0; p < bundle.size(); ++p) failed[hf] += bundle.status[p] != kRayOk;
          constraint_seeds(bundle);
          backward(w, sys.pupil, true);
        }
        start_rays(sys, hf, w, bundle, &edge);
        record.resize(k_count, bundle.size());
        trace_bundle_taped(sys.lens, w, bundle, &record, tape);
        for (std::size_t p = 0; p < bundle.size(); ++p) failed[hf] += bundle.status[p] != kRayOk;
        constraint_seeds(bundle);
        backward(w, edge, false);
      }
      path_linear[hf] = path_sum;
      angle_linear[hf] = angle_sum;
    }
  }
  SystemAdjoint out;
  out.reset(k_count, wl, all_fields);
  for (int hf = 0; hf < all_fields; ++hf) out.add(per_field[hf]);
  double spot = 0.0, path = 0.0, angle = 0.0;
  int failed_total = 0;
  for (int h = 0; h < field_count; ++h)
    spot += phi[h] == 1.0 ? field_rms[h] : phi[h] * field_rms[h];
  for (int hf = 0; hf < all_fields; ++hf) {
    path += path_linear[hf];
    angle += angle_linear[hf];
    failed_total += failed[hf];
  }
  loss.spot_mm = spot / phi_sum;
  loss.ray_path_mm = path / n_r;
  loss.ray_angle = angle / n_r;
  loss.field_rms_mm = field_rms;
  loss.field_weights = phi;
  loss.failed_rays = failed_total;
  loss.rays = static_cast<int>(n_r);
  return out;
}

template <int N>
DesignValueGradient design_adjoint_gradient(const LensParameterization& param,
                                            const std::vector<double>& x, GlassMode mode,
                                            const std::vector<int>& fixed_glasses,
                                            const TraceOptions& sampling,
                                            const DesignLossOptions& options) {
  DesignValueGradient out;
  const int n = param.size();
  out.gradient.assign(n, 0.0);
  // evaluate_design's system: unscaled, its sampling's setup; prepared on the Jets without the
  // ray aiming, whose maps and adjoint come from the taped aiming (trace/aiming_adjoint.h).
  TraceOptions unscaled = sampling;
  unscaled.scale_to_spec = false;
  const DesignSampling sampled = design_sampling(param.structure(), unscaled);
  TraceOptions unaimed = unscaled;
  unaimed.ray_aiming = false;
  SystemAdjoint adj;
  TraceSystem<double> values;
  AimingAdjoint aiming;
  for (int first = 0; first < n || first == 0; first += N) {
    ceres::Jet<double, N> profile;
    const auto sys = design_system<N>(param, x, first, mode, fixed_glasses, sampled.setup, unaimed,
                                      options, profile);
    for (int j = 0; j < std::min(N, n - first); ++j)
      out.gradient[first + j] += options.weight_profile * profile.v[j];
    out.loss.profile = profile.a;
    if (first == 0) {
      values = system_values(sys);
      if (!adjoint_supported(values.lens))
        return design_loss_gradient_jets(param, x, mode, fixed_glasses, sampling, options);
      if (sampling.ray_aiming) aim_pupil_maps(values, sampled.setup);
      adj = design_adjoint(values, sampled, param.structure(), sampling, options, out.loss);
      if (sampling.ray_aiming) aiming = aim_pupil_maps_adjoint(values, sampled.setup, adj.start);
    }
    chain_system_adjoint(sys, values, adj, sampling.ray_aiming ? &aiming : nullptr,
                         std::min(N, n - first), out.gradient.data() + first);
    if (n == 0) break;
  }
  // The glass-variable loss, direct: l_GV = sum ||g - g*||^2, g* the nearest catalog glass.
  double glass = 0.0;
  for (int i = 0; i < n; ++i) {
    if (param.variables()[i].kind != LensVariable::Kind::kGlass0) continue;
    const Eigen::Vector2d g(x[i], x[i + 1]);
    const Eigen::Vector2d p = param.glass_space().glass_point(param.glass_space().nearest(g));
    const double d0 = x[i] - p[0], d1 = x[i + 1] - p[1];
    glass += d0 * d0 + d1 * d1;
    out.gradient[i] += 2.0 * options.weight_glass * d0;
    out.gradient[i + 1] += 2.0 * options.weight_glass * d1;
  }
  out.loss.glass = glass;
  out.loss.total = options.weight_spot * out.loss.spot_mm +
                   options.weight_ray_path * out.loss.ray_path_mm +
                   options.weight_ray_angle * out.loss.ray_angle + options.weight_glass * glass +
                   options.weight_profile * out.loss.profile;
  out.finite = std::isfinite(out.loss.spot_mm + out.loss.ray_path_mm + out.loss.ray_angle + glass +
                             out.loss.profile);
  return out;
}

}  // namespace

DesignValueGradient design_loss_gradient(const LensParameterization& param,
                                         const std::vector<double>& x, GlassMode mode,
                                         const std::vector<int>& fixed_glasses,
                                         const TraceOptions& sampling,
                                         const DesignLossOptions& options) {
  // The adjoint covers the spot merit; the wavefront merit takes the forward-mode Jets.
  // So does an afocal lens's angular spot (design_loss.h): its seeds are not written here.
  if (options.merit == DesignMerit::kWavefront || param.afocal())
    return design_loss_gradient_jets(param, x, mode, fixed_glasses, sampling, options);
  const int n = param.size();
  return with_jet_width(n, [&](auto width) {
    return design_adjoint_gradient<decltype(width)::value>(param, x, mode, fixed_glasses, sampling,
                                                           options);
  });
}

DesignValueGradient design_loss_gradient_jets(const LensParameterization& param,
                                              const std::vector<double>& x, GlassMode mode,
                                              const std::vector<int>& fixed_glasses,
                                              const TraceOptions& sampling,
                                              const DesignLossOptions& options) {
  DesignValueGradient out;
  const int n = param.size();
  out.gradient.assign(n, 0.0);
  // The narrowest Jet that holds the variables in one pass; blocks of kDesignGradientWidth above.
  with_jet_width(n, [&](auto width) {
    constexpr int kWidth = decltype(width)::value;
    for (int first = 0; first < n; first += kWidth)
      accumulate<kWidth>(param, x, first, mode, fixed_glasses, sampling, options, out);
    return 0;
  });
  return out;
}

}  // namespace lensopt
