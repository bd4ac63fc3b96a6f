// The paper's lens design loss (Eq. lens_design_loss) and its least-squares form for
// Levenberg-Marquardt, from one templated evaluation.
//
// Paper:  l_lens = l_S + l_RP lambda_RP + l_RA lambda_RA + l_GV lambda_GV, with
//   l_S  = mean_h sqrt(mean_{w,p} (y - ybar_h)^2 + x^2)                         (spot, mm)
//          (with the lens's wavelength and field weights, analysis/spot.h's weighted mean:
//          sum_h phi_h S_h / sum_h phi_h, S_h and ybar_h means weighted by omega_w)
//   l_RP = 1/n_r sum_{k,r} max(dz_min^k - dz_{k,r}, 0) + max(dz_{k,r} - dz_max^k, 0)  (mm)
//          (a glass element split by a dummy or stop surface, glass_elements.h: dz of its last
//          space summed over the element's spaces, its other spaces only >= 0)
//   l_RA = 1/n_r sum_{k,r} max(cos^2 t_max - zeta_{k,r}, 0) + max(cos^2 t_max - zeta'_{k,r}, 0)
//   l_GV = sum_m ||g_m - g_m*||^2
// and, for lenses with conics or aspheres, l_PB lambda_PB (lambda_PB = weight_profile): the
// profile bounds of optimize/profile_bounds.h (slope at the clear semi-aperture, the conic's
// domain) as squared hinges, profile_bound_loss; in l_lens only (LM adds them as residuals of
// their own, optimizer.cpp).
// Least squares (Ceres minimizes 1/2 sum r_i^2), residuals in this order:
//   spot:  r = sqrt(a_h / N_h) (y - ybar_h) and sqrt(a_h / N_h) (x - xbar_h) for every traced ray
//          of field h (xbar_h = 0 on the mirrored half pupil; a system with VDX or VAN traces the
//          full pupil, TraceSystem::full_pupil, and then the x centroid is its own)
//          (N_h = W P rays; a failed ray gives 0). With the per-field weights
//          a_h = 1 / (F S_h0), S_h0 the field's RMS at the current point (iteratively reweighted),
//          sum of squares = sum_h S_h^2 / (F S_h0) = l_S at S = S_0, and its gradient is
//          2 grad l_S there: LM descends the paper's mean RMS, not the RMS of all rays.
//   path:  one per (field, space k): sqrt(lambda_RP sum_r v^2), v the hinge violation (mm)
//   angle: one per (field, surface, incidence|refraction): sqrt(lambda_RA sum_r v^2)
//   glass: sqrt(lambda_GV) (g - g*), two per glass.
// The penalties are squared hinges (smooth for LM) summed over rays, where the paper's are linear
// hinges averaged over rays: averaged, one ray crossing its bound costs almost nothing, and the
// paper's own baselines do cross them slightly (the Cooke reaches 63.9 deg against 60). The
// optimizer raises a weight tenfold while its constraint is violated, and the report checks each
// constraint against its bound at full sampling.
// Constraint rays: besides the spot rays, every field and wavelength traces kEdgeRays rays on
// the pupil edge (r = 1, azimuth -90..90 deg), which hold the extreme travels and angles that a
// coarse ring pattern misses; they enter the penalties and extremes, not the spot.
// Failed rays: spot residuals 0; their zeta/zeta' up to the failing surface do enter the angle
// penalty (a miss has zeta < 0), so the penalties pull failing rays back.
// Afocal merit (Specs::afocal: image at infinity, analysis/afocal.h; OpticStudio's "Afocal
// Image Space" merit): l_S is replaced by
//   l_A  = L sum_h phi_h A_h / sum_h phi_h                                       (mm)
// A_h the RMS angular spot of field h (analysis/angular_spot.h, the code `analyze` runs: the exit
// directions about their omega-weighted centroid direction, gnomonic projection, rad) and L the
// parameterization's length unit (the lens's vertex length, variables.h): the angular spot seen
// through an ideal lens of focal length L, a spot in mm, so the penalties' weights (set against
// a spot in mm) weigh as they do for a focusing lens. Its residuals take the place of the spot's,
// r = L sqrt(w_S a_h omega_w / (sum_w omega_w P)) (a - abar) per ray and component (tangential,
// sagittal; abar_x = 0 on the mirrored half pupil), so sum of squares = a_h (L A_h)^2 with the
// reweighting above. The last space (to an image plane at infinity) has no bound. No constraint
// holds the lens afocal: a residual power P spreads the on-axis beam of radius r over exit angles
// of about P r, which the on-axis angular spot measures, so the merit collimates (the residual
// power it leaves balances the spherical aberration, as a focusing lens's best focus does).
// The afocal lens has no wavefront merit here (Error): the plane-wave wavefront is analysed only.
// Wavefront merit (DesignMerit::kWavefront, `optimize --merit wavefront`): l_S is replaced by
//   l_W  = mean_h W_h,  W_h = sqrt(sum_w omega_w RMS_{h,w}^2 / sum_w omega_w)     (waves)
// the RMS wavefront with piston and tilt removed (analysis/wavefront.h, the same code as
// `analyze --wave`) on a polar Gauss quadrature of the pupil (wavefront_merit_pupil: n / 2
// rings and n azimuths per half for n = wavefront_pupil_samples, exact for wavefronts of degree
// n - 1), its half x_p > 0 mirrored (exact for the meridionally symmetric systems the tracer
// assumes) or the whole pupil when the system traces full pupils (a field's VDX or VAN set,
// TraceSystem::full_pupil), omega the lens's wavelength weights. The analysis judges on a square
// grid of cells, which converges to the same integral at first order in the cell size (its rim
// cells); the quadrature samples the 2-3 waves of high-order aberration of a fast lens at full
// field closer to that limit than a grid of as many rays (BENCHMARKS.md, wave-merit). Its
// residuals, one per (field, wavelength, quadrature node):
//   r = sqrt(a_h omega_w / sum omega) sqrt(g_i / sum g) (W_i - piston - tilt)
// (rms_wavefront_residuals), times sqrt(u) for the unit u = wavefront_unit_mm (mm per wave; 1
// when 0), so sum of squares = u sum_h a_h W_h^2 = u l_W at W = W_0 with the reweighting above;
// l_lens has u l_W in place of l_S. The unit matters for the strict phases: with the merit in
// waves (~2 on the Cooke against its spot's ~0.02 mm) the penalties weigh a hundredth of what
// they weigh against the spot, the designs of each round cross their bounds a hundred times
// further and LM spends its iteration limit on every round (BENCHMARKS.md, wave-merit).
// The quadrature rays (and each wavelength's chief ray) also carry the path and angle penalties
// in place of the ring rays; l_S is still reported, from the quadrature rays.
#pragma once

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>
#include <vector>

#include "lensopt/analysis/angular_spot.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/core/error.h"
#include "lensopt/core/jet_width.h"
#include "lensopt/core/threads.h"
#include "lensopt/optimize/design_sampling.h"
#include "lensopt/optimize/glass_elements.h"
#include "lensopt/optimize/profile_bounds.h"
#include "lensopt/optimize/variables.h"
#include "lensopt/trace/system.h"

namespace lensopt {

inline constexpr int kEdgeRays = 9;
inline constexpr int kConstraintFields = 21;

// What the least squares minimizes besides the penalties (header).
enum class DesignMerit { kSpot, kWavefront };

// Weights and bounds of the design loss (paper values by default).
struct DesignLossOptions {
  double weight_spot = 1.0;
  double weight_ray_path = 100.0;
  double weight_ray_angle = 100.0;
  double weight_glass = 0.01;
  double min_air_mm = 0.01;
  double min_glass_mm = 1.0;
  double max_glass_mm = 3.0;
  double min_image_clearance_mm = 12.0;
  // A virtual image (a diverging lens, optimize/virtual_image.h): when max_virtual_image_mm > 0
  // the image plane lies before the last surface and every ray's image-space travel dz (negative:
  // traced backwards to the plane) is held to -max_virtual_image_mm <= dz <=
  // -min_virtual_image_mm; min_image_clearance_mm is then not used.
  double min_virtual_image_mm = 0.0;
  double max_virtual_image_mm = 0.0;
  bool virtual_image() const { return max_virtual_image_mm > 0.0; }
  double max_ray_angle_deg = 60.0;
  // Profile bounds (optimize/profile_bounds.h): the surface normal of a conic or asphere tilts
  // at most this far from the axis up to the clear semi-aperture; its LM weight (raised tenfold
  // while violated, as the others).
  double max_surface_slope_deg = 60.0;
  double weight_profile = 100.0;
  // false (strict): squared hinges summed over rays, weights raised while violated (see above).
  // true (paper): the paper's soft penalties, linear hinges averaged over rays (smoothed within
  // kPaperHingeSmoothing of the bound so LM has a derivative), fixed weights; a design may then
  // cross a bound where the trade-off pays, as the paper's own baselines do.
  bool paper_penalties = false;
  // The merit: the paper's RMS spot, or the RMS wavefront (weight_spot weighs it) on a polar
  // quadrature of the pupil with wavefront_pupil_samples samples across its diameter
  // (wavefront_merit_pupil).
  DesignMerit merit = DesignMerit::kSpot;
  int wavefront_pupil_samples = 8;
  // The wavefront merit's unit in the least squares and in l_lens: mm per wave (0: 1, the merit
  // in waves). The optimizer sets wavefront_mm_per_wave of the start (analysis/wavefront.h), the
  // RMS spot of a pure defocus per wave of RMS wavefront, so the penalties, whose weights are
  // set against the spot in mm, weigh the same against either merit (header).
  double wavefront_unit_mm = 0.0;

  void validate() const;  // throws Error naming the bad value
};

// The paper's loss terms (double values; also the Jet values when evaluated on Jets).
template <typename T>
struct DesignLoss {
  T spot_mm;              // l_S (afocal: L A, header)
  T ray_path_mm;          // l_RP (linear hinge, as the paper)
  T ray_angle;            // l_RA
  T glass;                // l_GV
  T profile = K<T>(0.0);  // l_PB (profile bounds, weight 1)
  T total;                // l_lens with the options' weights
  std::vector<T> field_rms_mm;
  std::vector<double> field_weights;  // phi_h of the spot fields, normalized (spot.h)
  // The wavefront merit (DesignMerit::kWavefront only, else empty / 0): l_W and W_h (waves).
  T wavefront_waves = K<T>(0.0);
  std::vector<T> field_wavefront_waves;
  DesignMerit merit = DesignMerit::kSpot;
  // An afocal lens (header): the mean RMS angular spot and its per-field values (rad); spot_mm
  // and field_rms_mm then hold them times angular_unit_mm (the merit in mm).
  bool afocal = false;
  T angular_spot_rad = K<T>(0.0);
  std::vector<T> field_angular_spot_rad;
  double angular_unit_mm = 1.0;
  int failed_rays = 0;
  int rays = 0;
  // The optimized merit: l_S (mm) or l_W (waves), and its per-field values.
  const T& merit_value() const {
    return merit == DesignMerit::kWavefront ? wavefront_waves : spot_mm;
  }
  const std::vector<T>& field_merit() const {
    return merit == DesignMerit::kWavefront ? field_wavefront_waves : field_rms_mm;
  }
};

// Extremes over every traced ray, for the constraint report: per space k the smallest and
// largest axial travel (mm), and the smallest cos^2 of any incidence or refraction angle. In a
// glass element split by a dummy surface (glass_elements.h) the travel of space k is summed from
// the element's first space: its last space holds the element's travel.
struct DesignExtremes {
  std::vector<double> min_travel_mm;
  std::vector<double> max_travel_mm;
  double min_cos2_angle = 1.0;
};

// Number of residuals of the least-squares form for F spot fields, F_c constraint fields,
// W wavelengths, P pupil rays, K surfaces and M glasses.
inline int design_residual_count(int fields, int constraint_fields, int wavelengths, int rays,
                                 int surfaces, int glasses) {
  return fields * wavelengths * rays * 2 + constraint_fields * surfaces * 3 + glasses * 2;
}

// The wavefront merit's pupil samples for n = wavefront_pupil_samples (header): the polar
// quadrature of ceil(n / 2) rings and n azimuths per half, the half x_p > 0 mirrored (n^2 / 2 rays
// per field and wavelength for an even n), or both halves when the system traces full pupils
// (TraceSystem::full_pupil).
inline int wavefront_merit_rings(int n) {
  return (n + 1) / 2;
}
inline int wavefront_merit_half_azimuths(int n) {
  return n;
}
inline PupilGrid wavefront_merit_pupil(int n, bool full_pupil = false) {
  return make_pupil_quadrature(wavefront_merit_rings(n), wavefront_merit_half_azimuths(n),
                               !full_pupil);
}

// The merit's residuals per spot field: 2 per ring ray and wavelength (spot; `rays` the traced
// pupil samples, sys.pupil), or one per quadrature node and wavelength (wavefront).
inline int merit_residuals_per_field(const DesignLossOptions& options, int wavelengths, int rays,
                                     bool full_pupil = false) {
  if (options.merit == DesignMerit::kWavefront)
    return wavelengths * wavefront_merit_rings(options.wavefront_pupil_samples) *
           wavefront_merit_half_azimuths(options.wavefront_pupil_samples) * (full_pupil ? 2 : 1);
  return wavelengths * rays * 2;
}

// design_residual_count for the merit of `options`.
inline int design_residual_count(const DesignLossOptions& options, int fields,
                                 int constraint_fields, int wavelengths, int rays, int surfaces,
                                 int glasses, bool full_pupil = false) {
  return fields * merit_residuals_per_field(options, wavelengths, rays, full_pupil) +
         constraint_fields * surfaces * 3 + glasses * 2;
}

// The constraint field count used with `fields` spot fields (see evaluate_design).
inline int constraint_field_count(int fields, int paper_fields) {
  if (fields <= 1) return fields;
  const int c = std::max(fields, paper_fields);
  return (c - 1) % (fields - 1) == 0 ? c : fields;
}

// The bounds of the image space's travel dz: dz >= min_image_clearance_mm (a real image), or
// -max_virtual_image_mm <= dz <= -min_virtual_image_mm (a virtual one; DesignLossOptions).
inline void image_space_bounds(const DesignLossOptions& options, double& lower, double& upper) {
  if (options.virtual_image()) {
    lower = -options.max_virtual_image_mm;
    upper = -options.min_virtual_image_mm;
  } else {
    lower = options.min_image_clearance_mm;
    upper = std::numeric_limits<double>::infinity();
  }
}

namespace detail {

template <typename T>
T safe_norm(const T& sum_of_squares) {
  using std::sqrt;
  // sqrt is not differentiable at 0; an exactly inactive penalty is a constant 0.
  if (!(sum_of_squares > K<T>(0.0))) return K<T>(0.0);
  return sqrt(sum_of_squares);
}

template <typename T>
T hinge(const T& v) {
  return v > K<T>(0.0) ? v : K<T>(0.0);
}

// The linear hinge for v = hinge(...) >= 0, rounded within kPaperHingeSmoothing of the bound:
// v^2 / (2 d) below d, v - d / 2 above (continuous value and slope).
inline constexpr double kPaperHingeSmoothing = 1e-4;
template <typename T>
T smooth_hinge(const T& v) {
  const double d = kPaperHingeSmoothing;
  return v < K<T>(d) ? v * v * K<T>(0.5 / d) : v - K<T>(0.5 * d);
}

// The ray-angle hinge of a ray at its bound to within round-off (kHingeTie, on cos^2): a tie.
// Where a whole beam meets the bound exactly (a collimated beam on plane plates at a field of
// exactly the angle limit), the loss has a kink there and round-off, not the optics, puts each
// ray on one side or the other, differently in double and on Jets (their arithmetic rounds
// differently, e.g. the multi-versioned double kernel with FMA). A tie adds its value max(v, 0) as
// any ray, with half of v's slope: the central derivative of the kink, whichever side round-off
// chose (the adjoint's seeds in design_gradient.cpp do the same).
inline constexpr double kHingeTie = 1e-12;
template <typename T>
T tied_hinge(const T& v) {
  if constexpr (std::is_same_v<T, double>) {
    return v > 0.0 ? v : 0.0;
  } else {
    T r = K<T>(0.5) * v;
    r.a = v.a > 0.0 ? v.a : 0.0;
    return r;
  }
}

// Whether T is ceres::Jet<double, N> of a width of core/jet_width.h (traced by trace_bundle_jet).
template <typename T>
struct is_listed_jet : std::false_type {};
template <int N>
struct is_listed_jet<ceres::Jet<double, N>> : std::bool_constant<is_jet_width(N)> {};

// Sizes a record for `rays` rays at `surfaces` surfaces before a trace. On the Jets of
// core/jet_width.h the trace (trace_bundle_jet, src/trace/kernel_jet.cpp.in) leaves every travel
// and zeta entry written or zero, so a record reused at the same shape is not zeroed first (its
// 2.4 MB per 1024-ray bundle at width 12 were about 1.5 % of an LM run); elsewhere
// RayRecord::resize, which zeroes every array.
template <typename T>
void size_record(RayRecord<T>& record, int surfaces, std::size_t rays) {
  if constexpr (is_listed_jet<T>::value) {
    for (auto* arrays :
         {&record.axial_travel_mm, &record.cos2_incidence, &record.cos2_refraction}) {
      arrays->resize(surfaces);
      for (std::vector<T>& a : *arrays) a.resize(rays);
    }
    record.optical_path_mm.clear();
    record.path_start_z.clear();
    record.path_start_n.clear();
  } else {
    record.resize(surfaces, rays);
  }
}

// The per-thread buffers of evaluate_design (one set per thread and scalar type, reused).
template <typename T>
struct DesignScratch {
  RayBundle<T> bundle, edge_bundle;
  RayRecord<T> record, edge_record;
  std::vector<T> ys, xs, ls, ms, ns, ax, ay;
  std::vector<double> omega_ray;
  std::vector<char> ok, active;
  std::vector<T> path_sq, angle_sq, path_soft, angle_soft;
};

}  // namespace detail

// Evaluates the design loss of variables x. `residuals` (may be null) receives the least-squares
// residuals (design_residual_count of them) with per-field weights `field_weights` (F values,
// a_h above; null: a_h = 1 / F); `loss` (may be null) receives the paper's terms.
// Returns false if the evaluation is not finite (Ceres then treats the point as infeasible).
template <typename T>
bool evaluate_design(const LensParameterization& param, const T* x, GlassMode mode,
                     const std::vector<int>& fixed_glasses, const TraceOptions& trace_options,
                     const DesignLossOptions& options, const std::vector<double>* field_weights,
                     T* residuals, DesignLoss<T>* loss, DesignExtremes* extremes = nullptr) {
  using std::sqrt;
  const TraceLens<T> lens = param.to_trace_lens(x, mode, fixed_glasses);
  TraceOptions topt = trace_options;
  topt.scale_to_spec = false;  // the forward map gives the spec focal length exactly
  // The lens's sampling (design_sampling.h): the paper's (fields 0..hfov, EPD = f / N) in its
  // spec mode, else the lens's own fields, weights, aperture and object. Constraint rays run at
  // every field of the system (at least 21); spot rays at its spot fields.
  const Specs& specs = param.structure().specs;
  const DesignSampling sampled = design_sampling(param.structure(), topt);
  const TraceSystem<T> sys = prepare_system(lens, sampled.setup, topt);
  const int all_fields = static_cast<int>(sys.fields_deg.size());
  const int field_count = sampled.spot_fields;
  const int wl = sys.wavelength_count;
  const bool wavefront = options.merit == DesignMerit::kWavefront;
  // An afocal lens (Specs::afocal): the angular spot in place of the spot (header).
  const bool afocal = param.afocal();
  if (afocal && wavefront)
    throw Error(
        SourceLocation{param.structure().source_path.empty() ? param.structure().name
                                                             : param.structure().source_path},
        "the wavefront merit of an afocal lens (against a plane wave) is not implemented "
        "in the optimizer; use the angular spot merit (--merit spot)");
  const double angle_unit = afocal ? param.length_unit_mm() : 1.0;
  const double wave_unit = options.wavefront_unit_mm > 0.0 ? options.wavefront_unit_mm : 1.0;
  // The half pupil: the lens is symmetric about the meridional plane (as the half-pupil spot);
  // the full pupil when a field's vignetting is not (sys.full_pupil).
  const PupilGrid grid =
      wavefront ? wavefront_merit_pupil(options.wavefront_pupil_samples, sys.full_pupil)
                : PupilGrid{};
  // Rays per field and wavelength that carry the merit (and the spot).
  const int rays = wavefront ? static_cast<int>(grid.size()) : static_cast<int>(sys.pupil.size());
  const int k_count = lens.surface_count();
  const double n_r = static_cast<double>(field_count) * wl * rays;
  // The wavelength weights (the lens's; all 1 when it has none).
  std::vector<double> omega(wl, 1.0);
  if (static_cast<int>(specs.wavelength_weights.size()) == wl) omega = specs.wavelength_weights;
  double omega_sum = 0;
  for (double v : omega) omega_sum += v;
  // The spot's weights (analysis/spot.h): omega_w and phi_h normalized to their largest (all
  // exactly 1 when equal); phi of the spot fields.
  const SpotWeights spot_w = spot_weights(sys);
  double spot_omega_sum = 0.0;
  for (double v : spot_w.wavelength) spot_omega_sum += v;
  std::vector<double> phi(field_count, 1.0);
  for (int hf = 0; hf < all_fields; ++hf)
    if (sampled.spot_field[hf] >= 0) phi[sampled.spot_field[hf]] = spot_w.field[hf];
  double phi_sum = 0.0;
  for (int h = 0; h < field_count; ++h) phi_sum += phi[h];
  if (!(phi_sum > 0.0)) {  // no spot field with weight: the plain mean
    phi.assign(field_count, 1.0);
    phi_sum = field_count;
  }
  const bool equal_fields = phi_sum == field_count;
  const PupilSamples edge = sys.samples_for(pupil_edge_samples(kEdgeRays));
  const double cos2_max = std::pow(std::cos(options.max_ray_angle_deg * kPi / 180.0), 2);
  // Bounds per space: air >= min_air; glass in [min, max]; the last (image) >= clearance. A
  // glass element split by a dummy surface (glass_elements.h) is bounded on its summed travel at
  // its last space; its other spaces only by a travel >= 0.
  const std::vector<int> element_first = element_first_spaces(param.structure());
  std::vector<char> split(k_count, 0);  // space k continues an element (its travel is summed)
  std::vector<double> lower(k_count), upper(k_count);
  for (int k = 0; k < k_count; ++k) {
    split[k] = element_first[k] != k;
    if (!element_last_space(element_first, k)) {
      lower[k] = 0.0;  // a part of a split element: no ray travels backwards
      upper[k] = std::numeric_limits<double>::infinity();
    } else if (k == k_count - 1 && afocal) {
      lower[k] = -std::numeric_limits<double>::infinity();  // image at infinity: no plane
      upper[k] = std::numeric_limits<double>::infinity();
    } else if (k == k_count - 1) {
      image_space_bounds(options, lower[k], upper[k]);
    } else if (stop_at_vertex_space(param.structure(), k)) {
      lower[k] = -std::numeric_limits<double>::infinity();  // the stop on a vertex: no air gap
      upper[k] = std::numeric_limits<double>::infinity();
    } else if (lens.is_glass[k]) {
      lower[k] = options.min_glass_mm;
      upper[k] = options.max_glass_mm;
    } else {
      lower[k] = options.min_air_mm;
      upper[k] = std::numeric_limits<double>::infinity();
    }
  }

  std::vector<T> field_rms(field_count, K<T>(0.0));
  std::vector<T> field_angle(afocal ? field_count : 0, K<T>(0.0));
  std::vector<T> field_wave(wavefront ? field_count : 0, K<T>(0.0));
  std::vector<T> path_linear(all_fields, K<T>(0.0)), angle_linear(all_fields, K<T>(0.0));
  std::vector<int> failed(all_fields, 0);
  const bool any_split = std::find(split.begin(), split.end(), 1) != split.end();
  std::vector<DesignExtremes> field_extremes(all_fields);
  for (DesignExtremes& e : field_extremes) {
    e.min_travel_mm.assign(k_count, std::numeric_limits<double>::infinity());
    e.max_travel_mm.assign(k_count, -std::numeric_limits<double>::infinity());
  }
  const int spot_block = merit_residuals_per_field(options, wl, rays, sys.full_pupil);
  const int path_offset = field_count * spot_block;
  const int angle_offset = path_offset + all_fields * k_count;
  const int glass_offset = angle_offset + all_fields * k_count * 2;

  const int nthreads = thread_count(trace_options.threads);
#pragma omp parallel num_threads(nthreads)
  {
    // Each thread's buffers, kept from one evaluation to the next (an LM run evaluates thousands
    // of times; allocated per evaluation they were about 3 % of its CPU in malloc, page faults
    // and zeroing). Every buffer is sized and filled below before it is read.
    thread_local detail::DesignScratch<T> scratch;
    RayBundle<T>& bundle = scratch.bundle;
    RayBundle<T>& edge_bundle = scratch.edge_bundle;
    RayRecord<T>& record = scratch.record;
    RayRecord<T>& edge_record = scratch.edge_record;
    std::vector<T>& ys = scratch.ys;
    std::vector<T>& xs = scratch.xs;
    // afocal: exit directions and their projections
    std::vector<T>& ls = scratch.ls;
    std::vector<T>& ms = scratch.ms;
    std::vector<T>& ns = scratch.ns;
    std::vector<T>& ax = scratch.ax;
    std::vector<T>& ay = scratch.ay;
    std::vector<double>& omega_ray = scratch.omega_ray;
    std::vector<char>& ok = scratch.ok;
    std::vector<char>& active = scratch.active;  // add_constraints: rays to visit
    std::vector<T>& path_sq = scratch.path_sq;
    std::vector<T>& angle_sq = scratch.angle_sq;
    std::vector<T>& path_soft = scratch.path_soft;
    std::vector<T>& angle_soft = scratch.angle_soft;
    path_sq.assign(k_count, K<T>(0.0));
    angle_sq.assign(static_cast<std::size_t>(k_count) * 2, K<T>(0.0));
    path_soft.assign(k_count, K<T>(0.0));
    angle_soft.assign(static_cast<std::size_t>(k_count) * 2, K<T>(0.0));
#pragma omp for schedule(dynamic, 1)
    for (int hf = 0; hf < all_fields; ++hf) {
      // hf: constraint field; spot field h when sampled.spot_field[hf] = h >= 0.
      const int h = sampled.spot_field[hf];
      const bool spot_field = h >= 0;
      ys.assign(static_cast<std::size_t>(wl) * rays, K<T>(0.0));
      xs.assign(static_cast<std::size_t>(wl) * rays, K<T>(0.0));
      ok.assign(static_cast<std::size_t>(wl) * rays, 0);
      if (afocal) {
        ls.assign(static_cast<std::size_t>(wl) * rays, K<T>(0.0));
        ms = ls;
        ns = ls;
      }
      for (auto& v : path_sq) v = K<T>(0.0);
      for (auto& v : angle_sq) v = K<T>(0.0);
      for (auto& v : path_soft) v = K<T>(0.0);
      for (auto& v : angle_soft) v = K<T>(0.0);
      T path_sum = K<T>(0.0), angle_sum = K<T>(0.0);
      // Adds the path and angle penalties of the traced rays of `b` (records in `rec`).
      auto add_constraints = [&](const RayBundle<T>& b, const RayRecord<T>& rec) {
        const std::size_t count = b.size();
        // Without extremes to report (the LM's evaluations), a ray whose every hinge is inactive
        // adds nothing. A first pass over the records, surface by surface and branch-free, marks
        // the rays with an entry past a bound or within kHingeTie of the angle bound, and only
        // those are visited below, in ray order as before (the same sums, the same bits). The
        // pass also reads a failed ray's entries past its failure, which the visit does not:
        // they can only mark more rays. With a split element the travel is summed along the ray:
        // every ray is visited.
        const bool screen = !extremes && !any_split;
        if (screen) {
          active.assign(count, 0);
          const double angle_limit = cos2_max + detail::kHingeTie;
          for (int k = 0; k < k_count; ++k) {
            const T* travel = rec.axial_travel_mm[k].data();
            const T* in = rec.cos2_incidence[k].data();
            const T* out = rec.cos2_refraction[k].data();
            const double lo = lower[k], hi = upper[k];
            for (std::size_t p = 0; p < count; ++p)
              active[p] |= static_cast<char>(
                  (value_of(travel[p]) < lo) | (value_of(travel[p]) > hi) |
                  (value_of(in[p]) < angle_limit) | (value_of(out[p]) < angle_limit));
          }
        }
        for (std::size_t p = 0; p < count; ++p) {
          if (screen && !active[p]) continue;
          const bool traced = b.status[p] == kRayOk;
          const int last_valid = traced ? k_count - 1 : b.failed_surface[p];
          T element_dz = K<T>(0.0);  // the travel so far in a split element
          for (int k = 0; k <= last_valid && k < k_count; ++k) {
            // Ray path: the space after surface k (only up to a failure); in a split element
            // the travel summed over its spaces so far (the bound is on the element's last).
            if (traced || k < last_valid) {
              const T dz =
                  split[k] ? element_dz + rec.axial_travel_mm[k][p] : rec.axial_travel_mm[k][p];
              if (k + 1 < k_count && split[k + 1]) element_dz = dz;
              DesignExtremes& e = field_extremes[hf];
              e.min_travel_mm[k] = std::min(e.min_travel_mm[k], value_of(dz));
              e.max_travel_mm[k] = std::max(e.max_travel_mm[k], value_of(dz));
              // An inactive hinge adds exact zeros: skipped (most rays, and for Jets each
              // skipped term saves a dozen derivative operations).
              if (value_of(dz) < lower[k] || value_of(dz) > upper[k]) {
                T v = detail::hinge(K<T>(lower[k]) - dz);
                if (std::isfinite(upper[k])) v = v + detail::hinge(dz - K<T>(upper[k]));
                path_sq[k] = path_sq[k] + v * v;
                path_soft[k] = path_soft[k] + detail::smooth_hinge(v);
                path_sum = path_sum + v;
              }
            }
            const double cos2_in = value_of(rec.cos2_incidence[k][p]);
            const double cos2_out = value_of(rec.cos2_refraction[k][p]);
            field_extremes[hf].min_cos2_angle =
                std::min({field_extremes[hf].min_cos2_angle, cos2_in, cos2_out});
            // l_RA's linear hinge (a tie within kHingeTie of the bound: detail::tied_hinge).
            if (cos2_in < cos2_max + detail::kHingeTie) {
              const T va = K<T>(cos2_max) - rec.cos2_incidence[k][p];
              if (cos2_in < cos2_max) {
                angle_sq[2 * k] = angle_sq[2 * k] + va * va;
                angle_soft[2 * k] = angle_soft[2 * k] + detail::smooth_hinge(va);
              }
              angle_sum = angle_sum +
                          (cos2_in >= cos2_max - detail::kHingeTie ? detail::tied_hinge(va) : va);
            }
            if (cos2_out < cos2_max + detail::kHingeTie) {
              const T vb = K<T>(cos2_max) - rec.cos2_refraction[k][p];
              if (cos2_out < cos2_max) {
                angle_sq[2 * k + 1] = angle_sq[2 * k + 1] + vb * vb;
                angle_soft[2 * k + 1] = angle_soft[2 * k + 1] + detail::smooth_hinge(vb);
              }
              angle_sum = angle_sum +
                          (cos2_out >= cos2_max - detail::kHingeTie ? detail::tied_hinge(vb) : vb);
            }
          }
        }
      };
      // The traced spot rays of wavelength w (in `bundle`): positions kept, failures counted.
      auto keep_spot_rays = [&](int w) {
        for (int p = 0; p < rays; ++p) {
          const std::size_t i = static_cast<std::size_t>(w) * rays + p;
          const bool traced = bundle.status[p] == kRayOk;
          ok[i] = traced;
          if (traced) {
            ys[i] = bundle.y[p];
            xs[i] = bundle.x[p];
            if (afocal) {
              ls[i] = bundle.l[p];
              ms[i] = bundle.m[p];
              ns[i] = bundle.n[p];
            }
          } else {
            ++failed[hf];
          }
        }
      };
      if (spot_field && wavefront) {
        // The wavefront merit: the grid rays of every wavelength, against the field's sphere.
        const double a_h = field_weights ? (*field_weights)[h]
                                         : (equal_fields ? 1.0 / field_count : phi[h] / phi_sum);
        T* r = residuals ? residuals + static_cast<std::size_t>(h) * spot_block : nullptr;
        field_wave[h] = field_rms_wavefront(
            sys, hf, grid, omega, bundle, record, [&](int w, const Wavefront<T>& wf) {
              keep_spot_rays(w);
              failed[hf] += bundle.status[rays] != kRayOk;  // the chief ray
              add_constraints(bundle, record);
              if (r) {
                T* rw = r + static_cast<std::size_t>(w) * rays;
                rms_wavefront_residuals(wf, grid, rw);
                const T scale =
                    K<T>(std::sqrt(options.weight_spot * wave_unit * a_h * omega[w] / omega_sum));
                for (int p = 0; p < rays; ++p) rw[p] = scale * rw[p];
              }
            });
      }
      for (int w = 0; w < wl; ++w) {
        if (spot_field && !wavefront) {
          start_rays(sys, hf, w, bundle);
          detail::size_record(record, k_count, bundle.size());
          trace_bundle(sys.lens, w, k_count, true, bundle, &record);
          keep_spot_rays(w);
          add_constraints(bundle, record);
        }
        start_rays(sys, hf, w, edge_bundle, &edge);
        detail::size_record(edge_record, k_count, edge_bundle.size());
        trace_bundle(sys.lens, w, k_count, true, edge_bundle, &edge_record);
        for (std::size_t p = 0; p < edge_bundle.size(); ++p)
          failed[hf] += edge_bundle.status[p] != kRayOk;
        add_constraints(edge_bundle, edge_record);
      }
      path_linear[hf] = path_sum;
      angle_linear[hf] = angle_sum;
      if (residuals) {
        for (int k = 0; k < k_count; ++k) {
          residuals[path_offset + hf * k_count + k] =
              options.paper_penalties
                  ? detail::safe_norm(K<T>(options.weight_ray_path / n_r) * path_soft[k])
                  : detail::safe_norm(K<T>(options.weight_ray_path) * path_sq[k]);
          for (int j = 0; j < 2; ++j)
            residuals[angle_offset + (hf * k_count + k) * 2 + j] =
                options.paper_penalties
                    ? detail::safe_norm(K<T>(options.weight_ray_angle / n_r) *
                                        angle_soft[2 * k + j])
                    : detail::safe_norm(K<T>(options.weight_ray_angle) * angle_sq[2 * k + j]);
        }
      }
      if (!spot_field) continue;
      if (afocal) {
        // The angular spot of field h (analysis/angular_spot.h, the code analyze runs): the exit
        // directions about their centroid direction, omega_w weighted, in rad.
        const std::size_t n_rays = ys.size();
        omega_ray.resize(n_rays);
        for (std::size_t i = 0; i < n_rays; ++i) omega_ray[i] = spot_w.wavelength[i / rays];
        ax.assign(n_rays, K<T>(0.0));
        ay.assign(n_rays, K<T>(0.0));
        const AngularSpotMoments<T> a =
            angular_spot_moments<T>(n_rays, ls.data(), ms.data(), ns.data(), omega_ray.data(),
                                    ok.data(), !sys.full_pupil, ax.data(), ay.data());
        field_angle[h] = a.ok ? detail::safe_norm(a.variance) : K<T>(0.0);
        field_rms[h] = K<T>(angle_unit) * field_angle[h];
        if (residuals) {
          const double a_h = field_weights ? (*field_weights)[h]
                                           : (equal_fields ? 1.0 / field_count : phi[h] / phi_sum);
          // r = L sqrt(w_S a_h omega_w / (sum_w omega_w P)) (a - abar): sum of squares
          // a_h (L A_h)^2 when no ray fails (header).
          const double denominator = spot_omega_sum * rays;
          T* r = residuals + static_cast<std::size_t>(h) * spot_block;
          for (int w = 0; w < wl; ++w) {
            const T scale = K<T>(angle_unit * std::sqrt(options.weight_spot * a_h *
                                                        spot_w.wavelength[w] / denominator));
            for (int p = 0; p < rays; ++p) {
              const std::size_t i = static_cast<std::size_t>(w) * rays + p;
              const bool use = ok[i] && a.ok;
              r[2 * i] = use ? scale * (ay[i] - a.mean_y) : K<T>(0.0);
              r[2 * i + 1] = use ? scale * (ax[i] - a.mean_x) : K<T>(0.0);
            }
          }
        }
        continue;
      }
      // Spot of field h about its polychromatic centroid, weighted by omega_w (spot.h; a weight
      // of exactly 1 takes the unweighted sums).
      int count = 0;
      double weight_sum = 0.0;
      T y_sum = K<T>(0.0);
      for (std::size_t i = 0; i < ys.size(); ++i)
        if (ok[i]) {
          const double o = spot_w.wavelength[i / rays];
          y_sum = o == 1.0 ? y_sum + ys[i] : y_sum + K<T>(o) * ys[i];
          ++count;
          weight_sum += o;
        }
      const bool any = count > 0 && weight_sum > 0.0;
      const T y_mean = any ? y_sum / K<T>(weight_sum) : K<T>(0.0);
      // The x centroid of a full pupil (0 by symmetry on the mirrored half pupil): x about it.
      if (sys.full_pupil && any) {
        T x_sum = K<T>(0.0);
        for (std::size_t i = 0; i < xs.size(); ++i)
          if (ok[i]) {
            const double o = spot_w.wavelength[i / rays];
            x_sum = o == 1.0 ? x_sum + xs[i] : x_sum + K<T>(o) * xs[i];
          }
        const T x_mean = x_sum / K<T>(weight_sum);
        for (std::size_t i = 0; i < xs.size(); ++i)
          if (ok[i]) xs[i] = xs[i] - x_mean;
      }
      T s2 = K<T>(0.0);
      for (std::size_t i = 0; i < ys.size(); ++i)
        if (ok[i]) {
          const double o = spot_w.wavelength[i / rays];
          const T dy = ys[i] - y_mean;
          s2 = o == 1.0 ? s2 + dy * dy + xs[i] * xs[i] : s2 + K<T>(o) * (dy * dy + xs[i] * xs[i]);
        }
      field_rms[h] = any ? detail::safe_norm(s2 / K<T>(weight_sum)) : K<T>(0.0);
      if (residuals && !wavefront) {
        const double a_h = field_weights ? (*field_weights)[h]
                                         : (equal_fields ? 1.0 / field_count : phi[h] / phi_sum);
        // r = sqrt(w_S a_h omega_w / (sum_w omega_w P)) (y - ybar_h): sum of squares
        // a_h S_h^2 when no ray fails.
        const double denominator = spot_omega_sum * rays;
        T* r = residuals + static_cast<std::size_t>(h) * spot_block;
        for (int w = 0; w < wl; ++w) {
          const double o = spot_w.wavelength[w];
          const T scale = K<T>(std::sqrt(o == 1.0 ? options.weight_spot * a_h / denominator
                                                  : options.weight_spot * a_h * o / denominator));
          for (int p = 0; p < rays; ++p) {
            const std::size_t i = static_cast<std::size_t>(w) * rays + p;
            r[2 * i] = ok[i] ? scale * (ys[i] - y_mean) : K<T>(0.0);
            r[2 * i + 1] = ok[i] ? scale * xs[i] : K<T>(0.0);
          }
        }
      }
    }
  }

  // Glass-variable loss and residuals.
  T glass_loss = K<T>(0.0);
  int glass_pair = 0;
  for (int i = 0; i < param.size(); ++i) {
    if (param.variables()[i].kind != LensVariable::Kind::kGlass0) continue;
    const Eigen::Vector2d g(value_of(x[i]), value_of(x[i + 1]));
    const Eigen::Vector2d p = param.glass_space().glass_point(param.glass_space().nearest(g));
    const T d0 = x[i] - K<T>(p[0]);
    const T d1 = x[i + 1] - K<T>(p[1]);
    glass_loss = glass_loss + d0 * d0 + d1 * d1;
    if (residuals) {
      const T s = K<T>(std::sqrt(options.weight_glass));
      residuals[glass_offset + 2 * glass_pair] = s * d0;
      residuals[glass_offset + 2 * glass_pair + 1] = s * d1;
    }
    ++glass_pair;
  }

  const T profile = profile_bound_loss(lens, specs, options.max_surface_slope_deg);
  T spot = K<T>(0.0), path = K<T>(0.0), angle = K<T>(0.0);
  int failed_total = 0;
  T wave = K<T>(0.0);
  // sum_h phi_h S_h / sum_h phi_h (spot.h; the plain mean with equal weights).
  for (int h = 0; h < field_count; ++h)
    spot = phi[h] == 1.0 ? spot + field_rms[h] : spot + K<T>(phi[h]) * field_rms[h];
  T angular = K<T>(0.0);
  for (int h = 0; h < static_cast<int>(field_angle.size()); ++h)
    angular = phi[h] == 1.0 ? angular + field_angle[h] : angular + K<T>(phi[h]) * field_angle[h];
  angular = angular / K<T>(phi_sum);
  for (int h = 0; h < static_cast<int>(field_wave.size()); ++h)
    wave = phi[h] == 1.0 ? wave + field_wave[h] : wave + K<T>(phi[h]) * field_wave[h];
  wave = wave / K<T>(phi_sum);
  const T merit = wavefront ? K<T>(wave_unit) * wave : spot / K<T>(phi_sum);
  for (int hf = 0; hf < all_fields; ++hf) {
    path = path + path_linear[hf];
    angle = angle + angle_linear[hf];
    failed_total += failed[hf];
  }
  spot = spot / K<T>(phi_sum);
  path = path / K<T>(n_r);
  angle = angle / K<T>(n_r);
  if (extremes) {
    *extremes = field_extremes[0];
    for (int h = 1; h < all_fields; ++h) {
      for (int k = 0; k < k_count; ++k) {
        extremes->min_travel_mm[k] =
            std::min(extremes->min_travel_mm[k], field_extremes[h].min_travel_mm[k]);
        extremes->max_travel_mm[k] =
            std::max(extremes->max_travel_mm[k], field_extremes[h].max_travel_mm[k]);
      }
      extremes->min_cos2_angle =
          std::min(extremes->min_cos2_angle, field_extremes[h].min_cos2_angle);
    }
  }
  if (loss) {
    loss->spot_mm = spot;
    loss->ray_path_mm = path;
    loss->ray_angle = angle;
    loss->glass = glass_loss;
    loss->total = K<T>(options.weight_spot) * merit + K<T>(options.weight_ray_path) * path +
                  K<T>(options.weight_ray_angle) * angle + K<T>(options.weight_glass) * glass_loss +
                  K<T>(options.weight_profile) * profile;
    loss->profile = profile;
    loss->field_rms_mm = field_rms;
    loss->field_weights = phi;
    loss->merit = options.merit;
    loss->wavefront_waves = wave;
    loss->field_wavefront_waves = field_wave;
    loss->afocal = afocal;
    loss->angular_spot_rad = angular;
    loss->field_angular_spot_rad = field_angle;
    loss->angular_unit_mm = angle_unit;
    loss->failed_rays = failed_total;
    loss->rays = static_cast<int>(n_r);
  }
  const double total_value =
      value_of(merit) + value_of(path) + value_of(angle) + value_of(glass_loss) + value_of(profile);
  return std::isfinite(total_value);
}

// evaluate_design on the Jets of core/jet_width.h is compiled once per width, in a translation unit
// of its own (src/optimize/design_loss_jet.cpp.in, at the inlining budget of the LM Jacobian).
#define LENSOPT_DESIGN_LOSS_JET(N)                                                            \
  extern template bool evaluate_design<ceres::Jet<double, N>>(                                \
      const LensParameterization&, const ceres::Jet<double, N>*, GlassMode,                   \
      const std::vector<int>&, const TraceOptions&, const DesignLossOptions&,                 \
      const std::vector<double>*, ceres::Jet<double, N>*, DesignLoss<ceres::Jet<double, N>>*, \
      DesignExtremes*);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_DESIGN_LOSS_JET)
#undef LENSOPT_DESIGN_LOSS_JET
// evaluate_design on double (the LM residuals and the reports' loss) is compiled once, in
// src/optimize/design_double.cpp (BENCHMARKS.md "Build time, third round").
extern template bool evaluate_design<double>(const LensParameterization&, const double*, GlassMode,
                                             const std::vector<int>&, const TraceOptions&,
                                             const DesignLossOptions&, const std::vector<double>*,
                                             double*, DesignLoss<double>*, DesignExtremes*);

}  // namespace lensopt
