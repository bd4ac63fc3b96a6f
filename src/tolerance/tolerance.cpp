// Monte-Carlo tolerancing: the nominal model, trial draws, evaluation and the run.
// The maths and conventions are in include/lensopt/tolerance/tolerance.h.
#include "lensopt/tolerance/tolerance.h"

#include <ceres/ceres.h>
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <mutex>

#include "lensopt/analysis/field_maps.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/core/error.h"
#include "lensopt/core/random.h"
#include "lensopt/core/threads.h"
#include "lensopt/lens/profile_sag.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/system.h"

namespace lensopt {
namespace {

// One unit draw in [-1, 1]: uniform, or normal with sigma 1/2 truncated at +-1 (Box-Muller,
// rejection outside the limits).
double unit_draw(Rng& rng, ToleranceDistribution distribution) {
  if (distribution == ToleranceDistribution::kUniform) return 2.0 * unit_interval(rng) - 1.0;
  for (;;) {
    const double u1 = 1.0 - unit_interval(rng);  // (0, 1]
    const double u2 = unit_interval(rng);
    const double z = std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
    const double u = 0.5 * z;
    if (std::abs(u) <= 1.0) return u;
  }
}

// The minimum of a convex function by golden-section search: bracket from [-h, h] outwards,
// then shrink until the bracket is below `tolerance`.
template <typename F>
double minimize_convex(F&& f, double h, double tolerance) {
  double a = -h, m = 0.0, b = h;
  double fa = f(a), fm = f(m), fb = f(b);
  for (int i = 0; i < 60 && (fa < fm || fb < fm); ++i) {
    if (fa < fm) {  // move left
      b = m, fb = fm;
      m = a, fm = fa;
      a = m - 2.0 * (b - m);
      fa = f(a);
    } else {  // move right
      a = m, fa = fm;
      m = b, fm = fb;
      b = m + 2.0 * (m - a);
      fb = f(b);
    }
  }
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);  // 0.618...
  double x1 = b - g * (b - a), x2 = a + g * (b - a);
  double f1 = f(x1), f2 = f(x2);
  for (int i = 0; i < 200 && (b - a) > tolerance; ++i) {
    if (f1 <= f2) {
      b = x2;
      x2 = x1, f2 = f1;
      x1 = b - g * (b - a);
      f1 = f(x1);
    } else {
      a = x1;
      x1 = x2, f1 = f2;
      x2 = a + g * (b - a);
      f2 = f(x2);
    }
  }
  const double x = 0.5 * (a + b);
  // Never worse than the starting plane (tau = 0), e.g. for a function flat to rounding.
  return f(x) <= f(0.0) ? x : 0.0;
}

// One field's spot through focus (tolerance.h, "Compensators beyond focus"), from its moments:
// about its centroid S^2(t) = a + 2 b t + c t^2, the centroid p + t q in the image frame (mm).
struct FieldThroughFocus {
  double a = 0, b = 0, c = 0;
  double px = 0, py = 0, qx = 0, qy = 0;
};

FieldThroughFocus field_through_focus(const TraceSystem<double>& sys, int h,
                                      const ThroughFocusSpot& f) {
  FieldThroughFocus out;
  if (f.count() == 0 || !(f.spot.weight_sum > 0.0)) return out;
  // The quadratic's coefficients from three values (exact up to rounding: it is a quadratic).
  out.a = f.variance(0.0);
  const double plus = f.variance(1.0), minus = f.variance(-1.0);
  out.b = 0.25 * (plus - minus);
  out.c = 0.5 * (plus + minus) - out.a;
  // The centroid in the field's frame, (u, v) + t (du, dv), then turned into the image frame.
  const double inv = 1.0 / f.spot.weight_sum;
  const double u = f.spot.centroid_x();
  const double du = f.spot.full_pupil ? f.sum_sx * inv : 0.0;
  const double v = f.centroid(0.0);
  const double dv = f.sy0 + f.sum_ds * inv;
  sys.field_to_lens(h, u, v, out.px, out.py);
  sys.field_to_lens(h, du, dv, out.qx, out.qy);
  return out;
}

// The residuals of the image-shift solve: r_h = sqrt(w_h S_h), S_h^2 = a + 2 b t + c t^2 +
// |p + t q - n - s|^2 (w_h = phi_h / sum phi), so sum r_h^2 is the mean RMS spot (mm).
struct ImageShiftResidual {
  const std::vector<FieldThroughFocus>* lines;
  const std::vector<double>* nominal_x;
  const std::vector<double>* nominal_y;
  const std::vector<double>* weights;
  template <typename T>
  bool operator()(const T* shift, const T* tau, T* residuals) const {
    using std::sqrt;
    const T& t = tau[0];
    for (std::size_t h = 0; h < lines->size(); ++h) {
      const FieldThroughFocus& f = (*lines)[h];
      const T dx = K<T>(f.px - (*nominal_x)[h]) + t * K<T>(f.qx) - shift[0];
      const T dy = K<T>(f.py - (*nominal_y)[h]) + t * K<T>(f.qy) - shift[1];
      T v = K<T>(f.a) + t * (K<T>(2.0 * f.b) + t * K<T>(f.c)) + dx * dx + dy * dy;
      // S_h > 0 for any real spot; a point image would make sqrt(sqrt) singular at 0.
      if (!(v > K<T>(1e-30))) v = K<T>(1e-30);
      residuals[h] = K<T>(std::sqrt((*weights)[h])) * sqrt(sqrt(v));
    }
    return true;
  }
};

struct ImageShift {
  double x_mm = 0, y_mm = 0, tau = 0;
};

// The image shift (and, with the best-rms focus, the focus shift tau) minimizing the mean RMS
// spot about the shifted nominal image points: Levenberg-Marquardt on ImageShiftResidual from
// the closed-form shift of the centroids s_0 = sum_h w_h (p_h - n_h) (tau = 0); the result is
// never worse than that start.
ImageShift solve_image_shift(const std::vector<FieldThroughFocus>& lines,
                             const std::vector<double>& nominal_x,
                             const std::vector<double>& nominal_y,
                             const std::vector<double>& weights, bool solve_focus) {
  ImageShift start;
  for (std::size_t h = 0; h < lines.size(); ++h) {
    start.x_mm += weights[h] * (lines[h].px - nominal_x[h]);
    start.y_mm += weights[h] * (lines[h].py - nominal_y[h]);
  }
  double shift[2] = {start.x_mm, start.y_mm};
  double tau[1] = {0.0};
  const ImageShiftResidual functor{&lines, &nominal_x, &nominal_y, &weights};
  auto cost = [&](const double* s, const double* t) {
    std::vector<double> r(lines.size());
    functor(s, t, r.data());
    double sum = 0.0;
    for (double v : r) sum += v * v;
    return sum;
  };
  const double start_cost = cost(shift, tau);
  ceres::Problem problem;
  problem.AddResidualBlock(
      new ceres::AutoDiffCostFunction<ImageShiftResidual, ceres::DYNAMIC, 2, 1>(
          new ImageShiftResidual(functor), static_cast<int>(lines.size())),
      nullptr, shift, tau);
  if (!solve_focus) problem.SetParameterBlockConstant(tau);
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::DENSE_QR;
  options.max_num_iterations = 200;
  options.function_tolerance = 1e-16;
  options.gradient_tolerance = 1e-16;
  options.parameter_tolerance = 1e-15;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  if (!(std::isfinite(shift[0]) && std::isfinite(shift[1]) && std::isfinite(tau[0])) ||
      !(cost(shift, tau) <= start_cost))
    return start;
  return {shift[0], shift[1], tau[0]};
}

std::string glass_label(const Material& m) {
  if (m.kind == Material::Kind::kCatalog) return m.glass_name;
  return fmt::format("nd {:.4f}, vd {:.2f}", m.nd, m.vd);
}

std::string format_limit(double value, const char* unit) {
  return fmt::format("{:g}{}", value, unit);
}

// Clear semi-aperture per surface (mm): its semi-diameter when the lens gives one, else the
// paraxial estimate |y_marginal| + |y_chief| (paraxial.h, the optimizer's profile bounds' too).
std::vector<double> clear_semi_apertures_mm(const Lens& lens, const TraceLens<double>& tl) {
  // Non-finite where the paraxial estimate is (the edge-gap check then skips that space).
  std::vector<double> aperture = paraxial_clear_semi_apertures_or_nonfinite(tl, lens.specs);
  for (int k = 0; k < tl.surface_count(); ++k) {
    const double given = lens.surfaces[k].semi_diameter_mm;
    if (given > 0.0) aperture[k] = given;
  }
  return aperture;
}

// The profile terms of the non-spherical surfaces (tolerance.h, "profile").
void add_profile_parameters(const Lens& lens, const Tolerances& tol,
                            std::vector<ToleranceParameter>& out) {
  using Kind = ToleranceParameter::Kind;
  bool any = false;
  for (const Surface& s : lens.surfaces) any = any || !s.is_spherical();
  if (!any) return;
  const std::vector<double> aperture = clear_semi_apertures_mm(lens, make_trace_lens(lens));
  const double sag_mm = tol.asphere_sag_um / 1000.0;
  const int k_count = static_cast<int>(lens.surfaces.size());
  for (int k = 0; k < k_count; ++k) {
    const Surface& s = lens.surfaces[k];
    if (s.is_spherical()) continue;
    const double h = aperture[k];
    const bool usable = std::isfinite(h) && h > 0.0;
    const std::string where = fmt::format("{:g} um sag at h {:.4g} mm", tol.asphere_sag_um, h);
    // Conic: dS/dk = c^3 h^4 / (2 q (1 + q)^2), q = sqrt(1 - (1 + k) c^2 h^2).
    const double c = s.curvature_per_mm;
    if (c != 0.0) {
      const double q2 = 1.0 - (1.0 + s.conic) * c * c * h * h;
      const double q = std::sqrt(std::max(q2, 0.0));
      const double slope = std::abs(c * c * c) * h * h * h * h / (2.0 * q * (1.0 + q) * (1.0 + q));
      ToleranceParameter p;
      p.kind = Kind::kConic;
      p.surface = k;
      p.limit = usable && q2 > 0.0 && slope > 0.0 ? sag_mm / slope : 0.0;
      p.name = fmt::format("k{}", k + 1);
      p.column = fmt::format("dk{}", k + 1);
      p.description = fmt::format("surface {} conic constant (k {:.6g})", k + 1, s.conic);
      p.limit_text = fmt::format("{} (k +-{:.3g})", where, p.limit);
      out.push_back(p);
    }
    // Asphere terms a_2i (term j = i - 1): the sag a_2i h^(2i).
    for (int j = 0; j < kAsphereTerms; ++j) {
      const double value = j == 0 ? s.asphere_r2_per_mm : s.asphere[j - 1];
      if (value == 0.0) continue;
      const int power = 2 * (j + 1);
      ToleranceParameter p;
      p.kind = Kind::kAsphere;
      p.surface = k;
      p.term = j;
      p.limit = usable ? sag_mm / std::pow(h, power) : 0.0;
      p.name = fmt::format("a{}_{}", power, k + 1);
      p.column = fmt::format("da{}_{}", power, k + 1);
      p.description =
          fmt::format("surface {} asphere term a{} ({:.6g} mm^{})", k + 1, power, value, 1 - power);
      p.limit_text = fmt::format("{} (a{} +-{:.3g})", where, power, p.limit);
      out.push_back(p);
    }
  }
}

}  // namespace

namespace {

// Element decenters and tilts (TEDX, TEDY, TETX, TETY; see the header): each run of glasses (a
// "group": a cemented pair is one group but two elements in the rows above),
// surfaces a .. b (b the first surface followed by air), as a whole.
void add_placement_parameters(const Lens& lens, const Tolerances& tol,
                              std::vector<ToleranceParameter>& out) {
  using Kind = ToleranceParameter::Kind;
  for (const Surface& s : lens.surfaces)
    if (s.mirror || s.breaks_symmetry()) return;  // not modelled for such lenses (header)
  const int k_count = static_cast<int>(lens.surfaces.size());
  int element = 0;
  for (int a = 0; a < k_count; ++a) {
    if (lens.surfaces[a].material.is_air()) continue;
    int b = a;
    while (b < k_count && !lens.surfaces[b].material.is_air()) ++b;
    if (b >= k_count) break;  // validate() keeps the last medium air
    ++element;
    const std::string surfaces = fmt::format("surfaces {} to {}", a + 1, b + 1);
    const struct {
      Kind kind;
      const char* name;
      const char* unit;
      double limit;
      const char* what;
    } kinds[4] = {{Kind::kDecenterX, "tedx", "mm", tol.decenter_mm, "decenter x"},
                  {Kind::kDecenterY, "tedy", "mm", tol.decenter_mm, "decenter y"},
                  {Kind::kTiltX, "tetx", "arcmin", tol.tilt_arcmin, "tilt about x"},
                  {Kind::kTiltY, "tety", "arcmin", tol.tilt_arcmin, "tilt about y"}};
    for (const auto& k : kinds) {
      ToleranceParameter p;
      p.kind = k.kind;
      p.surface = a;
      p.last_surface = b;
      p.limit = k.limit;
      p.name = fmt::format("{}{}", k.name, element);
      p.column = fmt::format("{}{}_{}", k.name, element, k.unit);
      p.description = fmt::format("group {} {} ({})", element, k.what, surfaces);
      p.limit_text = format_limit(
          k.limit, k.kind == Kind::kDecenterX || k.kind == Kind::kDecenterY ? " mm" : " arcmin");
      out.push_back(p);
    }
    a = b - 1;  // the next element starts after b (the loop's ++a gives b, which is air)
  }
}

// Surface decenters and tilts (TSDX, TSDY, TSTX, TSTY; see the header): each surface alone,
// added only when its tolerance is nonzero (a lens toleranced without them keeps its parameter
// list, CSV columns and draws). Not the stop, not a coordinate break, not a surface that has a
// placement of its own; a flat surface gets no decenter (a plane decentred in itself is the same
// plane). A mirror's tilt is named as such.
void add_surface_placement_parameters(const Lens& lens, const Tolerances& tol,
                                      std::vector<ToleranceParameter>& out) {
  using Kind = ToleranceParameter::Kind;
  if (!(tol.surface_decenter_mm > 0.0) && !(tol.surface_tilt_arcmin > 0.0)) return;
  const int k_count = static_cast<int>(lens.surfaces.size());
  for (int k = 0; k < k_count; ++k) {
    const Surface& s = lens.surfaces[k];
    if (s.is_stop || s.coordinate_break || s.breaks_symmetry()) continue;
    const bool flat = s.curvature_per_mm == 0.0 && s.asphere_r2_per_mm == 0.0 && !s.has_asphere();
    const struct {
      Kind kind;
      const char* name;
      const char* unit;
      double limit;
      const char* what;
    } kinds[4] = {{Kind::kSurfaceDecenterX, "tsdx", "mm", tol.surface_decenter_mm, "decenter x"},
                  {Kind::kSurfaceDecenterY, "tsdy", "mm", tol.surface_decenter_mm, "decenter y"},
                  {Kind::kSurfaceTiltX, "tstx", "arcmin", tol.surface_tilt_arcmin,
                   s.mirror ? "mirror tilt about x" : "tilt (wedge) about x"},
                  {Kind::kSurfaceTiltY, "tsty", "arcmin", tol.surface_tilt_arcmin,
                   s.mirror ? "mirror tilt about y" : "tilt (wedge) about y"}};
    for (const auto& kind : kinds) {
      const bool decenter =
          kind.kind == Kind::kSurfaceDecenterX || kind.kind == Kind::kSurfaceDecenterY;
      if (!(kind.limit > 0.0) || (decenter && flat)) continue;
      ToleranceParameter p;
      p.kind = kind.kind;
      p.surface = k;
      p.last_surface = k;
      p.limit = kind.limit;
      p.name = fmt::format("{}{}", kind.name, k + 1);
      p.column = fmt::format("{}{}_{}", kind.name, k + 1, kind.unit);
      p.description = fmt::format("surface {} {}", k + 1, kind.what);
      p.limit_text = format_limit(kind.limit, decenter ? " mm" : " arcmin");
      out.push_back(p);
    }
  }
}

}  // namespace

std::vector<ToleranceParameter> tolerance_parameters(const Lens& lens, const Tolerances& tol) {
  using Kind = ToleranceParameter::Kind;
  std::vector<ToleranceParameter> out;
  const int k_count = static_cast<int>(lens.surfaces.size());
  const int stop = lens.stop_index();
  // Element number (1-based) of the glass after surface k; 0 for air. Each glass is its own
  // element: the two halves of a cemented pair are elements 1 and 2, not both element 1.
  std::vector<int> element(k_count, 0);
  int e = 0;
  for (int k = 0; k < k_count; ++k)
    if (!lens.surfaces[k].material.is_air()) element[k] = ++e;
  for (int k = 0; k < k_count; ++k) {
    const Surface& s = lens.surfaces[k];
    if (s.is_stop || s.curvature_per_mm == 0.0) continue;
    ToleranceParameter p;
    p.kind = Kind::kCurvature;
    p.surface = k;
    p.limit = tol.curvature_pct / 100.0;
    p.name = fmt::format("c{}", k + 1);
    p.column = fmt::format("dc{}_rel", k + 1);
    p.description =
        fmt::format("surface {} curvature (R {:.4g} mm)", k + 1, 1.0 / s.curvature_per_mm);
    p.limit_text = format_limit(tol.curvature_pct, " %");
    out.push_back(p);
  }
  for (int k = 0; k + 1 < k_count; ++k) {
    const Surface& s = lens.surfaces[k];
    ToleranceParameter p;
    p.kind = Kind::kThickness;
    p.surface = k;
    p.air = s.material.is_air();
    p.name = fmt::format("t{}", k + 1);
    p.column = fmt::format("dt{}_mm", k + 1);
    if (p.air) {
      if (k + 1 == stop) continue;  // the stop is mounted with the group before it
      p.limit = tol.air_thickness_mm;
      p.description = fmt::format("airspace surface {} to {}", k + 1, k + 2);
    } else {
      p.limit = tol.glass_thickness_mm;
      p.description = fmt::format("element {} thickness, surface {} to {} ({})", element[k], k + 1,
                                  k + 2, glass_label(s.material));
    }
    p.limit_text = format_limit(p.limit, " mm");
    out.push_back(p);
  }
  for (int pass = 0; pass < 2; ++pass) {
    for (int k = 0; k < k_count; ++k) {
      const Surface& s = lens.surfaces[k];
      if (s.material.is_air()) continue;
      ToleranceParameter p;
      p.surface = k;
      if (pass == 0) {
        p.kind = Kind::kNd;
        p.limit = tol.nd;
        p.name = fmt::format("nd{}", k + 1);
        p.column = fmt::format("dnd{}", k + 1);
        p.description = fmt::format("element {} index nd, glass after surface {} ({})", element[k],
                                    k + 1, glass_label(s.material));
        p.limit_text = format_limit(tol.nd, "");
      } else {
        p.kind = Kind::kVd;
        p.limit = tol.vd_pct / 100.0;
        p.name = fmt::format("vd{}", k + 1);
        p.column = fmt::format("dvd{}_rel", k + 1);
        p.description = fmt::format("element {} Abbe number vd, glass after surface {} ({})",
                                    element[k], k + 1, glass_label(s.material));
        p.limit_text = format_limit(tol.vd_pct, " %");
      }
      out.push_back(p);
    }
  }
  add_profile_parameters(lens, tol, out);
  add_placement_parameters(lens, tol, out);
  add_surface_placement_parameters(lens, tol, out);
  return out;
}

struct ToleranceModel::Impl {
  ToleranceOptions options;
  Specs specs;
  Lens scaled_lens;
  TraceLens<double> nominal;
  std::vector<ToleranceParameter> parameters;
  double scale = 1;
  double stop_height_mm = 0;  // paraxial marginal-ray height at the stop (fixed aperture)
  double defocus_mm = 0;      // t0_{K-1} - BFL0
  double image_distance0_mm = 0;
  std::vector<double> fields_deg;
  // A lens with its own system data (SpecMode::kAsWritten and written fields) is traced at its
  // fields (type, weights, vignetting factors) and object distance, not at 0..hfov.
  bool as_written = false;
  SystemSetup written;
  int rays = 0;
  // Edge-gap check: per space k (between surfaces k and k+1, the image space excluded) the
  // height it is checked at (mm) and whether the nominal's gap there is >= 0 (a space that is
  // already negative in the nominal, such as a stop at a curved vertex, is not checked).
  std::vector<double> gap_height_mm;
  std::vector<char> gap_checked;
  // Compensators beyond focus (header): per decentred group its tedx/tedy parameter indices;
  // the nominal image points q_h (image frame, mm; spot_reference nominal, once the nominal is
  // traced).
  std::vector<int> comp_dx, comp_dy;
  std::vector<double> nominal_x_mm, nominal_y_mm;

  // Traces the nominal with `perturbations` applied and the decentred groups moved further by
  // `decenters` (2 per decenter compensator, x and y; null: none), compensated in focus and
  // image shift (the evaluation of ToleranceModel::evaluate without the decenter solve).
  TrialResult trace(const std::vector<double>& perturbations, const double* decenters) const;
  // The nominal image points (after the rest is set up).
  void finish_setup();

  // Axial distance from surface k to k+1 at height h: t_k + sag_{k+1}(h) - sag_k(h), the
  // profile's sag c h^2 / (1 + q) + a2 h^2 + ... + a16 h^16 (lens/profile_sag.h) with q clamped
  // at 0 outside the conic's domain (for a sphere: h kept inside it, |c| h > 1 gives c h^2).
  static double edge_gap_mm(const TraceLens<double>& tl, int k, double h) {
    const double rho = h * h;
    const double spherical[kAsphereTerms] = {};
    auto sag = [&tl, rho, &spherical](int i) {
      const double c = tl.curvature_per_mm[i];
      const bool profiled = tl.has_profiles();
      const double one_plus_k = profiled ? 1.0 + tl.conic[i] : 1.0;
      const double* a =
          profiled ? tl.asphere.data() + static_cast<std::size_t>(i) * kAsphereTerms : spherical;
      const double q = std::sqrt(std::max(profile_q2(c, one_plus_k, rho), 0.0));  // the clamp
      return profile_sag_at_q(c, a, rho, q);
    };
    return tl.thickness_mm[k] + sag(k + 1) - sag(k);
  }

  // Moves surface j alone (restore_frame: the surfaces after it stay): adds `value` to slot
  // `slot` of its placement (0, 1: decenter x, y in mm; 2, 3: tilt about x, y in deg). The one
  // place where element (TEDX..TETY) and surface (TSDX..TSTY) perturbations and the decenter
  // compensators change a placement; the nominal's placement of such a surface is zero.
  static void move_surface(TraceLens<double>& tl, int j, int slot, double value) {
    tl.geometry.placement[static_cast<std::size_t>(j) * 5 + static_cast<std::size_t>(slot)] +=
        value;
    tl.geometry.flags[static_cast<std::size_t>(j)] |= kPlacementMoved | kPlacementRestore;
  }

  TraceLens<double> apply(const std::vector<double>& perturbations) const {
    using Kind = ToleranceParameter::Kind;
    TraceLens<double> tl = nominal;
    for (std::size_t i = 0; i < parameters.size(); ++i) {
      const ToleranceParameter& p = parameters[i];
      const double d = perturbations[i];
      switch (p.kind) {
        case Kind::kCurvature:
          tl.curvature_per_mm[p.surface] *= 1.0 + d;
          break;
        case Kind::kThickness:
          tl.thickness_mm[p.surface] += d;
          break;
        case Kind::kNd:
          tl.nd[p.surface] += d;
          break;
        case Kind::kVd:
          tl.vd[p.surface] *= 1.0 + d;
          break;
        case Kind::kConic:
          // Only non-spherical surfaces have profile terms: their loop is already the profile's.
          tl.ensure_profiles();
          tl.conic[p.surface] += d;
          if (tl.profile[p.surface] == kProfileSphere) tl.profile[p.surface] = kProfileConic;
          break;
        case Kind::kAsphere:
          tl.ensure_profiles();
          tl.asphere[static_cast<std::size_t>(p.surface) * kAsphereTerms + p.term] += d;
          tl.profile[p.surface] = kProfileAsphere;
          break;
        case Kind::kDecenterX:
        case Kind::kDecenterY:
        case Kind::kTiltX:
        case Kind::kTiltY: {
          if (d == 0.0) break;
          // The nominal carries zero placements whenever these parameters are toleranced.
          const double theta = d / 60.0 * kDegToRad;  // tilts: arcmin
          double z = 0.0;  // vertex of surface j behind the element's first one
          for (int j = p.surface; j <= p.last_surface; ++j) {
            switch (p.kind) {
              case Kind::kDecenterX:
                move_surface(tl, j, 0, d);
                break;
              case Kind::kDecenterY:
                move_surface(tl, j, 1, d);
                break;
              case Kind::kTiltX:  // Rx(theta) takes (0, 0, z) to (0, -z sin theta, z cos theta)
                move_surface(tl, j, 1, -z * std::sin(theta));
                move_surface(tl, j, 2, d / 60.0);
                break;
              default:  // kTiltY: Ry(theta) takes (0, 0, z) to (z sin theta, 0, z cos theta)
                move_surface(tl, j, 0, z * std::sin(theta));
                move_surface(tl, j, 3, d / 60.0);
                break;
            }
            z += nominal.thickness_mm[j];
          }
          break;
        }
        case Kind::kSurfaceDecenterX:
          if (d != 0.0) move_surface(tl, p.surface, 0, d);
          break;
        case Kind::kSurfaceDecenterY:
          if (d != 0.0) move_surface(tl, p.surface, 1, d);
          break;
        case Kind::kSurfaceTiltX:  // about the surface's vertex, arcmin -> deg
          if (d != 0.0) move_surface(tl, p.surface, 2, d / 60.0);
          break;
        case Kind::kSurfaceTiltY:
          if (d != 0.0) move_surface(tl, p.surface, 3, d / 60.0);
          break;
      }
    }
    return tl;
  }
};

ToleranceModel::ToleranceModel(const Lens& lens, const ToleranceOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.validate();
  Impl& m = *impl_;
  m.options = options;
  m.options.progress = nullptr;
  m.specs = lens.specs;
  // The scale as analyze computes it, then the nominal at the spec focal length.
  m.scale = lens_spec_scale(lens);
  if (!(std::isfinite(m.scale) && m.scale > 0))
    throw Error(SourceLocation{lens.source_path},
                fmt::format("cannot scale the lens to the spec focal length (paraxial EFL {} mm)",
                            lens.specs.focal_length_mm() / m.scale));
  m.scaled_lens = scaled(lens, m.scale);
  m.nominal = make_trace_lens(m.scaled_lens);
  m.parameters = tolerance_parameters(m.scaled_lens, options.tolerances);
  // Element decenters and tilts: zero placements on the nominal, so that every trial and the
  // nominal alike take the kernel's 3D path on the full pupil (a zero placement moves nothing).
  bool placed = false;
  for (const ToleranceParameter& p : m.parameters)
    placed = placed || (p.limit > 0.0 && (p.kind == ToleranceParameter::Kind::kDecenterX ||
                                          p.kind == ToleranceParameter::Kind::kDecenterY ||
                                          p.kind == ToleranceParameter::Kind::kTiltX ||
                                          p.kind == ToleranceParameter::Kind::kTiltY ||
                                          p.kind == ToleranceParameter::Kind::kSurfaceDecenterX ||
                                          p.kind == ToleranceParameter::Kind::kSurfaceDecenterY ||
                                          p.kind == ToleranceParameter::Kind::kSurfaceTiltX ||
                                          p.kind == ToleranceParameter::Kind::kSurfaceTiltY));
  // Decenter compensators: the groups' tedx/tedy parameters (present, with limit 0 when the
  // decenter tolerance is 0, on every lens without mirrors or placements of its own).
  for (int k : options.decenter_compensators) {
    int dx = -1, dy = -1, groups = 0;
    for (std::size_t i = 0; i < m.parameters.size(); ++i) {
      const ToleranceParameter& p = m.parameters[i];
      if (p.kind == ToleranceParameter::Kind::kDecenterX) ++groups;
      if (p.kind == ToleranceParameter::Kind::kDecenterX && p.name == fmt::format("tedx{}", k))
        dx = static_cast<int>(i);
      if (p.kind == ToleranceParameter::Kind::kDecenterY && p.name == fmt::format("tedy{}", k))
        dy = static_cast<int>(i);
    }
    if (dx < 0 || dy < 0)
      throw Error(SourceLocation{lens.source_path.empty() ? lens.name : lens.source_path},
                  groups == 0
                      ? fmt::format("compensator decenter:element={}: the lens has no groups of "
                                    "glasses to decenter (a lens with mirrors or placements of "
                                    "its own has no element decenters)",
                                    k)
                      : fmt::format("compensator decenter:element={}: the lens has {} group{} of "
                                    "glasses (rows tedx1..tedx{})",
                                    k, groups, groups == 1 ? "" : "s", groups));
    m.comp_dx.push_back(dx);
    m.comp_dy.push_back(dy);
  }
  placed = placed || !m.comp_dx.empty();
  if (placed && !m.nominal.geometry.placed()) {
    const std::size_t k_count = static_cast<std::size_t>(m.nominal.surface_count());
    m.nominal.geometry.placement.assign(k_count * 5, 0.0);
    m.nominal.geometry.flags.assign(k_count, 0);
    m.nominal.geometry.aperture_center_mm.assign(k_count * 2, 0.0);
  }

  const ParaxialData<double> par = paraxial_data(m.nominal, m.nominal.reference_nm());
  const double r_ep = par.efl_mm / lens.specs.f_number / 2.0;
  m.stop_height_mm = par.stop_magnification * r_ep;
  m.image_distance0_mm = m.nominal.thickness_mm.back();
  m.defocus_mm = paraxial_defocus_mm(m.nominal, par);
  if (!(std::isfinite(m.stop_height_mm) && m.stop_height_mm != 0.0 && std::isfinite(m.defocus_mm)))
    throw Error(SourceLocation{lens.source_path},
                "the lens has no finite paraxial stop height or back focal length");
  m.fields_deg = field_angles_deg(lens.specs.half_field_deg, options.fields);
  if (lens.specs.mode == SpecMode::kAsWritten && !lens.specs.fields.empty()) {
    TraceOptions to;
    to.rings = options.rings;
    to.fields = options.fields;
    to.ray_aiming = options.ray_aiming;
    to.scale_to_spec = false;
    to.threads = 1;
    m.as_written = true;
    m.written = lens_setup(m.scaled_lens, to);
    // With decenters or tilts toleranced the trials are not rotationally symmetric: a field on
    // -y is then not the mirror of the one on +y, and is traced where it is written (as
    // specs_setup does for a lens with placements of its own).
    if (placed) {
      const SystemSetup fields = specs_setup(m.scaled_lens.specs, to, false);
      m.written.field_values = fields.field_values;
      m.written.field_weights = fields.field_weights;
      m.written.vignetting = fields.vignetting;
      m.written.field_azimuth_deg = fields.field_azimuth_deg;
    }
    // The nominal's chief-ray angles (deg) label the fields.
    const TraceSystem<double> labels =
        prepare_system(make_trace_lens(m.scaled_lens), m.written, to);
    if (!labels.field_solve_failure.empty())
      throw Error(SourceLocation{lens.source_path.empty() ? lens.name : lens.source_path},
                  labels.field_solve_failure);
    m.fields_deg = labels.fields_deg;
  }
  m.rays = static_cast<int>(paper_pupil_samples(options.rings).size()) *
           ((m.as_written && needs_full_pupil(m.written.vignetting)) ||
                    m.scaled_lens.breaks_symmetry() || m.nominal.geometry.placed()
                ? 2
                : 1);

  // Clear semi-apertures (clear_semi_apertures_mm). An element's rim is at the larger of its
  // two surfaces' apertures; two surfaces across air meet first at the smaller one.
  const int k_count = m.nominal.surface_count();
  const std::vector<double> aperture = clear_semi_apertures_mm(m.scaled_lens, m.nominal);
  m.gap_height_mm.assign(std::max(0, k_count - 1), 0.0);
  m.gap_checked.assign(std::max(0, k_count - 1), 0);
  for (int k = 0; k + 1 < k_count; ++k) {
    const bool glass = !m.scaled_lens.surfaces[k].material.is_air();
    const double h =
        glass ? std::max(aperture[k], aperture[k + 1]) : std::min(aperture[k], aperture[k + 1]);
    m.gap_height_mm[k] = std::isfinite(h) ? h : 0.0;
    // A stop at a lens vertex (0 mm away, as a .zmx stop on a curved surface imports) is that
    // surface's own aperture, not a part that can collide.
    const bool stop_at_vertex =
        (m.scaled_lens.surfaces[k].is_stop || m.scaled_lens.surfaces[k + 1].is_stop) &&
        m.nominal.thickness_mm[k] == 0.0;
    m.gap_checked[k] = !stop_at_vertex && std::isfinite(h) &&
                               Impl::edge_gap_mm(m.nominal, k, m.gap_height_mm[k]) >= 0.0 &&
                               m.nominal.thickness_mm[k] >= 0.0
                           ? 1
                           : 0;
  }
  m.finish_setup();
}

ToleranceModel::~ToleranceModel() = default;

void ToleranceModel::Impl::finish_setup() {
  Impl& m = *this;
  // The nominal image points q_h: the nominal's centroids on its compensated image plane.
  if (m.options.spot_reference == SpotReference::kNominal) {
    const TrialResult nominal = m.trace(std::vector<double>(m.parameters.size(), 0.0), nullptr);
    if (nominal.valid) {
      m.nominal_x_mm = nominal.centroid_x_mm;
      m.nominal_y_mm = nominal.centroid_y_mm;
    }
  }
}

const std::vector<ToleranceParameter>& ToleranceModel::parameters() const {
  return impl_->parameters;
}
double ToleranceModel::scale() const {
  return impl_->scale;
}
const Lens& ToleranceModel::scaled_lens() const {
  return impl_->scaled_lens;
}
std::vector<double> ToleranceModel::fields_deg() const {
  return impl_->fields_deg;
}
int ToleranceModel::wavelength_count() const {
  return static_cast<int>(impl_->specs.wavelengths_nm.size());
}
int ToleranceModel::rays_per_field_wavelength() const {
  return impl_->rays;
}
std::vector<std::string> ToleranceModel::compensation_names() const {
  std::vector<std::string> out;
  if (impl_->options.image_shift) out = {"image_shift_x_mm", "image_shift_y_mm"};
  for (int k : impl_->options.decenter_compensators) {
    out.push_back(fmt::format("comp_dx{}_mm", k));
    out.push_back(fmt::format("comp_dy{}_mm", k));
  }
  return out;
}

TraceLens<double> ToleranceModel::perturbed_trace_lens(
    const std::vector<double>& perturbations) const {
  const Impl& m = *impl_;
  if (perturbations.size() != m.parameters.size())
    throw Error(fmt::format("{} perturbations for {} toleranced parameters", perturbations.size(),
                            m.parameters.size()));
  return m.apply(perturbations);
}

InverseSensitivity inverse_sensitivity(const ToleranceModel& model, int parameter, double drop_um,
                                       double nominal_spot_um) {
  const std::vector<ToleranceParameter>& params = model.parameters();
  if (parameter < 0 || parameter >= static_cast<int>(params.size()))
    throw Error(fmt::format("inverse sensitivity: no parameter {}", parameter));
  if (!(drop_um > 0.0) || !std::isfinite(drop_um))
    throw Error(fmt::format("inverse sensitivity: drop {} um must be positive", drop_um));
  const double limit = params[static_cast<std::size_t>(parameter)].limit;
  InverseSensitivity out;
  if (!(limit > 0.0)) return out;
  const double inf = std::numeric_limits<double>::infinity();
  // g(m) - D: the worse side's rise of the mean spot over the drop; an untraceable side counts
  // as beyond any drop.
  std::vector<double> d(params.size(), 0.0);
  auto g = [&](double m) {
    double worst = -inf;
    for (const double sign : {1.0, -1.0}) {
      d[static_cast<std::size_t>(parameter)] = sign * m;
      const TrialResult r = model.evaluate(d);
      ++out.evaluations;
      const double rise = r.valid ? r.mean_spot_um - nominal_spot_um : inf;
      worst = std::max(worst, std::isfinite(rise) ? rise : inf);
    }
    return worst - drop_um;
  };
  // A bracket [lo, hi] with g(lo) < 0 <= g(hi), from the limit: doubling or halving.
  double lo = 0.0, g_lo = -drop_um, hi = limit, g_hi = g(limit);
  if (g_hi < 0.0) {
    lo = hi;
    g_lo = g_hi;
    for (int i = 0; i < 40 && g_hi < 0.0; ++i) {
      lo = hi;
      g_lo = g_hi;
      hi *= 2.0;
      g_hi = g(hi);
    }
    if (g_hi < 0.0) return out;  // 2^40 limits do not reach the drop
  } else {
    for (int i = 0; i < 60; ++i) {
      const double m = 0.5 * hi;
      const double gm = g(m);
      if (gm < 0.0) {
        lo = m;
        g_lo = gm;
        break;
      }
      hi = m;
      g_hi = gm;
    }
  }
  // Regula falsi with the Illinois step (bisection while a side is untraceable).
  const double tol = 1e-4 * drop_um;
  double best = hi, best_g = g_hi;
  int side = 0;
  for (int i = 0; i < 100 && std::abs(best_g) > tol && hi - lo > 1e-12 * hi; ++i) {
    double m = std::isfinite(g_hi) ? (lo * g_hi - hi * g_lo) / (g_hi - g_lo) : 0.5 * (lo + hi);
    if (!(m > lo && m < hi)) m = 0.5 * (lo + hi);
    const double gm = g(m);
    if (std::abs(gm) < std::abs(best_g)) {
      best = m;
      best_g = gm;
    }
    if (gm < 0.0) {
      lo = m;
      g_lo = gm;
      if (side == -1) g_hi *= 0.5;
      side = -1;
    } else {
      hi = m;
      g_hi = gm;
      if (side == 1) g_lo *= 0.5;
      side = 1;
    }
  }
  if (!std::isfinite(best_g)) return out;
  out.limit = best;
  out.spot_change_um = best_g + drop_um;
  return out;
}

std::vector<double> ToleranceModel::draw(int index) const {
  const Impl& m = *impl_;
  Rng rng(stream_seed(m.options.seed, static_cast<std::uint64_t>(index)));
  std::vector<double> out(m.parameters.size());
  for (std::size_t i = 0; i < out.size(); ++i)
    out[i] = m.parameters[i].limit * unit_draw(rng, m.options.distribution);
  return out;
}

TrialResult ToleranceModel::Impl::trace(const std::vector<double>& perturbations,
                                        const double* decenters) const {
  const Impl& m = *this;
  TrialResult r;
  r.perturbations = perturbations;
  const int field_count = static_cast<int>(m.fields_deg.size());
  r.rms_spot_um.assign(field_count, 0.0);
  r.centroid_x_mm.assign(field_count, 0.0);
  r.centroid_y_mm.assign(field_count, 0.0);
  const bool nominal_reference =
      m.options.spot_reference == SpotReference::kNominal && !m.nominal_x_mm.empty();
  // The image shift moves nothing while the spots are about their centroids (and the nominal,
  // which defines q_h, is traced before q_h exists).
  const bool image_shift = m.options.image_shift && nominal_reference;
  if (m.options.image_shift) r.compensation.assign(2, 0.0);

  TraceLens<double> tl;
  if (decenters != nullptr && !m.comp_dx.empty()) {
    // The compensators' decenters add to the group's drawn ones (the same placement slots).
    std::vector<double> moved = perturbations;
    for (std::size_t i = 0; i < m.comp_dx.size(); ++i) {
      moved[static_cast<std::size_t>(m.comp_dx[i])] += decenters[2 * i];
      moved[static_cast<std::size_t>(m.comp_dy[i])] += decenters[2 * i + 1];
      r.compensation.push_back(decenters[2 * i]);
      r.compensation.push_back(decenters[2 * i + 1]);
    }
    tl = m.apply(moved);
  } else {
    for (std::size_t i = 0; i < m.comp_dx.size(); ++i)
      r.compensation.insert(r.compensation.end(), 2, 0.0);
    tl = m.apply(perturbations);
  }
  const int last = tl.surface_count() - 1;
  // Elements that intersect (a checked edge gap below 0, or a centre thickness below 0).
  r.min_edge_gap_mm = std::numeric_limits<double>::infinity();
  for (int k = 0; k + 1 < tl.surface_count(); ++k) {
    if (!m.gap_checked[k]) continue;
    const double gap = std::min(Impl::edge_gap_mm(tl, k, m.gap_height_mm[k]), tl.thickness_mm[k]);
    r.min_edge_gap_mm = std::min(r.min_edge_gap_mm, gap);
    if (gap < 0.0) r.collision = true;
  }
  if (!std::isfinite(r.min_edge_gap_mm)) r.min_edge_gap_mm = 0.0;
  const ParaxialData<double> par = paraxial_data(tl, tl.reference_nm());
  // Reference image plane: the paraxial solve (also the start of the best-RMS search).
  const double t_ref = m.options.compensator == FocusCompensator::kNone
                           ? m.image_distance0_mm
                           : image_distance_for_defocus_mm(par, m.defocus_mm);
  tl.thickness_mm[last] = t_ref;
  r.efl_mm = par.efl_mm;
  r.image_distance_mm = t_ref;
  const double r_ep = m.stop_height_mm / par.stop_magnification;
  const double f_number = par.efl_mm / (2.0 * r_ep);
  if (!(std::isfinite(t_ref) && std::isfinite(f_number) && f_number > 0.0 &&
        std::isfinite(par.efl_mm))) {
    r.valid = false;
    return r;
  }

  TraceOptions to;
  to.rings = m.options.rings;
  to.fields = m.options.fields;
  to.ray_aiming = m.options.ray_aiming;
  to.scale_to_spec = false;
  to.threads = 1;
  SystemSetup setup =
      paper_setup(m.specs.focal_length_mm(), f_number, m.specs.half_field_deg, to.fields);
  setup.scale = false;
  if (m.as_written) {
    // The lens's own fields and object (the aperture stays the fixed stop above).
    setup.field_type = m.written.field_type;
    setup.field_values = m.written.field_values;
    setup.field_weights = m.written.field_weights;
    setup.vignetting = m.written.vignetting;
    // Each field where it is written: a field on x (or on -y of a lens without rotational
    // symmetry) keeps its azimuth, so a trial's decenters and tilts act on it as they would.
    setup.field_azimuth_deg = m.written.field_azimuth_deg;
    setup.object_distance_mm = m.written.object_distance_mm;
  }
  TraceSystem<double> sys = prepare_system(tl, setup, to);

  // The lens's wavelength weights and the fields' weights (the mean spot of analysis/spot.h).
  if (m.specs.wavelength_weights.size() == m.specs.wavelengths_nm.size())
    sys.wavelength_weights = m.specs.wavelength_weights;
  const SpotWeights spot_w = spot_weights(sys);
  std::vector<ThroughFocusSpot> moments(field_count);
  for (ThroughFocusSpot& m : moments) m.spot.full_pupil = sys.full_pupil;
  // One trace of every field and wavelength (analysis/spot.h trace_fields, the trace of
  // measure_fields); its rays also feed the through-focus moments, weighted by omega_w.
  std::vector<double> slopes;
  const SpotResult<double> traced =
      trace_fields(sys, 1, [&](int h, int w, const RayBundle<double>& rays) {
        moments[h].add(rays, slopes, spot_w.wavelength[w]);
      });
  r.ray_failures += traced.total_failed;
  for (int h = 0; h < field_count; ++h) {
    r.ray_failures += traced.vignetted_rays[h];
    if (moments[h].count() == 0) r.valid = false;
  }

  // Each field's spot through focus in the image frame: about its centroid S_h^2(t) = a + 2 b t
  // + c t^2 (ThroughFocusSpot), the centroid p + t q (field frame turned into the image frame).
  std::vector<FieldThroughFocus> lines(field_count);
  for (int h = 0; h < field_count && r.valid; ++h)
    lines[h] = field_through_focus(sys, h, moments[h]);
  const bool best_rms = m.options.compensator == FocusCompensator::kBestRms;
  double tau = 0.0, shift_x = 0.0, shift_y = 0.0;
  // S_h^2 at focus shift t and image shift s, about the centroid or the nominal image point.
  auto field_s2 = [&](int h, double t, double sx, double sy) {
    const FieldThroughFocus& f = lines[h];
    double v = f.a + t * (2.0 * f.b + t * f.c);
    if (nominal_reference) {
      const double dx = f.px + t * f.qx - m.nominal_x_mm[h] - sx;
      const double dy = f.py + t * f.qy - m.nominal_y_mm[h] - sy;
      v += dx * dx + dy * dy;
    }
    return v;
  };
  auto field_rms = [&](int h, double t, double sx, double sy) {
    if (!nominal_reference) return moments[h].rms(t);  // the same bits as before compensators
    const double v = field_s2(h, t, sx, sy);
    return v > 0.0 ? std::sqrt(v) : 0.0;
  };
  if (best_rms && r.valid && !image_shift) {
    auto mean_spot = [&](double t) {
      double sum = 0.0;
      for (int h = 0; h < field_count; ++h)
        sum += spot_w.field[h] == 1.0 ? field_rms(h, t, 0.0, 0.0)
                                      : spot_w.field[h] * field_rms(h, t, 0.0, 0.0);
      return sum / spot_w.field_sum;
    };
    // Start with a bracket of +-2 % of the image distance (or 0.1 mm): focus shifts from
    // manufacturing errors are far smaller; the bracket grows if needed.
    const double h = std::max(0.1, 0.02 * std::abs(t_ref));
    tau = minimize_convex(mean_spot, h, 1e-9 * std::max(1.0, std::abs(t_ref)));
  }
  if (image_shift && r.valid) {
    std::vector<double> weights(field_count);
    for (int h = 0; h < field_count; ++h) weights[h] = spot_w.field[h] / spot_w.field_sum;
    const ImageShift s =
        solve_image_shift(lines, m.nominal_x_mm, m.nominal_y_mm, weights, best_rms);
    tau = s.tau;
    shift_x = s.x_mm;
    shift_y = s.y_mm;
    r.compensation[0] = shift_x;
    r.compensation[1] = shift_y;
  }
  if (tau != 0.0) {
    sys.lens.thickness_mm[last] = t_ref + tau;
    r.image_distance_mm = t_ref + tau;
  }

  double sum = 0.0;
  for (int h = 0; h < field_count; ++h) {
    r.rms_spot_um[h] = field_rms(h, tau, shift_x, shift_y) * 1000.0;
    sum += spot_w.field[h] == 1.0 ? r.rms_spot_um[h] : spot_w.field[h] * r.rms_spot_um[h];
    r.centroid_x_mm[h] = lines[h].px + tau * lines[h].qx;
    r.centroid_y_mm[h] = lines[h].py + tau * lines[h].qy;
  }
  r.mean_spot_um = sum / spot_w.field_sum;
  // Distortion as analyze measures it (analysis/field_maps.h), on the refocused image plane (and
  // about the shifted image: the shift turned into the field's frame).
  const std::vector<double> y_ref = reference_heights(sys);
  for (int h = 0; h < field_count; ++h) {
    if (moments[h].count() == 0) continue;
    double centroid = moments[h].centroid(tau);
    if (shift_x != 0.0 || shift_y != 0.0) {
      const double a = sys.field_azimuth(h) * kDegToRad;
      centroid -= a == 0.0 ? shift_y : shift_x * std::sin(a) + shift_y * std::cos(a);
    }
    const double d = 100.0 * field_distortion(centroid, y_ref[h], y_ref.back());
    r.max_abs_distortion_pct = std::max(r.max_abs_distortion_pct, std::abs(d));
  }
  if (!(std::isfinite(r.mean_spot_um) && std::isfinite(r.max_abs_distortion_pct) &&
        std::isfinite(r.image_distance_mm)))
    r.valid = false;
  return r;
}

namespace {

// The merit of the decenter compensators (tolerance.h): the trial's mean RMS spot (um) with the
// groups moved by x (2 per group, mm), each evaluation a full compensated trace, and its
// gradient by central differences of step kDecenterStep.
class DecenterMerit final : public ceres::FirstOrderFunction {
 public:
  static constexpr double kDecenterStep = 1e-6;  // mm
  DecenterMerit(const std::function<bool(const double*, double*)>& merit, int count)
      : merit_(merit), count_(count) {}
  bool Evaluate(const double* x, double* cost, double* gradient) const override {
    if (!merit_(x, cost)) return false;
    if (gradient == nullptr) return true;
    std::vector<double> at(x, x + count_);
    for (int j = 0; j < count_; ++j) {
      double plus = 0.0, minus = 0.0;
      at[j] = x[j] + kDecenterStep;
      if (!merit_(at.data(), &plus)) return false;
      at[j] = x[j] - kDecenterStep;
      if (!merit_(at.data(), &minus)) return false;
      at[j] = x[j];
      gradient[j] = (plus - minus) / (2.0 * kDecenterStep);
    }
    return true;
  }
  int NumParameters() const override { return count_; }

 private:
  const std::function<bool(const double*, double*)>& merit_;
  int count_;
};

}  // namespace

TrialResult ToleranceModel::evaluate(const std::vector<double>& perturbations) const {
  const Impl& m = *impl_;
  if (perturbations.size() != m.parameters.size())
    throw Error(fmt::format("{} perturbations for {} toleranced parameters", perturbations.size(),
                            m.parameters.size()));
  if (m.comp_dx.empty()) return m.trace(perturbations, nullptr);
  // Decenter compensators: the mean spot minimized over the groups' decenters from (0, 0) by
  // Ceres' line-search BFGS on central differences; the trial ends no worse than uncompensated.
  // (As least squares over the fields, r_h = sqrt(phi_h S_h), Levenberg-Marquardt stalls: the
  // residuals stay large at the minimum, whose curvature is in the r_h's own second
  // derivatives, which Gauss-Newton leaves out; it moved a 0.02 mm decenter back by 0.0001.)
  const int count = static_cast<int>(2 * m.comp_dx.size());
  std::vector<double> moves(static_cast<std::size_t>(count), 0.0);
  const TrialResult start = m.trace(perturbations, moves.data());
  if (!start.valid) return start;
  const std::function<bool(const double*, double*)> merit = [&](const double* d, double* cost) {
    const TrialResult r = m.trace(perturbations, d);
    if (!r.valid || !std::isfinite(r.mean_spot_um)) return false;
    *cost = r.mean_spot_um;
    return true;
  };
  ceres::GradientProblem problem(new DecenterMerit(merit, count));
  ceres::GradientProblemSolver::Options options;
  options.line_search_direction_type = ceres::BFGS;
  options.max_num_iterations = 100;
  options.function_tolerance = 1e-15;
  options.gradient_tolerance = 1e-13;
  options.parameter_tolerance = 1e-13;
  options.logging_type = ceres::SILENT;
  ceres::GradientProblemSolver::Summary summary;
  ceres::Solve(options, problem, moves.data(), &summary);
  for (double v : moves)
    if (!std::isfinite(v)) return start;
  TrialResult best = m.trace(perturbations, moves.data());
  if (!best.valid || !(best.mean_spot_um <= start.mean_spot_um)) return start;
  return best;
}

SpotStatistics spot_statistics(std::vector<double> values) {
  SpotStatistics s;
  s.count = static_cast<int>(values.size());
  if (values.empty()) return s;
  std::sort(values.begin(), values.end());
  // About the smallest value, so that equal values give exactly that value and std 0.
  double sum = 0.0;
  for (double v : values) sum += v - values.front();
  s.mean = values.front() + sum / s.count;
  double ss = 0.0;
  for (double v : values) ss += (v - s.mean) * (v - s.mean);
  s.std = s.count > 1 ? std::sqrt(ss / (s.count - 1)) : 0.0;
  auto quantile = [&](double q) {
    const double pos = q * (s.count - 1);
    const std::size_t i = static_cast<std::size_t>(std::floor(pos));
    if (i + 1 >= values.size()) return values.back();
    const double f = pos - static_cast<double>(i);
    return values[i] + f * (values[i + 1] - values[i]);
  };
  s.p50 = quantile(0.50);
  s.p90 = quantile(0.90);
  s.p95 = quantile(0.95);
  s.p99 = quantile(0.99);
  s.best = values.front();
  s.worst = values.back();
  return s;
}

ToleranceReport run_tolerance(const Lens& lens, const ToleranceOptions& options) {
  const ToleranceModel model(lens, options);
  ToleranceReport report;
  report.lens_name = lens.name;
  report.source_path = lens.source_path;
  report.scale = model.scale();
  report.scaled_to_spec = specs_setup(lens.specs, TraceOptions{}).scale;
  report.spec_focal_length_mm = report.scaled_to_spec ? lens.specs.focal_length_mm() : 0.0;
  report.options = options;
  report.options.progress = nullptr;
  report.options.sensitivity_progress = nullptr;
  report.threads = thread_count(options.jobs);
  report.wavelength_count = model.wavelength_count();
  report.rays_per_field_wavelength = model.rays_per_field_wavelength();
  report.fields_deg = model.fields_deg();
  report.parameters = model.parameters();
  report.compensation_names = model.compensation_names();
  const std::size_t parameter_count = report.parameters.size();
  report.nominal = model.evaluate(std::vector<double>(parameter_count, 0.0));
  if (!report.nominal.valid)
    throw Error(SourceLocation{lens.source_path},
                "the nominal lens cannot be traced at every field (no ray reaches the image)");

  // Monte-Carlo trials: trial i depends only on (seed, i); results land at index i.
  const int n = options.trials;
  report.trials.resize(n);
  std::atomic<int> done{0};
  std::mutex progress_mutex;
  const auto start = std::chrono::steady_clock::now();
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  double last_report = -1.0;
#pragma omp parallel for schedule(dynamic, 1) num_threads(report.threads)
  for (int i = 0; i < n; ++i) {
    TrialResult r = model.evaluate(model.draw(i));
    r.index = i;
    report.trials[i] = std::move(r);
    const int now_done = done.fetch_add(1) + 1;
    if (options.progress && now_done < n && progress_mutex.try_lock()) {
      const double t = elapsed();
      if (t - last_report >= 0.25) {
        last_report = t;
        options.progress(now_done, n, t);
      }
      progress_mutex.unlock();
    }
  }
  report.elapsed_s = elapsed();
  report.ms_per_trial = 1000.0 * report.elapsed_s / n;
  if (options.progress) options.progress(n, n, report.elapsed_s);

  // Summary.
  std::vector<double> spots, efl, distortion;
  int within = 0;
  for (const TrialResult& r : report.trials) {
    if (r.ray_failures > 0) ++report.trials_with_failures;
    if (r.collision) ++report.trials_with_collisions;
    if (!r.valid) {
      ++report.invalid_trials;
      continue;
    }
    spots.push_back(r.mean_spot_um);
    efl.push_back(r.efl_mm);
    distortion.push_back(r.max_abs_distortion_pct);
    // A trial whose elements intersect cannot be built: a failure, whatever its spot.
    if (options.max_spot_um && !r.collision && r.mean_spot_um <= *options.max_spot_um) ++within;
  }
  report.spot = spot_statistics(spots);
  if (options.max_spot_um) report.yield = static_cast<double>(within) / n;
  if (!efl.empty()) {
    const SpotStatistics e = spot_statistics(efl);
    report.efl_mean_mm = e.mean;
    report.efl_std_mm = e.std;
    report.efl_min_mm = e.best;
    report.efl_max_mm = e.worst;
    const SpotStatistics d = spot_statistics(distortion);
    report.distortion_mean_pct = d.mean;
    report.distortion_worst_pct = d.worst;
  }

  // Sensitivity: each parameter alone at +-limit.
  if (options.sensitivity) {
    const auto sens_start = std::chrono::steady_clock::now();
    std::vector<int> active;
    for (std::size_t p = 0; p < parameter_count; ++p)
      if (report.parameters[p].limit > 0) active.push_back(static_cast<int>(p));
    const int jobs = static_cast<int>(active.size()) * 2;
    std::vector<TrialResult> results(jobs);
    std::atomic<int> sens_done{0};
    std::mutex sens_mutex;
#pragma omp parallel for schedule(dynamic, 1) num_threads(report.threads)
    for (int j = 0; j < jobs; ++j) {
      const int p = active[j / 2];
      std::vector<double> d(parameter_count, 0.0);
      d[p] = (j % 2 == 0 ? 1.0 : -1.0) * report.parameters[p].limit;
      results[j] = model.evaluate(d);
      const int now_done = ++sens_done;
      if (options.sensitivity_progress && now_done < jobs && sens_mutex.try_lock()) {
        options.sensitivity_progress(
            now_done, jobs,
            std::chrono::duration<double>(std::chrono::steady_clock::now() - sens_start).count());
        sens_mutex.unlock();
      }
    }
    if (options.sensitivity_progress)
      options.sensitivity_progress(
          jobs, jobs,
          std::chrono::duration<double>(std::chrono::steady_clock::now() - sens_start).count());
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (std::size_t a = 0; a < active.size(); ++a) {
      SensitivityRow row;
      row.parameter = active[a];
      const TrialResult& plus = results[2 * a];
      const TrialResult& minus = results[2 * a + 1];
      row.plus_um = plus.valid ? plus.mean_spot_um - report.nominal.mean_spot_um : nan;
      row.minus_um = minus.valid ? minus.mean_spot_um - report.nominal.mean_spot_um : nan;
      row.efl_plus_mm = plus.efl_mm - report.nominal.efl_mm;
      row.efl_minus_mm = minus.efl_mm - report.nominal.efl_mm;
      // An untraceable side ranks first.
      row.score_um = (plus.valid && minus.valid)
                         ? std::max(std::abs(row.plus_um), std::abs(row.minus_um))
                         : std::numeric_limits<double>::infinity();
      report.sensitivity.push_back(row);
    }
    // Inverse sensitivity: each parameter's magnitude for the stated drop.
    if (options.inverse_drop_um) {
      std::vector<InverseSensitivity> inverse(active.size());
#pragma omp parallel for schedule(dynamic, 1) num_threads(report.threads)
      for (int a = 0; a < static_cast<int>(active.size()); ++a)
        inverse[a] = inverse_sensitivity(model, active[a], *options.inverse_drop_um,
                                         report.nominal.mean_spot_um);
      for (std::size_t a = 0; a < active.size(); ++a) {
        report.sensitivity[a].inverse_limit = inverse[a].limit;
        report.sensitivity[a].inverse_spot_um = inverse[a].spot_change_um;
      }
    }
    std::stable_sort(
        report.sensitivity.begin(), report.sensitivity.end(),
        [](const SensitivityRow& a, const SensitivityRow& b) { return a.score_um > b.score_um; });
    report.sensitivity_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - sens_start).count();
  }
  return report;
}

}  // namespace lensopt
