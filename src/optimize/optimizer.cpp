#include "lensopt/optimize/optimizer.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>

#include "lensopt/analysis/afocal.h"
#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/core/adam.h"
#include "lensopt/core/error.h"
#include "lensopt/core/jet_width.h"
#include "lensopt/core/text.h"
#include "lensopt/lens/profile_sag.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/optimize/free_jacobian.h"
#include "lensopt/optimize/glass_elements.h"
#include "lensopt/optimize/profile_bounds.h"
#include "lensopt/optimize/virtual_image.h"

namespace lensopt {
namespace {

// Jet widths for the Jacobian: the smallest that covers the lens's variables in one pass.
constexpr int kStride = 24;
// The stall test of the wavefront merit's strict rounds (ProgressCallback).
constexpr int kStallWindow = 10;
constexpr double kStallRelative = 1e-3;

// The TraceLens of a lens at its spec scale (as analysis traces it: the spec focal length in the
// paper's mode, as written otherwise).
TraceLens<double> scaled_trace_lens(const Lens& lens) {
  const double scale = lens_spec_scale(lens);
  return make_trace_lens(std::isfinite(scale) && scale > 0.0 ? scaled(lens, scale) : lens);
}

struct DesignFunctor {
  const LensParameterization* param;
  GlassMode mode;
  std::vector<int> fixed_glasses;
  TraceOptions sampling;
  DesignLossOptions loss;
  std::vector<double> field_weights;
  std::atomic<int>* evaluations;
  // (evaluation number, l_S in mm) of every evaluation, for the LM-vs-Adam comparison. Ceres
  // calls the functor from one thread (num_threads = 1), so a plain vector suffices.
  std::vector<std::pair<int, double>>* trajectory;

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const int number = evaluations->fetch_add(1) + 1;
    DesignLoss<T> terms;
    const bool ok = evaluate_design<T>(*param, parameters[0], mode, fixed_glasses, sampling, loss,
                                       &field_weights, residuals, &terms);
    if (ok) trajectory->emplace_back(number, value_of(terms.spot_mm));
    return ok;
  }
};

// The profile bounds (profile_bounds.h) of variables x at fixed clear semi-apertures.
struct ProfileBoundFunctor {
  const LensParameterization* param;
  GlassMode mode;
  std::vector<int> fixed_glasses;
  std::vector<double> heights_mm;
  double max_slope_deg;
  double weight;

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const TraceLens<T> lens = param->to_trace_lens(parameters[0], mode, fixed_glasses);
    profile_bound_residuals(lens, heights_mm, max_slope_deg, weight, residuals);
    return true;
  }
};

// Glass edge thickness: for the glass element of spaces k..m (between surfaces k and m + 1; m > k
// for an element split by a dummy or stop surface, glass_elements.h)
//   e_k = t_k + ... + t_m + sag_{m+1}(h_k) - sag_k(h_k)
// at h_k the largest clear semi-aperture of its surfaces (semi_diameter_mm where written, else
// the paraxial estimate of the start, profile_bounds.h), with the real profile's sag
// (lens/profile_sag.h; q clamped at 0 outside a conic's domain, as the tolerance edge gap).
template <typename T>
T glass_edge_mm(const TraceLens<T>& tl, int k, int m, double h) {
  using std::sqrt;
  const T rho = K<T>(h * h);
  T spherical[kAsphereTerms];
  for (T& a : spherical) a = K<T>(0.0);
  auto sag = [&](int i) {
    const T& c = tl.curvature_per_mm[i];
    const bool profiled = tl.has_profiles();
    const T one_plus_k = profiled ? K<T>(1.0) + tl.conic[i] : K<T>(1.0);
    const T* a =
        profiled ? tl.asphere.data() + static_cast<std::size_t>(i) * kAsphereTerms : spherical;
    const T q2 = profile_q2(c, one_plus_k, rho);
    const T q = q2 > K<T>(0.0) ? sqrt(q2) : K<T>(0.0);
    return profile_sag_at_q(c, a, rho, q);
  };
  T t = tl.thickness_mm[k];
  for (int i = k + 1; i <= m; ++i) t = t + tl.thickness_mm[i];
  return t + sag(m + 1) - sag(k);
}

// The edge-thickness bound of a run: the glass spaces, their heights (fixed for the run: the
// start's clear apertures) and the lower bound min(min_glass_mm, half the start's thinnest edge)
// (so the start meets it; a start with a glass of negative edge bounds it at 0).
struct EdgeBound {
  std::vector<int> spaces;  // the element's first space k
  std::vector<int> last;    // and its last space m
  std::vector<double> heights_mm;
  double min_edge_mm = 0.0;
  double lambda = 100.0;  // raised tenfold per round while violated
};

EdgeBound edge_bound_for(const Lens& start, const double min_glass_mm) {
  EdgeBound out;
  const TraceLens<double> tl = scaled_trace_lens(start);
  std::vector<double> h;
  try {
    h = paraxial_clear_semi_apertures_mm(tl, start.specs);
  } catch (const Error&) {
    return out;
  }
  const double scale = lens_spec_scale(start);
  double thinnest = std::numeric_limits<double>::infinity();
  const std::vector<int> first = element_first_spaces(start);
  for (int m = 0; m + 1 < tl.surface_count(); ++m) {
    // One bound per element, at its last space m (its first k: several spaces when split).
    if (start.surfaces[m].material.is_air() || !element_last_space(first, m)) continue;
    const int k = first[m];
    auto height = [&](int i) {
      const double written = start.surfaces[i].semi_diameter_mm * scale;
      return written > 0.0 ? written : (i < static_cast<int>(h.size()) ? h[i] : 0.0);
    };
    double hk = 0.0;
    for (int i = k; i <= m + 1; ++i) hk = std::max(hk, height(i));
    if (!(std::isfinite(hk) && hk > 0.0)) continue;
    out.spaces.push_back(k);
    out.last.push_back(m);
    out.heights_mm.push_back(hk);
    thinnest = std::min(thinnest, glass_edge_mm(tl, k, m, hk));
  }
  if (out.spaces.empty()) return out;
  out.min_edge_mm = std::max(0.0, std::min(min_glass_mm, 0.5 * thinnest));
  return out;
}

// The edge residuals sqrt(lambda) max(e_min - e_k, 0) of variables x.
struct EdgeFunctor {
  const LensParameterization* param;
  GlassMode mode;
  std::vector<int> fixed_glasses;
  const EdgeBound* bound;
  double lambda;

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const TraceLens<T> tl = param->to_trace_lens(parameters[0], mode, fixed_glasses);
    const T root = K<T>(std::sqrt(lambda));
    for (std::size_t i = 0; i < bound->spaces.size(); ++i) {
      // The design margin (as with_margin's glass bound): 1 um above the bound.
      const T short_of = K<T>(bound->min_edge_mm + 1e-3) -
                         glass_edge_mm(tl, bound->spaces[i], bound->last[i], bound->heights_mm[i]);
      residuals[i] = short_of > K<T>(0.0) ? root * short_of : K<T>(0.0);
    }
    return true;
  }
};

// The designer's residual targets (targets.h) of a run: their sampling, the weight lambda_T
// (raised tenfold per round while one is unmet) and the wavefront unit.
struct TargetTerms {
  EdgeBound edges;                    // the glass edge-thickness bound
  std::vector<DesignTarget> targets;  // the residual targets (solved ones excluded)
  TargetSampling sampling;
  // Starts at 1 (a target far from the start at 100 pulled the Cooke-sized merit of a double
  // Gauss into a 200 um basin before the merit had a say) and rises tenfold per unmet round.
  double lambda = 1.0;
  double wave_unit_mm = 0.0;
};

// The target residuals of variables x (targets.h evaluate_targets).
struct TargetFunctor {
  const LensParameterization* param;
  GlassMode mode;
  std::vector<int> fixed_glasses;
  TraceOptions sampling;
  const TargetTerms* terms;
  double lambda;

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    return evaluate_targets<T>(*param, parameters[0], mode, fixed_glasses, sampling, terms->targets,
                               terms->sampling, lambda, terms->wave_unit_mm, residuals);
  }
};

// The number of target residuals at `sampling` (the field count of the target system).
int target_residuals(const LensParameterization& param, const std::vector<double>& x,
                     GlassMode mode, const std::vector<int>& fixed, const TraceOptions& sampling,
                     const TargetTerms& terms) {
  if (terms.targets.empty()) return 0;
  const TraceLens<double> lens = param.to_trace_lens(x.data(), mode, fixed);
  const TraceSystem<double> sys = target_system(param, lens, sampling);
  return target_residual_count(terms.targets, static_cast<int>(sys.fields_deg.size()));
}

// Whether every residual target is met at the optimization sampling, with the design margins
// (an equality within its tolerance, a bound inside its margin).
bool targets_met(const LensParameterization& param, const std::vector<double>& x, GlassMode mode,
                 const std::vector<int>& fixed, const TraceOptions& sampling,
                 const TargetTerms& terms) {
  if (terms.targets.empty()) return true;
  TargetValues<double> values;
  if (!evaluate_targets<double>(param, x.data(), mode, fixed, sampling, terms.targets,
                                terms.sampling, 1.0, terms.wave_unit_mm, nullptr, &values))
    return false;
  for (std::size_t i = 0; i < terms.targets.size(); ++i) {
    const DesignTarget& t = terms.targets[i];
    for (std::size_t j = 0; j < values.items[i].size(); ++j) {
      if (!values.item_known[i][j]) continue;
      const double v = target_violation(t, values.items[i][j], true);
      if (t.relation == TargetRelation::kEqual ? std::abs(v) > target_tolerance(t) : v > 0.0)
        return false;
    }
  }
  return true;
}

// The lens of x, its clear semi-apertures and its profile-bound residual count (0: no profiles).
struct ProfileBoundSetup {
  std::vector<double> heights_mm;
  int count = 0;
};
ProfileBoundSetup profile_bound_setup(const LensParameterization& param,
                                      const std::vector<double>& x, GlassMode mode,
                                      const std::vector<int>& fixed) {
  ProfileBoundSetup out;
  const TraceLens<double> lens = param.to_trace_lens(x.data(), mode, fixed);
  out.count = profile_bound_count(lens);
  if (out.count > 0)
    out.heights_mm = paraxial_clear_semi_apertures_mm(lens, param.structure().specs);
  return out;
}

// Sum of squares of the profile-bound residuals at weight 1 (0: every bound met).
double profile_violation(const LensParameterization& param, const std::vector<double>& x,
                         GlassMode mode, const std::vector<int>& fixed,
                         const ProfileBoundSetup& setup, double max_slope_deg) {
  if (setup.count == 0) return 0.0;
  const TraceLens<double> lens = param.to_trace_lens(x.data(), mode, fixed);
  std::vector<double> r(setup.count);
  profile_bound_residuals(lens, setup.heights_mm, max_slope_deg, 1.0, r.data());
  double sum = 0.0;
  for (double v : r) sum += v * v;
  return sum;
}

class ProgressCallback : public ceres::IterationCallback {
 public:
  // stall_window > 0: the round ends once the best cost of the last stall_window iterations is
  // not below (1 - stall_relative) times the best cost stall_window iterations earlier (a creeping
  // round: LM's per-iteration function tolerance sees each small step as progress).
  ProgressCallback(std::string phase, bool verbose, const std::atomic<bool>* interrupt,
                   int stall_window = 0, double stall_relative = 0.0)
      : phase_(std::move(phase)),
        verbose_(verbose),
        interrupt_(interrupt),
        stall_window_(stall_window),
        stall_relative_(stall_relative) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (verbose_) {
      fmt::print(stderr, "  [{}] iter {:3d}  cost {:.6e}  |step| {:.2e}  lm radius {:.1e}\n",
                 phase_, s.iteration, s.cost, s.step_norm, s.trust_region_radius);
    }
    if (interrupt_ && interrupt_->load()) return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
    if (s.iteration == 0 || s.step_is_successful)
      best_.push_back(best_.empty() ? s.cost : std::min(best_.back(), s.cost));
    else
      best_.push_back(best_.back());
    const int n = static_cast<int>(best_.size());
    if (stall_window_ > 0 && n > stall_window_ &&
        !(best_[n - 1] < (1.0 - stall_relative_) * best_[n - 1 - stall_window_]))
      return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
    return ceres::SOLVER_CONTINUE;
  }

 private:
  std::string phase_;
  bool verbose_;
  const std::atomic<bool>* interrupt_;
  int stall_window_;
  double stall_relative_;
  std::vector<double> best_;  // the best cost after each iteration
};

DesignLoss<double> evaluate_double(const LensParameterization& param, const std::vector<double>& x,
                                   GlassMode mode, const std::vector<int>& fixed,
                                   const TraceOptions& sampling, const DesignLossOptions& loss,
                                   DesignExtremes* extremes = nullptr) {
  DesignLoss<double> out;
  evaluate_design<double>(param, x.data(), mode, fixed, sampling, loss, nullptr, nullptr, &out,
                          extremes);
  return out;
}

// Bounds tightened by the design margin so that constraints met at the optimization sampling
// stay met at full sampling (which has rays nearer the pupil edge and fields in between).
DesignLossOptions with_margin(DesignLossOptions loss) {
  loss.min_air_mm += 0.001;
  loss.min_glass_mm += 0.001;
  loss.max_glass_mm -= 0.001;
  loss.min_image_clearance_mm += 0.005;
  if (loss.virtual_image()) {
    loss.min_virtual_image_mm += 0.005;
    loss.max_virtual_image_mm -= 0.005;
  }
  loss.max_ray_angle_deg -= 0.05;
  loss.max_surface_slope_deg -= 0.05;
  return loss;
}

struct Counters {
  std::atomic<int> evaluations{0};
  std::vector<std::pair<int, double>> trajectory;
  int jacobians = 0;
  int iterations = 0;
  std::string termination;
};

int residual_count(const LensParameterization& param, const TraceOptions& sampling,
                   const DesignLossOptions& loss) {
  const Specs& specs = param.structure().specs;
  // The design loss's sampling (design_sampling.h): spot fields among all traced fields.
  const DesignSampling sampled = design_sampling(param.structure(), sampling);
  const int fields = sampled.spot_fields;
  // A field with VDX or VAN: every field is traced on the full pupil (system.h).
  const bool full_pupil =
      needs_full_pupil(sampled.setup.vignetting) || param.structure().breaks_symmetry();
  const int rays =
      static_cast<int>(paper_pupil_samples(sampling.rings).size()) * (full_pupil ? 2 : 1);
  int glasses = 0;
  for (const LensVariable& v : param.variables()) glasses += v.kind == LensVariable::Kind::kGlass0;
  return design_residual_count(loss, fields, static_cast<int>(sampled.setup.field_values.size()),
                               static_cast<int>(specs.wavelengths_nm.size()), rays,
                               static_cast<int>(param.structure().surfaces.size()), glasses,
                               full_pupil);
}

// "mean spot 12.3456 um" (and the mean RMS wavefront with the wavefront merit; an afocal lens's
// mean RMS angular spot).
std::string merit_text(const DesignLoss<double>& l) {
  if (l.afocal) return fmt::format("mean RMS angular spot {:.6f} mrad", 1e3 * l.angular_spot_rad);
  std::string out = fmt::format("mean spot {:.4f} um", l.spot_mm * 1000);
  if (l.merit == DesignMerit::kWavefront)
    out = fmt::format("mean RMS wavefront {:.5f} waves, ", l.wavefront_waves) + out;
  return out;
}

// The mean RMS wavefront (waves, piston and tilt removed) of a lens traced as `analyze` traces
// it (its spec mode, `sampling`'s fields) on a 32 x 32 pupil grid, with the lens's wavelength
// weights: the full-sampling measure of the wavefront merit.
double full_wavefront_waves(const Lens& lens, const TraceOptions& sampling) {
  const TraceSystem<double> sys = prepare_lens_system(lens, sampling);
  std::vector<double> weights;
  if (static_cast<int>(lens.specs.wavelength_weights.size()) == sys.wavelength_count)
    weights = lens.specs.wavelength_weights;
  const double w = mean_rms_wavefront(sys, make_pupil_grid(32), weights);
  return std::isfinite(w) ? w : std::numeric_limits<double>::infinity();
}

// Rounds of LM with reweighting; x is updated in place. Returns the final double loss.
DesignLoss<double> run_phase(const LensParameterization& param, std::vector<double>& x,
                             GlassMode mode, const std::vector<int>& fixed,
                             const std::vector<int>& frozen, const OptimizeOptions& options,
                             DesignLossOptions& loss, const std::string& name, int max_rounds,
                             int max_iterations, Counters& counters, TargetTerms& targets,
                             double glass_weight_growth = 1.0) {
  const int n = param.size();
  DesignLoss<double> current = evaluate_double(param, x, mode, fixed, options.sampling, loss);
  double radius = 1e4;  // Ceres's default initial trust region; carried between rounds
  for (int round = 0; round < max_rounds; ++round) {
    if (options.interrupt && options.interrupt->load()) break;
    if (static_cast<int>(frozen.size()) >= n) break;
    const std::vector<double>& field_merit = current.field_merit();
    const int field_count = static_cast<int>(field_merit.size());
    // a_h = phi_h / (Phi S_h0): the field weights of the spot average (analysis/spot.h).
    std::vector<double> weights(field_count);
    double phi_sum = 0.0;
    for (int h = 0; h < field_count; ++h)
      phi_sum += static_cast<int>(current.field_weights.size()) == field_count
                     ? current.field_weights[h]
                     : 1.0;
    for (int h = 0; h < field_count; ++h)
      weights[h] = phi_sum == field_count
                       ? 1.0 / (field_count * std::max(field_merit[h], 1e-5))
                       : current.field_weights[h] / (phi_sum * std::max(field_merit[h], 1e-5));
    auto* functor = new DesignFunctor{&param,
                                      mode,
                                      fixed,
                                      options.sampling,
                                      loss,
                                      weights,
                                      &counters.evaluations,
                                      &counters.trajectory};
    ceres::Problem problem;
    problem.AddResidualBlock(
        make_free_jacobian_cost(functor, n, residual_count(param, options.sampling, loss), frozen),
        nullptr, x.data());
    // The profile bounds, at the clear semi-apertures of this round's start.
    const ProfileBoundSetup bounds = profile_bound_setup(param, x, mode, fixed);
    if (bounds.count > 0) {
      auto* cost = new ceres::DynamicAutoDiffCostFunction<ProfileBoundFunctor, kStride>(
          new ProfileBoundFunctor{&param, mode, fixed, bounds.heights_mm,
                                  loss.max_surface_slope_deg, loss.weight_profile});
      cost->AddParameterBlock(n);
      cost->SetNumResiduals(bounds.count);
      problem.AddResidualBlock(cost, nullptr, x.data());
    }
    // The designer's targets (targets.h): a residual block of their own, exact Jets.
    const int target_count = target_residuals(param, x, mode, fixed, options.sampling, targets);
    if (target_count > 0)
      problem.AddResidualBlock(
          make_free_jacobian_cost(
              new TargetFunctor{&param, mode, fixed, options.sampling, &targets, targets.lambda}, n,
              target_count, frozen),
          nullptr, x.data());
    const int edge_count = static_cast<int>(targets.edges.spaces.size());
    if (edge_count > 0)
      problem.AddResidualBlock(
          make_free_jacobian_cost(
              new EdgeFunctor{&param, mode, fixed, &targets.edges, targets.edges.lambda}, n,
              edge_count, frozen),
          nullptr, x.data());
    if (!frozen.empty()) problem.SetManifold(x.data(), new ceres::SubsetManifold(n, frozen));
    ceres::Solver::Options solver;
    solver.minimizer_type = ceres::TRUST_REGION;
    solver.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    solver.linear_solver_type = ceres::DENSE_QR;
    solver.max_num_iterations = max_iterations;
    solver.initial_trust_region_radius = radius;
    // (1e-5 for the wavefront merit saved the Cooke's creeping strict rounds but stopped the
    // AC254-100 achromat at 0.186 waves against 0.092: BENCHMARKS.md, wave-merit.)
    solver.function_tolerance = 1e-6;
    solver.gradient_tolerance = 1e-12;
    solver.parameter_tolerance = 1e-8;
    solver.num_threads = 1;  // the loss parallelizes over fields itself
    solver.update_state_every_iteration = true;
    solver.logging_type = ceres::SILENT;
    // The wavefront merit's strict rounds creep (the Cooke's: 1 % of the cost in 30-50
    // iterations, l_RP of nanometres traded against the merit's fourth digit), so they end when
    // 10 iterations gain less than 0.1 % (BENCHMARKS.md, wave-merit).
    const bool creeping = loss.merit == DesignMerit::kWavefront && !loss.paper_penalties;
    ProgressCallback progress(fmt::format("{} round {}", name, round + 1), options.verbose,
                              options.interrupt, creeping ? kStallWindow : 0, kStallRelative);
    solver.callbacks.push_back(&progress);
    ceres::Solver::Summary summary;
    ceres::Solve(solver, &problem, &summary);
    counters.iterations += static_cast<int>(summary.iterations.size());
    counters.jacobians += summary.num_jacobian_evaluations;
    counters.termination = summary.message;
    if (!summary.iterations.empty())
      radius = std::max(summary.iterations.back().trust_region_radius, 1e-2);
    const DesignLoss<double> next = evaluate_double(param, x, mode, fixed, options.sampling, loss);
    // Raise the weight of a constraint still violated (strict penalties only).
    bool violated = false;
    if (!loss.paper_penalties && next.ray_path_mm > 0 && loss.weight_ray_path < 1e8) {
      loss.weight_ray_path *= 10;
      violated = true;
    }
    if (!loss.paper_penalties && next.ray_angle > 0 && loss.weight_ray_angle < 1e8) {
      loss.weight_ray_angle *= 10;
      violated = true;
    }
    if (profile_violation(param, x, mode, fixed, bounds, loss.max_surface_slope_deg) > 0 &&
        loss.weight_profile < 1e8) {
      loss.weight_profile *= 10;
      violated = true;
    }
    if (target_count > 0 && targets.lambda < 1e10 &&
        !targets_met(param, x, mode, fixed, options.sampling, targets)) {
      targets.lambda *= 10;
      violated = true;
    }
    if (edge_count > 0 && targets.edges.lambda < 1e10) {
      const TraceLens<double> tl = param.to_trace_lens(x.data(), mode, fixed);
      bool short_edge = false;
      for (std::size_t i = 0; i < targets.edges.spaces.size(); ++i)
        short_edge = short_edge ||
                     glass_edge_mm(tl, targets.edges.spaces[i], targets.edges.last[i],
                                   targets.edges.heights_mm[i]) < targets.edges.min_edge_mm + 1e-3;
      if (short_edge) {
        targets.edges.lambda *= 10;
        violated = true;
      }
    }
    loss.weight_glass *= glass_weight_growth;
    const double change = std::abs(next.merit_value() - current.merit_value()) /
                          std::max(current.merit_value(), 1e-9);
    if (options.verbose) {
      fmt::print(stderr,
                 "lensopt optimize: {} round {}: {} (optimization sampling), "
                 "l_RP {:.2e}, l_RA {:.2e}, l_GV {:.2e}, {} failed rays; {} iterations\n",
                 name, round + 1, merit_text(next), next.ray_path_mm, next.ray_angle, next.glass,
                 next.failed_rays, summary.iterations.size());
    }
    current = next;
    // A round that ran out of iterations has not converged, however little it changed the merit
    // (a short round can spend its iterations shrinking the trust region from its start): the
    // next round continues from its radius.
    const bool converged = summary.termination_type != ceres::NO_CONVERGENCE;
    if (!violated && change < 2e-3 && glass_weight_growth == 1.0 && converged) break;
  }
  return current;
}

// Bounds between the start's own extremes (t = 0: the start is feasible) and the target bounds
// (t = 1), for the constraints the start violates: constraint continuation, so that a start
// outside the feasible set is walked into it instead of being thrown out of its basin.
DesignLossOptions continued_bounds(const DesignLossOptions& target, const DesignExtremes& start,
                                   const Lens& structure, double t) {
  DesignLossOptions out = target;
  const int k_count = static_cast<int>(structure.surfaces.size());
  const std::vector<int> first = element_first_spaces(structure);
  double min_air = std::numeric_limits<double>::infinity(), min_glass = min_air;
  double max_glass = -min_air;
  for (int k = 0; k + 1 < k_count; ++k) {
    if (!element_last_space(first, k)) continue;  // a split element: its summed travel at its end
    if (stop_at_vertex_space(structure, k)) continue;  // the stop on a vertex: no air gap
    if (structure.surfaces[k].material.is_air()) {
      min_air = std::min(min_air, start.min_travel_mm[k]);
    } else {
      min_glass = std::min(min_glass, start.min_travel_mm[k]);
      max_glass = std::max(max_glass, start.max_travel_mm[k]);
    }
  }
  const double clearance = start.min_travel_mm[k_count - 1];
  const double angle_deg =
      std::acos(std::sqrt(std::clamp(start.min_cos2_angle, 0.0, 1.0))) * 180.0 / kPi;
  auto lower = [t](double bound, double value) {
    return value < bound ? (value - 1e-4) + t * (bound - value + 1e-4) : bound;
  };
  auto upper = [t](double bound, double value) {
    return value > bound ? (value + 1e-4) + t * (bound - value - 1e-4) : bound;
  };
  out.min_air_mm = lower(target.min_air_mm, min_air);
  out.min_glass_mm = lower(target.min_glass_mm, min_glass);
  out.max_glass_mm = upper(target.max_glass_mm, max_glass);
  out.min_image_clearance_mm = lower(target.min_image_clearance_mm, clearance);
  if (target.virtual_image()) {
    // A virtual image: the image travel dz in [-max, -min] (design_loss.h), continued as the
    // other bounds from the start's own extremes.
    out.max_virtual_image_mm =
        upper(target.max_virtual_image_mm, -start.min_travel_mm[k_count - 1]);
    out.min_virtual_image_mm =
        lower(target.min_virtual_image_mm, -start.max_travel_mm[k_count - 1]);
  }
  out.max_ray_angle_deg = upper(target.max_ray_angle_deg, angle_deg);
  return out;
}

bool constraints_met(const DesignLoss<double>& loss) {
  return loss.ray_path_mm <= 1e-12 && loss.ray_angle <= 1e-12 && loss.failed_rays == 0;
}

}  // namespace

OptimizeOptions::OptimizeOptions() {
  sampling.rings = 8;
  sampling.fields = 11;
}

void OptimizeOptions::validate() const {
  sampling.validate();
  loss.validate();
  if (glass_neighbours < 0 || glass_neighbours > 64)
    throw Error(fmt::format("glass_neighbours = {} must be in [0, 64]", glass_neighbours));
  if (max_iterations < 1) throw Error("max_iterations must be >= 1");
  if (max_rounds < 1) throw Error("max_rounds must be >= 1");
}

void DesignLossOptions::validate() const {
  auto positive = [](double v, const char* name) {
    if (!(v >= 0.0) || !std::isfinite(v))
      throw Error(fmt::format("{} = {} must be a finite number >= 0", name, v));
  };
  positive(weight_spot, "weight_spot");
  positive(weight_ray_path, "weight_ray_path");
  positive(weight_ray_angle, "weight_ray_angle");
  positive(weight_glass, "weight_glass");
  positive(min_air_mm, "min_air_mm");
  positive(min_glass_mm, "min_glass_mm");
  positive(max_glass_mm, "max_glass_mm");
  positive(min_image_clearance_mm, "min_image_clearance_mm");
  positive(min_virtual_image_mm, "min_virtual_image_mm");
  positive(max_virtual_image_mm, "max_virtual_image_mm");
  if (virtual_image() && max_virtual_image_mm < min_virtual_image_mm)
    throw Error(fmt::format("max_virtual_image_mm = {} is below min_virtual_image_mm = {}",
                            max_virtual_image_mm, min_virtual_image_mm));
  if (max_glass_mm < min_glass_mm)
    throw Error(
        fmt::format("max_glass_mm = {} is below min_glass_mm = {}", max_glass_mm, min_glass_mm));
  if (!(max_ray_angle_deg > 0.0 && max_ray_angle_deg < 90.0))
    throw Error(fmt::format("max_ray_angle_deg = {} must be in (0, 90)", max_ray_angle_deg));
  positive(weight_profile, "weight_profile");
  positive(wavefront_unit_mm, "wavefront_unit_mm");
  if (wavefront_pupil_samples < 4 || wavefront_pupil_samples > 256)
    throw Error(
        fmt::format("wavefront_pupil_samples = {} must be in [4, 256]", wavefront_pupil_samples));
  if (!(max_surface_slope_deg > 0.0 && max_surface_slope_deg < 90.0))
    throw Error(
        fmt::format("max_surface_slope_deg = {} must be in (0, 90)", max_surface_slope_deg));
}

bool ConstraintReport::all_pass() const {
  if (ray_failures > 0) return false;
  for (const Row& r : rows)
    if (!r.pass) return false;
  return true;
}

namespace {

bool is_paper_lens_impl(const Lens& lens);

}  // namespace

// The catalog the optimizer picks glasses from: the lens's own; for a lens of model glasses
// (nd, vd), the paper's for the paper's lenses, else the catalog whose glasses lie nearest to
// the lens's (the least sum over its glasses of the squared glass-map distance
// (100 dnd)^2 + dvd^2 to the nearest catalog glass; ties to the first of ohara, SCHOTT, OHARA,
// HOYA, CDGM), so a start with a vendor's (nd, vd) keeps that vendor's glasses.
std::string glass_catalog_for(const Lens& lens) {
  if (!lens.catalog_name.empty()) return lens.catalog_name;
  if (is_paper_lens_impl(lens)) return "ohara";
  std::vector<std::string> names = {"ohara"};
  for (const std::string& n : shipped_catalog_names()) names.push_back(n);
  std::string best = "ohara";
  double best_sum = std::numeric_limits<double>::infinity();
  for (const std::string& name : names) {
    std::shared_ptr<const Catalog> catalog;
    try {
      catalog = load_catalog(name);
    } catch (const Error&) {
      continue;
    }
    double sum = 0.0;
    for (const Surface& surface : lens.surfaces) {
      if (surface.material.is_air()) continue;
      const auto nearest = catalog->closest_by_index(surface.material.nd, surface.material.vd, 1);
      if (nearest.empty()) {
        sum = std::numeric_limits<double>::infinity();
        break;
      }
      const double dn = 100.0 * (nearest[0]->nd - surface.material.nd);
      const double dv = nearest[0]->vd - surface.material.vd;
      sum += dn * dn + dv * dv;
    }
    if (sum < best_sum) {
      best_sum = sum;
      best = name;
    }
  }
  return best;
}

namespace {

GlassSpace glass_space_for(const Lens& lens) {
  return GlassSpace(*load_catalog(glass_catalog_for(lens)));
}

}  // namespace

ConstraintReport check_constraints(const Lens& lens, const DesignLossOptions& loss,
                                   const TraceOptions& sampling) {
  const LensParameterization param(lens, glass_space_for(lens));
  const std::vector<double> x = param.from_lens(lens);
  DesignExtremes ext;
  const DesignLoss<double> l =
      evaluate_double(param, x, GlassMode::kContinuous, {}, sampling, loss, &ext);
  ConstraintReport report;
  report.ray_failures = l.failed_rays;
  const int k_count = static_cast<int>(lens.surfaces.size());
  const std::vector<int> first = element_first_spaces(lens);
  for (int k = 0; k < k_count; ++k) {
    const bool last = k == k_count - 1;
    const bool glass = !lens.surfaces[k].material.is_air();
    // A glass element split by a dummy or stop surface: one row pair, of its summed travel.
    if (!element_last_space(first, k)) continue;
    if (stop_at_vertex_space(lens, k)) continue;  // the stop on a vertex: no air gap to bound
    if (last && loss.virtual_image()) {
      // A virtual image (design_loss.h): how far before the last surface the rays are traced
      // back, -dz, within [min, max].
      const double nearest = -ext.max_travel_mm[k], farthest = -ext.min_travel_mm[k];
      report.rows.push_back({"virtual image distance min", nearest, loss.min_virtual_image_mm, true,
                             nearest >= loss.min_virtual_image_mm});
      report.rows.push_back({"virtual image distance max", farthest, loss.max_virtual_image_mm,
                             false, farthest <= loss.max_virtual_image_mm});
    } else if (last && lens.specs.afocal) {
      continue;  // an image at infinity: no image plane to clear (design_loss.h)
    } else if (last) {
      report.rows.push_back({"image clearance", ext.min_travel_mm[k], loss.min_image_clearance_mm,
                             true, ext.min_travel_mm[k] >= loss.min_image_clearance_mm});
    } else if (glass) {
      const std::string name =
          fmt::format("glass {}-{} ({})", first[k] + 1, k + 2, lens.surfaces[k].material.label());
      report.rows.push_back({name + " min", ext.min_travel_mm[k], loss.min_glass_mm, true,
                             ext.min_travel_mm[k] >= loss.min_glass_mm});
      report.rows.push_back({name + " max", ext.max_travel_mm[k], loss.max_glass_mm, false,
                             ext.max_travel_mm[k] <= loss.max_glass_mm});
    } else {
      report.rows.push_back({fmt::format("air {}-{}", k + 1, k + 2), ext.min_travel_mm[k],
                             loss.min_air_mm, true, ext.min_travel_mm[k] >= loss.min_air_mm});
    }
  }
  const double max_angle_deg =
      std::acos(std::sqrt(std::clamp(ext.min_cos2_angle, 0.0, 1.0))) * 180.0 / kPi;
  report.rows.push_back({"largest ray angle (deg)", max_angle_deg, loss.max_ray_angle_deg, false,
                         max_angle_deg <= loss.max_ray_angle_deg});
  // Profile bounds (profile_bounds.h) of the conics and aspheres, at the lens's clear apertures.
  const TraceLens<double> traced = param.to_trace_lens(x.data(), GlassMode::kContinuous, {});
  if (profile_bound_count(traced) > 0) {
    double slope_deg = 0.0, min_q2 = 1.0;
    profile_extremes(traced, paraxial_clear_semi_apertures_mm(traced, lens.specs), slope_deg,
                     min_q2);
    report.rows.push_back({"steepest profile slope (deg)", slope_deg, loss.max_surface_slope_deg,
                           false,
                           slope_deg <= loss.max_surface_slope_deg && min_q2 >= kProfileMinDomain});
  }
  // Clear apertures: the rays a surface's semi_diameter_mm clips, traced as analyze traces them.
  bool apertures = false;
  for (const Surface& s : lens.surfaces) apertures = apertures || s.semi_diameter_mm > 0.0;
  if (apertures) {
    int vignetted = 0;
    try {
      // (measure_fields without its maps: the rays alone, which an afocal lens traces too.)
      const FieldOptics<double> f =
          measure_fields(prepare_lens_system(lens, sampling), FieldOpticsOptions{false, 0});
      for (int v : f.spots.vignetted_rays) vignetted += v;
    } catch (const Error&) {
      vignetted = std::numeric_limits<int>::max();
    }
    report.rows.push_back({"rays vignetted by clear apertures", static_cast<double>(vignetted), 0.0,
                           false, vignetted == 0});
  }
  return report;
}

bool is_paper_lens(const Lens& lens) {
  return is_paper_lens_impl(lens);
}

namespace {
bool is_paper_lens_impl(const Lens& lens) {
  const std::string extension = lower_extension(lens.source_path);
  return extension == ".yml" || extension == ".yaml" || lens.catalog_name == "ohara";
}
}  // namespace

DesignLossOptions lens_derived_bounds(const Lens& lens, const DesignLossOptions& paper) {
  DesignLossOptions out = paper;
  // The lens's length unit: |f|, or an afocal lens's vertex length (variables.h).
  const double f = design_length_unit_mm(lens);
  const double s = std::isfinite(f) && f > 0.0 ? f / 50.0 : 1.0;
  out.min_air_mm = s * paper.min_air_mm;
  out.min_glass_mm = s * paper.min_glass_mm;
  out.max_glass_mm = s * paper.max_glass_mm;
  out.min_image_clearance_mm = s * paper.min_image_clearance_mm;
  const LensParameterization param(lens, glass_space_for(lens));
  const std::vector<double> x = param.from_lens(lens);
  DesignExtremes ext;
  const DesignLoss<double> l =
      evaluate_double(param, x, GlassMode::kContinuous, {}, AnalyzeOptions{}.trace, paper, &ext);
  const int k_count = static_cast<int>(lens.surfaces.size());
  // The extremes of the rays that trace (a failed ray up to its failing surface): a space no
  // ray crosses has nothing to derive its bound from (never the paper's bound in silence).
  for (int k = 0; k < k_count; ++k) {
    const bool crossed = k < static_cast<int>(ext.min_travel_mm.size()) &&
                         std::isfinite(ext.min_travel_mm[k]) && std::isfinite(ext.max_travel_mm[k]);
    if (!crossed)
      throw Error(SourceLocation{lens.source_path},
                  fmt::format("bounds derived from the start: no ray of the start crosses the "
                              "space after surface {} ({} of its rays fail); give the bounds "
                              "(--min-air-mm, --min-glass-mm, --max-glass-mm, "
                              "--min-image-clearance-mm or [optimize] keys), or --bounds paper",
                              k + 1, l.failed_rays));
  }
  double min_air = std::numeric_limits<double>::infinity(), min_glass = min_air;
  double max_glass = 0.0;
  const std::vector<int> first = element_first_spaces(lens);
  for (int k = 0; k + 1 < k_count; ++k) {
    // A glass element split by a dummy or stop surface (glass_elements.h): its summed travel, at
    // its last space (a half of it may be 0 mm thick on axis and bounds nothing).
    if (!element_last_space(first, k) || stop_at_vertex_space(lens, k)) continue;
    if (lens.surfaces[k].material.is_air()) {
      // A zero-thickness air space (a stop at a vertex) bounds nothing.
      if (ext.max_travel_mm[k] > 0.0) min_air = std::min(min_air, ext.min_travel_mm[k]);
    } else {
      min_glass = std::min(min_glass, ext.min_travel_mm[k]);
      max_glass = std::max(max_glass, ext.max_travel_mm[k]);
    }
  }
  const double clearance = ext.min_travel_mm[k_count - 1];
  const double angle_deg =
      std::acos(std::sqrt(std::clamp(ext.min_cos2_angle, 0.0, 1.0))) * 180.0 / kPi;
  if (std::isfinite(min_air))
    out.min_air_mm = std::min(out.min_air_mm, std::max(0.0, 0.5 * min_air));
  if (std::isfinite(min_glass))
    out.min_glass_mm = std::min(out.min_glass_mm, std::max(0.0, 0.5 * min_glass));
  if (max_glass > 0.0) out.max_glass_mm = std::max(out.max_glass_mm, 1.5 * max_glass);
  if (std::isfinite(clearance))
    out.min_image_clearance_mm =
        std::min(out.min_image_clearance_mm, std::max(0.0, 0.75 * clearance));
  if (std::isfinite(angle_deg))
    out.max_ray_angle_deg = std::min(85.0, std::max(paper.max_ray_angle_deg, angle_deg + 2.0));
  return out;
}

DesignLossOptions bounds_for(const Lens& lens, const DesignLossOptions& paper, BoundsMode mode) {
  const bool use_paper =
      mode == BoundsMode::kPaper || (mode == BoundsMode::kAuto && is_paper_lens(lens));
  // A diverging lens's virtual image is bounded by its own start (virtual_image.h).
  return with_virtual_image_bounds(lens, use_paper ? paper : lens_derived_bounds(lens, paper));
}

double design_spot_mm(const LensParameterization& param, const std::vector<double>& x,
                      GlassMode mode, const std::vector<int>& fixed_glasses,
                      const OptimizeOptions& options) {
  return evaluate_double(param, x, mode, fixed_glasses, options.sampling, options.loss).spot_mm;
}

namespace {

// optimize_lens in named steps (its header comment states the order): the state every step
// shares, one method per phase.
class LensOptimization {
 public:
  LensOptimization(const Lens& start, const OptimizeOptions& options)
      : start_(start),
        options_(options),
        param_(start, glass_space_for(start), options.vary),
        x_(param_.from_lens(start)),
        wavefront_(options.loss.merit == DesignMerit::kWavefront),
        afocal_(start.specs.afocal),
        soft_(options.loss.paper_penalties) {
    // Which variables are free and why (variables.h choose_variables: pickups and solves,
    // the explicit freeze / vary lists, the file's vary flags); the report says so.
    const VariableChoice choice =
        choose_variables(param_, options.freeze, options.vary, options.focus_only);
    frozen_user_ = choice.held;
    variable_report_ = choice.report;
    // A dummy surface 0 mm before the next inside a glass element (the flat stop the .zmx reader
    // puts at the vertex of a curved stop surface) stays there: its spacing is held.
    const std::vector<int> element_first = element_first_spaces(start);
    for (int i = 0; i < param_.size(); ++i) {
      const LensVariable& v = param_.variables()[i];
      if (v.kind == LensVariable::Kind::kSpacing && element_first[v.surface] != v.surface &&
          start.surfaces[v.surface].thickness_mm == 0.0)
        frozen_user_.push_back(i);
      // So does a flat stop 0 mm before the surface whose vertex it marks (glass_elements.h).
      if (v.kind == LensVariable::Kind::kSpacing && stop_at_vertex_space(start, v.surface))
        frozen_user_.push_back(i);
    }
    for (int i = 0; i < param_.size(); ++i) {
      const auto kind = param_.variables()[i].kind;
      if (kind == LensVariable::Kind::kGlass0 || kind == LensVariable::Kind::kGlass1)
        glass_indices_.push_back(i);
    }
    frozen_all_ = frozen_user_;
    frozen_all_.insert(frozen_all_.end(), glass_indices_.begin(), glass_indices_.end());
    std::sort(frozen_all_.begin(), frozen_all_.end());
    frozen_all_.erase(std::unique(frozen_all_.begin(), frozen_all_.end()), frozen_all_.end());
    const bool glasses_frozen_by_user =
        std::all_of(glass_indices_.begin(), glass_indices_.end(), [&](int i) {
          return std::find(frozen_user_.begin(), frozen_user_.end(), i) != frozen_user_.end();
        });
    search_ = options.glass_search != GlassSearch::kNone && !glasses_frozen_by_user &&
              !options.focus_only;
    loss_ = soft_ ? options.loss : with_margin(options.loss);
    // The residual targets (the solved ones are met by the start and the forward map).
    for (const DesignTarget& t : options.targets)
      if (!target_is_solved(t.quantity)) targets_.targets.push_back(t);
    targets_.sampling.threads = options.sampling.threads;
    targets_.edges = edge_bound_for(start, options.loss.min_glass_mm);
    targets_.sampling.wavefront_grid = wavefront_merit_pupil(options.loss.wavefront_pupil_samples);
    bool wave_target = false;
    for (const DesignTarget& t : targets_.targets)
      wave_target = wave_target || t.quantity == TargetQuantity::kRmsWavefrontWaves;
    if (wave_target) {
      const double unit = wavefront_mm_per_wave(prepare_lens_system(start, options.sampling));
      targets_.wave_unit_mm = std::isfinite(unit) && unit > 0.0 ? unit : 0.0;
    }
  }

  OptimizeResult run() {
    const auto clock_start = std::chrono::steady_clock::now();
    result_.log.insert(result_.log.end(), variable_report_.begin(), variable_report_.end());
    measure_start();
    // Phase A: the start's glasses, snapped to the catalog and held; LM on the rest, with the
    // bounds the start violates tightened in stages from its own values to the targets.
    fixed_ = param_.nearest_glasses(x_.data());
    set_glasses(x_, fixed_);
    focus();
    soft_start();
    fixed_glasses();
    if (search_ && !interrupted()) continuous_glasses();
    if (search_ && options_.glass_search == GlassSearch::kNeighbours &&
        options_.glass_neighbours > 0)
      neighbour_glasses();
    finish();
    result_.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - clock_start).count();
    return std::move(result_);
  }

 private:
  bool interrupted() const { return options_.interrupt && options_.interrupt->load(); }
  // With the paper's soft penalties a candidate is judged by l_lens; strictly, by the merit
  // among designs that meet every constraint.
  bool feasible(const DesignLoss<double>& l) const { return soft_ || constraints_met(l); }
  // The targets met at the optimization sampling (targets_met) by variables x, glasses `fixed`.
  bool targets_ok(const std::vector<double>& x, const std::vector<int>& fixed) const {
    return targets_met(param_, x, GlassMode::kFixed, fixed, options_.sampling, targets_);
  }
  bool better(const DesignLoss<double>& a, const DesignLoss<double>& b) const {
    return soft_ ? a.total < b.total * (1 - 1e-4) : a.merit_value() < b.merit_value() * (1 - 1e-3);
  }
  // Puts the whitened points of catalog glasses `glasses` into the glass variables of xs.
  void set_glasses(std::vector<double>& xs, const std::vector<int>& glasses) const {
    for (std::size_t pair = 0; 2 * pair < glass_indices_.size(); ++pair) {
      const Eigen::Vector2d p = param_.glass_space().glass_point(glasses[pair]);
      xs[glass_indices_[2 * pair]] = p[0];
      xs[glass_indices_[2 * pair + 1]] = p[1];
    }
  }
  DesignLoss<double> phase(std::vector<double>& x, GlassMode mode, const std::vector<int>& fixed,
                           const std::vector<int>& frozen, DesignLossOptions& loss,
                           const std::string& name, int rounds, int iterations,
                           double glass_weight_growth = 1.0) {
    return run_phase(param_, x, mode, fixed, frozen, options_, loss, name, rounds, iterations,
                     counters_, targets_, glass_weight_growth);
  }

  // The glass edge-thickness rows (EdgeBound) of `lens` (at its spec scale).
  void add_edge_rows(ConstraintReport& report, const Lens& lens) const {
    const EdgeBound& e = targets_.edges;
    if (e.spaces.empty()) return;
    const TraceLens<double> tl = scaled_trace_lens(lens);
    for (std::size_t i = 0; i < e.spaces.size(); ++i) {
      const int k = e.spaces[i], m = e.last[i];
      const double v = glass_edge_mm(tl, k, m, e.heights_mm[i]);
      report.rows.push_back(
          {fmt::format("glass {}-{} edge at {:.3g} mm", k + 1, m + 2, e.heights_mm[i]), v,
           e.min_edge_mm, true, v >= e.min_edge_mm});
    }
  }

  // An afocal lens's mean RMS angular spot (mrad, +inf when a field has no ray) and its fields at
  // full sampling, as `analyze` reports them (analysis/afocal.h, without the wavefront).
  void measure_afocal(const Lens& lens, double& mean_mrad, std::vector<double>& field_mrad) const {
    AfocalOptions afocal;
    afocal.wavefront = false;
    const AfocalReport r = analyze_afocal_lens(lens, full_.trace, afocal);
    mean_mrad = r.mean_rms_angular_spot_mrad.value_or(std::numeric_limits<double>::infinity());
    field_mrad.clear();
    for (const AfocalField& f : r.fields)
      field_mrad.push_back(f.rms_angular_spot_mrad.value_or(0.0));
  }

  // The start at full sampling.
  void measure_start() {
    if (options_.verbose)
      fmt::print(stderr, "lensopt optimize: {}\n",
                 describe_design_sampling(param_.structure(), options_.sampling));
    result_.afocal = afocal_;
    if (afocal_) {
      measure_afocal(start_, result_.start_angular_spot_mrad,
                     result_.start_field_angular_spot_mrad);
    } else {
      const AnalysisReport start_report = analyze_lens(start_, full_);
      result_.start_spot_um =
          start_report.mean_rms_spot_um.value_or(std::numeric_limits<double>::infinity());
      for (const FieldReport& f : start_report.fields)
        result_.start_field_spot_um.push_back(f.rms_spot_um.value_or(0.0));
    }
    result_.start_constraints = check_constraints(start_, options_.loss, full_.trace);
    add_edge_rows(result_.start_constraints, start_);
    if (wavefront_) result_.start_wavefront_waves = full_wavefront_waves(start_, full_.trace);
  }

  // The loss of the first phases, which pick the basin (focus, soft start): the paper's soft
  // penalties, and the spot merit whatever the merit. The wavefront merit starts from the spot
  // merit's basin: with the soft penalties, whose weights are set against a merit in mm (the
  // spot, ~0.02 mm on the Cooke; the wavefront is ~2 waves), it crosses the bounds a hundred
  // times further than the spot merit does (Cooke: l_RP 5.5e-4 against 1.5e-7 mm) and the
  // strict phases then lose more walking it back than it gained (2.05 -> 2.51 waves at the
  // optimization sampling); with the penalties rescaled to the wavefront's unit it lands in a
  // worse basin (3.26 waves). The RMS spot is the RMS slope of the wavefront (transverse ray
  // aberration = -(R / r_p) dW/drho), the smoother merit for finding the basin; the wavefront
  // merit then takes over at the strict phases (BENCHMARKS.md, wave-merit).
  DesignLossOptions basin_loss() const {
    DesignLossOptions loss = options_.loss;
    loss.paper_penalties = true;
    loss.merit = DesignMerit::kSpot;
    return loss;
  }

  // Focus first: a start far from focus (a perturbed last spacing is a defocus of a tenth of the
  // back focal length) has a spot dominated by defocus, and LM's first steps on all variables
  // then bend the curvatures to compensate and land in a poor basin. The defocus alone is
  // nearly quadratic, so one short LM round on it (soft penalties) removes it first.
  void focus() {
    if (interrupted()) return;
    std::vector<int> all_but_defocus;
    bool defocus_free = false;
    for (int i = 0; i < param_.size(); ++i) {
      const bool frozen = std::binary_search(frozen_all_.begin(), frozen_all_.end(), i);
      if (param_.variables()[i].kind == LensVariable::Kind::kDefocus && !frozen)
        defocus_free = true;
      else
        all_but_defocus.push_back(i);
    }
    if (!defocus_free) return;
    DesignLossOptions focus_loss = basin_loss();
    // The merit alone (no target): a target that moves the image plane (total track, BFL) would
    // otherwise defocus the start before any other variable can meet it; a --focus-only run
    // holds its targets in the phases after this one.
    TargetTerms no_targets;
    const DesignLoss<double> f =
        run_phase(param_, x_, GlassMode::kFixed, fixed_, all_but_defocus, options_, focus_loss,
                  "focus", 1, options_.max_iterations, counters_, no_targets);
    result_.log.push_back(fmt::format("focus: {} (optimization sampling)", merit_text(f)));
  }

  // Phase 0 (strict constraints only): the paper's soft penalties first. Squared hinges summed
  // over rays push a start that crosses a bound straight back inside, often into a worse basin
  // (the Cooke baseline: 30.6 -> 40.0 um); the soft loss first finds the good basin, where the
  // design crosses its bounds only slightly, and the continuation then walks it inside.
  void soft_start() {
    if (soft_ || !options_.soft_start || interrupted()) return;
    DesignLossOptions soft_loss = basin_loss();
    const DesignLoss<double> s =
        phase(x_, GlassMode::kFixed, fixed_, frozen_all_, soft_loss, "soft penalties",
              options_.max_rounds, options_.max_iterations);
    result_.log.push_back(fmt::format("soft penalties: {} (optimization sampling)", merit_text(s)));
  }

  // The bounds continued from the start's extremes to the targets (25, 50, 75 %), then LM with
  // the fixed glasses at the target bounds: the design every later phase must beat.
  // The wavefront merit skips the continuation when its strict phases start from a spot-merit
  // soft design (basin_loss) that crosses its bounds only slightly (within 0.01 mm and 0.5 deg:
  // the Cooke's, l_RP 1.5e-7 mm, l_RA 1.6e-6): each stage, changing the merit as well, ran to its
  // 20-iteration limit (63 of the 266 iterations of the Cooke run) for a design the target round
  // then moves anyway. A start still far outside (short rounds) is walked in as before.
  void fixed_glasses() {
    DesignExtremes start_extremes;
    evaluate_double(param_, x_, GlassMode::kFixed, fixed_, options_.sampling, loss_,
                    &start_extremes);
    const DesignLossOptions target_loss = loss_;
    const DesignLossOptions from = continued_bounds(target_loss, start_extremes, start_, 0.0);
    const double length_gap_mm = std::max(
        {std::abs(from.min_air_mm - target_loss.min_air_mm),
         std::abs(from.min_glass_mm - target_loss.min_glass_mm),
         std::abs(from.max_glass_mm - target_loss.max_glass_mm),
         target_loss.virtual_image()
             ? std::max(std::abs(from.min_virtual_image_mm - target_loss.min_virtual_image_mm),
                        std::abs(from.max_virtual_image_mm - target_loss.max_virtual_image_mm))
             : std::abs(from.min_image_clearance_mm - target_loss.min_image_clearance_mm)});
    const double angle_gap_deg = std::abs(from.max_ray_angle_deg - target_loss.max_ray_angle_deg);
    const bool nearly_inside = length_gap_mm <= 0.01 && angle_gap_deg <= 0.5;
    for (double t : {0.25, 0.5, 0.75}) {
      if (interrupted() || soft_ || (wavefront_ && options_.soft_start && nearly_inside)) break;
      DesignLossOptions stage = continued_bounds(target_loss, start_extremes, start_, t);
      phase(x_, GlassMode::kFixed, fixed_, frozen_all_, stage,
            fmt::format("constraints {:.0f}%", 100 * t), 1, std::min(options_.max_iterations, 20));
      loss_.weight_ray_path = std::max(loss_.weight_ray_path, stage.weight_ray_path);
      loss_.weight_ray_angle = std::max(loss_.weight_ray_angle, stage.weight_ray_angle);
    }
    best_ = phase(x_, GlassMode::kFixed, fixed_, frozen_all_, loss_, "fixed glasses",
                  options_.max_rounds, options_.max_iterations);
    result_.log.push_back(
        fmt::format("fixed glasses: {} (optimization sampling)", merit_text(best_)));
  }

  // Phase B: continuous glasses with an annealed glass-variable loss (its weight grows tenfold
  // per round, pulling each g onto a catalog glass), then snapped and re-optimized; kept only if
  // it beats phase A.
  void continuous_glasses() {
    std::vector<double> xc = x_;
    DesignLossOptions continuous_loss = loss_;
    phase(xc, GlassMode::kContinuous, {}, frozen_user_, continuous_loss, "continuous glasses", 4,
          options_.max_iterations, 10.0);
    std::vector<int> snapped = param_.nearest_glasses(xc.data());
    set_glasses(xc, snapped);
    DesignLossOptions snapped_loss = loss_;
    const DesignLoss<double> b = phase(xc, GlassMode::kFixed, snapped, frozen_all_, snapped_loss,
                                       "snapped", options_.max_rounds, options_.max_iterations);
    result_.log.push_back(fmt::format("continuous then snapped: {}", merit_text(b)));
    if (feasible(b) && targets_ok(xc, snapped) &&
        (!feasible(best_) || !targets_ok(x_, fixed_) || better(b, best_))) {
      x_ = xc;
      fixed_ = snapped;
      best_ = b;
      loss_ = snapped_loss;
      result_.log.push_back("kept the snapped continuous-glass design");
    }
  }

  // Phase C: up to glass_neighbours nearest catalog glasses per element, in passes until none
  // improves (at most 3), then a polish.
  void neighbour_glasses() {
    for (int pass = 0; pass < 3 && !interrupted(); ++pass) {
      bool improved = false;
      for (std::size_t m = 0; m < fixed_.size() && !interrupted(); ++m)
        improved = try_neighbours(m) || improved;
      if (!improved) break;
    }
    if (!result_.log.empty() && result_.log.back().rfind("element", 0) == 0)
      best_ = phase(x_, GlassMode::kFixed, fixed_, frozen_all_, loss_, "polish",
                    options_.max_rounds, options_.max_iterations);
  }
  // Element m's neighbouring glasses, nearest first; keeps each that beats the best design.
  bool try_neighbours(std::size_t m) {
    bool improved = false;
    const std::vector<int> order =
        param_.glass_space().by_distance(param_.glass_space().glass_point(fixed_[m]));
    int tried = 0;
    for (int candidate : order) {
      if (tried >= options_.glass_neighbours || interrupted()) break;
      if (candidate == fixed_[m]) continue;
      ++tried;
      std::vector<int> trial_fixed = fixed_;
      trial_fixed[m] = candidate;
      std::vector<double> trial_x = x_;
      set_glasses(trial_x, trial_fixed);
      DesignLossOptions trial_loss = loss_;
      const DesignLoss<double> trial =
          phase(trial_x, GlassMode::kFixed, trial_fixed, frozen_all_, trial_loss,
                fmt::format("element {} as {}", m + 1, param_.glass_space().name(candidate)), 2,
                std::max(10, options_.max_iterations / 3));
      if (feasible(trial) && targets_ok(trial_x, trial_fixed) && better(trial, best_)) {
        result_.log.push_back(fmt::format("element {}: {} -> {} ({})", m + 1,
                                          param_.glass_space().name(fixed_[m]),
                                          param_.glass_space().name(candidate), merit_text(trial)));
        fixed_ = trial_fixed;
        x_ = trial_x;
        best_ = trial;
        loss_ = trial_loss;
        improved = true;
      }
    }
    return improved;
  }

  // The lens of variables x with the phase's glasses, named and cataloged as the start.
  Lens result_lens(const std::vector<double>& x) const {
    Lens lens = param_.to_lens(x.data(), GlassMode::kFixed, fixed_);
    if (options_.focus_only) {
      // Refocused only: the start itself (at its spec scale) with the new image distance, its
      // glasses as they are (not replaced by their catalog neighbours).
      const double image_mm = lens.surfaces.back().thickness_mm;
      const double scale = lens_spec_scale(start_);
      lens = std::isfinite(scale) && scale > 0.0 && scale != 1.0 ? scaled(start_, scale) : start_;
      lens.surfaces.back().thickness_mm = image_mm;
      return lens;
    }
    lens.name = start_.name;
    lens.source_path = start_.source_path;
    // The glasses are the glass space's catalog glasses: name that catalog, so the lens reads
    // back (a start with model glasses has none).
    if (!glass_indices_.empty()) lens.catalog_name = glass_catalog_for(start_);
    // The clear apertures stay the start's (optimize_lens refuses a start they vignet; the
    // constraint check counts the rays the result's apertures clip).
    for (std::size_t k = 0; k < lens.surfaces.size(); ++k)
      lens.surfaces[k].semi_diameter_mm = start_.surfaces[k].semi_diameter_mm;
    return lens;
  }

  // Feasibility at the check's fields. The optimization traces its merit rays at
  // options.sampling.fields fields and only the pupil-edge rays at the constraint fields in
  // between; full sampling traces the merit rays at every constraint field. Where a bound is
  // reached by an interior pupil ray at an in-between field (the Cooke's largest ray angle under
  // the wavefront merit: 60.54 deg against 60), a design feasible at the optimization sampling
  // fails the full check. Then LM runs again (strict penalties, the weights carried over) with
  // merit rays at every constraint field, and its design is kept if it passes the full check.
  // Returns the full-sampling constraint check of the lens kept in x_.
  ConstraintReport restore_feasibility() {
    ConstraintReport report = check_constraints(result_lens(x_), options_.loss, full_.trace);
    if (soft_ || interrupted() || report.all_pass()) return report;
    OptimizeOptions dense = options_;
    dense.sampling.fields = constraint_field_count(options_.sampling.fields, kConstraintFields);
    // Nothing new to trace when the spot fields are already every constraint field (or are the
    // lens's own written fields, which the sampling's field count does not change).
    const Lens& structure = param_.structure();
    if (design_sampling(structure, dense.sampling).spot_fields ==
        design_sampling(structure, options_.sampling).spot_fields)
      return report;
    std::vector<double> x = x_;
    DesignLossOptions loss = loss_;
    const DesignLoss<double> l =
        run_phase(param_, x, GlassMode::kFixed, fixed_, frozen_all_, dense, loss,
                  "feasibility at every constraint field", options_.max_rounds,
                  options_.max_iterations, counters_, targets_);
    ConstraintReport dense_report = check_constraints(result_lens(x), options_.loss, full_.trace);
    const bool ok = dense_report.all_pass();
    result_.log.push_back(fmt::format(
        "feasibility at all {} constraint fields: {} ({} the full-sampling constraint check)",
        dense.sampling.fields, merit_text(l), ok ? "passes" : "still fails"));
    if (!ok) return report;
    x_ = x;
    return dense_report;
  }

  // The result at full sampling, never behind the start, and the counters.
  void finish() {
    // A design that is not a lens (the penalties are soft: a glass thickness driven below 0 by
    // bounds far from the lens's own, as the paper's 1..3 mm on a 100 mm double Gauss) cannot
    // be analysed; it is behind every start (an infinite merit below keeps the start).
    try {
      ConstraintReport final_constraints = restore_feasibility();
      add_edge_rows(final_constraints, result_lens(x_));
      result_.lens = result_lens(x_);
      result_.lens.validate();
      if (afocal_) {
        measure_afocal(result_.lens, result_.final_angular_spot_mrad,
                       result_.final_field_angular_spot_mrad);
      } else {
        const AnalysisReport final_report = analyze_lens(result_.lens, full_);
        result_.final_spot_um =
            final_report.mean_rms_spot_um.value_or(std::numeric_limits<double>::infinity());
        for (const FieldReport& f : final_report.fields)
          result_.final_field_spot_um.push_back(f.rms_spot_um.value_or(0.0));
      }
      result_.final_constraints = std::move(final_constraints);
      result_.final_targets = check_targets(result_.lens, options_.targets, full_.trace);
      if (wavefront_)
        result_.final_wavefront_waves = full_wavefront_waves(result_.lens, full_.trace);
    } catch (const Error& e) {
      result_.final_spot_um = result_.final_wavefront_waves = result_.final_angular_spot_mrad =
          std::numeric_limits<double>::infinity();
      result_.log.push_back(
          fmt::format("the final design is not a valid lens ({}); the start is kept", e.what()));
    }
    // Never return a worse lens than the start: designs are ordered by (every constraint met at
    // full sampling, then the merit at full sampling: mean spot, or mean RMS wavefront); a start
    // that is not behind the result in this order is returned instead (a feasible start is never
    // traded for an infeasible result; an infeasible start only for a feasible result or a
    // smaller merit), whatever its glasses.
    // The targets count with the constraints: the start here is the solved start (its efl_mm
    // and f_number targets applied), measured as the result is.
    const TargetReport solved_start_targets = check_targets(start_, options_.targets, full_.trace);
    const bool start_ok = result_.start_constraints.all_pass() && solved_start_targets.all_pass();
    const bool final_ok = result_.final_constraints.all_pass() && result_.final_targets.all_pass();
    const double start_merit = afocal_      ? result_.start_angular_spot_mrad
                               : wavefront_ ? result_.start_wavefront_waves
                                            : result_.start_spot_um;
    const double final_merit = afocal_      ? result_.final_angular_spot_mrad
                               : wavefront_ ? result_.final_wavefront_waves
                                            : result_.final_spot_um;
    const bool start_not_behind =
        (start_ok && !final_ok) || (start_ok == final_ok && !(final_merit < start_merit));
    if (start_not_behind || !std::isfinite(final_merit)) {
      // Say why: the result's merit and what it fails.
      std::string failing =
          final_ok ? std::string() : failing_constraints(result_.final_constraints);
      for (const TargetRow& r : result_.final_targets.rows)
        if (!r.pass)
          failing += fmt::format("{}target {} is {:.6g}", failing.empty() ? "" : "; ",
                                 target_text(r.target), r.value);
      result_.log.push_back(
          fmt::format("the start is kept: the result (merit {:.6g}{}) is not "
                      "ahead of it (merit {:.6g}{})",
                      final_merit, failing.empty() ? "" : "; fails: " + failing, start_merit,
                      start_ok ? "" : ", fails its own checks"));
      result_.lens = start_;
      result_.final_spot_um = result_.start_spot_um;
      result_.final_field_spot_um = result_.start_field_spot_um;
      result_.final_wavefront_waves = result_.start_wavefront_waves;
      result_.final_angular_spot_mrad = result_.start_angular_spot_mrad;
      result_.final_field_angular_spot_mrad = result_.start_field_angular_spot_mrad;
      result_.final_constraints = result_.start_constraints;
      result_.final_targets = solved_start_targets;
      result_.kept_start = true;
    }
    // One glass per element: a glass element split by a dummy or stop surface
    // (glass_elements.h) has one glass variable, named once.
    const std::vector<int> element_first = element_first_spaces(result_.lens);
    for (std::size_t k = 0; k < result_.lens.surfaces.size(); ++k) {
      const Surface& s = result_.lens.surfaces[k];
      if (!s.material.is_air() && element_first[k] == static_cast<int>(k))
        result_.glasses.push_back(s.material.label());
    }
    result_.iterations = counters_.iterations;
    result_.loss_evaluations = counters_.evaluations.load();
    result_.jacobian_evaluations = counters_.jacobians;
    result_.spot_trajectory = std::move(counters_.trajectory);
    result_.termination = interrupted() ? std::string("interrupted") : counters_.termination;
    result_.interrupted = interrupted();
  }

  const Lens& start_;
  const OptimizeOptions& options_;
  const LensParameterization param_;
  std::vector<double> x_;
  const bool wavefront_;
  const bool afocal_;  // Specs::afocal: the merit is the angular spot (design_loss.h)
  const bool soft_;
  AnalyzeOptions full_;
  std::vector<int> frozen_user_, glass_indices_, frozen_all_;
  std::vector<std::string> variable_report_;
  bool search_ = false;
  DesignLossOptions loss_;
  std::vector<int> fixed_;  // the catalog glass of each element
  TargetTerms targets_;     // the residual targets and their weight
  DesignLoss<double> best_;
  Counters counters_;
  OptimizeResult result_;
};

}  // namespace

namespace {

// Refuses a start whose clear apertures (semi_diameter_mm) vignet rays: the design loss traces
// unclipped pupils, so its merit would not be the merit analyze reports (header).
void check_clear_apertures(const Lens& start, const AnalyzeOptions& full) {
  bool any = false;
  for (const Surface& s : start.surfaces) any = any || s.semi_diameter_mm > 0.0;
  if (!any) return;
  if (start.specs.afocal) {
    AfocalOptions afocal;
    afocal.wavefront = false;
    const int vignetted = analyze_afocal_lens(start, full.trace, afocal).vignetted_rays;
    if (vignetted == 0) return;
    throw Error(SourceLocation{start.source_path},
                fmt::format("the clear apertures vignet {} rays of the start (analyze lists "
                            "them); the optimizer traces unclipped pupils and would optimize "
                            "rays that analyze drops. Remove semi_diameter_mm from those surfaces "
                            "(or enlarge it), or describe the vignetted pupil with [system] "
                            "vignetting factors (vdy, vcy), and run again",
                            vignetted));
  }
  const AnalysisReport report = analyze_lens(start, full);
  if (report.vignetted_rays == 0) return;
  std::string where;
  for (std::size_t k = 0; k < report.vignetted_by_surface.size(); ++k)
    if (report.vignetted_by_surface[k] > 0)
      where +=
          fmt::format("{}surface {} (semi_diameter_mm = {:g}: {} rays)", where.empty() ? "" : ", ",
                      k + 1, start.surfaces[k].semi_diameter_mm, report.vignetted_by_surface[k]);
  throw Error(SourceLocation{start.source_path},
              fmt::format("the clear apertures vignet {} rays of the start ({}); the optimizer "
                          "traces unclipped pupils and would optimize rays that analyze drops. "
                          "Remove semi_diameter_mm from those surfaces (or enlarge it), or "
                          "describe the vignetted pupil with [system] vignetting factors "
                          "(vdy, vcy), and run again",
                          report.vignetted_rays, where));
}

}  // namespace

OptimizeResult optimize_lens(const Lens& given_start, const OptimizeOptions& given_options) {
  given_options.validate();
  // The targets: the caller's, the default efl_mm of an as-written lens; the solved ones
  // (efl_mm, f_number) applied to the start (targets.h).
  if (given_start.specs.afocal) {
    // An afocal lens (design_loss.h): the angular spot merit, no image plane.
    const std::string where =
        given_start.source_path.empty() ? given_start.name : given_start.source_path;
    if (given_options.loss.merit == DesignMerit::kWavefront)
      throw Error(SourceLocation{where},
                  "the wavefront merit of an afocal lens (against a plane wave) is not "
                  "implemented in the optimizer; its merit is the RMS angular spot (--merit "
                  "spot); analyze --wave measures its plane-wave wavefront");
    if (given_options.loss.virtual_image())
      throw Error(SourceLocation{where},
                  "virtual-image bounds (min/max_virtual_image_mm) do not apply to an afocal "
                  "lens: its image is at infinity");
  }
  check_target_fields(given_start, given_options.targets);
  OptimizeOptions options = given_options;
  options.targets = targets_with_defaults(given_start, given_options.targets);
  // The lens file's pickups and solves met before anything is measured (paraxial/solves.h).
  const Lens start = with_solves(apply_target_solves(given_start, options.targets));
  const AnalyzeOptions full;
  check_clear_apertures(start, full);
  const TargetReport start_targets = check_targets(given_start, options.targets, full.trace);
  std::vector<std::string> solve_log;
  if (start.specs.afocal) {
    const auto magnification = [](const Lens& lens) {
      const TraceLens<double> traced = make_trace_lens(lens);
      return paraxial_angular_magnification(traced, traced.reference_nm());
    };
    const double m0 = magnification(given_start), m1 = magnification(start);
    solve_log.push_back(
        m0 != m1 ? fmt::format("afocal: the merit is the RMS angular spot (image at infinity); the "
                               "start's last curvature is solved from angular magnification {:.9g} "
                               "to the target {:.9g}, then held",
                               m0, m1)
                 : fmt::format("afocal: the merit is the RMS angular spot (image at infinity); the "
                               "angular magnification {:.9g} is held by the last curvature",
                               m1));
  }
  const double f0 = design_focal_length_mm(given_start), f1 = design_focal_length_mm(start);
  if (!start.specs.afocal && f0 != f1)
    solve_log.push_back(fmt::format(
        "focal length: the start is scaled from {:.6g} mm to the target {:.6g} mm", f0, f1));
  if (start.specs.f_number != given_start.specs.f_number ||
      start.specs.aperture_value != given_start.specs.aperture_value)
    solve_log.push_back(
        fmt::format("aperture: F-number {:.6g} (EPD = f / N)", start.specs.f_number));
  // A diverging lens: its image is virtual, its merit measured there (virtual_image.h).
  std::string virtual_image;
  options.loss = with_virtual_image_bounds(start, options.loss, &virtual_image);
  if (virtual_image.empty() && options.loss.virtual_image())  // bounds given (bounds_for)
    virtual_image = fmt::format(
        "image: virtual, measured {:.6g} mm before the last surface; its distance is held "
        "within [{:.6g}, {:.6g}] mm",
        -start.surfaces.back().thickness_mm, options.loss.min_virtual_image_mm,
        options.loss.max_virtual_image_mm);
  if (!virtual_image.empty()) solve_log.push_back(virtual_image);
  if (options.loss.merit == DesignMerit::kWavefront && !(options.loss.wavefront_unit_mm > 0.0)) {
    // The wavefront merit in mm (design_loss.h): the start's defocus unit, fixed for the run.
    const double unit = wavefront_mm_per_wave(prepare_lens_system(start, options.sampling));
    if (std::isfinite(unit) && unit > 0.0) options.loss.wavefront_unit_mm = unit;
  }
  OptimizeResult result = LensOptimization(start, options).run();
  result.start_targets = start_targets;
  result.log.insert(result.log.begin(), solve_log.begin(), solve_log.end());
  return result;
}

AdamResult adam_on_design_loss(const LensParameterization& param, std::vector<double> x,
                               GlassMode mode, const std::vector<int>& fixed_glasses,
                               const OptimizeOptions& options, double learning_rate, int max_steps,
                               double target_spot_mm) {
  const int n = param.size();
  std::vector<char> frozen(n, 0);
  for (int i : choose_variables(param, options.freeze, options.vary, options.focus_only).held)
    frozen[i] = 1;
  AdamMoments moments(n);
  AdamResult result;
  for (int step = 1; step <= max_steps; ++step) {
    // l_lens and its gradient by the adjoint (design_gradient.h).
    const DesignValueGradient loss =
        design_loss_gradient(param, x, mode, fixed_glasses, options.sampling, options.loss);
    ++result.evaluations;
    result.spot_mm = loss.loss.spot_mm;
    if (result.spot_mm <= target_spot_mm) {
      result.reached = true;
      break;
    }
    adam_update(x, loss.gradient, moments.m, moments.v, step, learning_rate, frozen);
  }
  result.x = x;
  return result;
}

}  // namespace lensopt
