// The designer's targets: what a design must hold besides its merit (`[[optimize.targets]]` in
// the lens TOML, `optimize --target`, lensopt.optimize(targets=...)), in the spirit of
// OpticStudio's operands but named for people.
//
// A target is a quantity q, a relation (q = t, q <= t, q >= t), a weight w and optionally a field
// (1-based, the lens's fields as `analyze` lists them). The quantities, all measured on the lens
// as `analyze` traces it (paraxial values at the primary wavelength from paraxial/paraxial.h;
// traced ones from analysis/field_optics.h measure_fields and analysis/wavefront.h):
//   efl_mm                paraxial effective focal length (mm)
//   f_number              EFL / EPD (the image-space F-number of an object at infinity)
//   total_track_mm        first vertex to image plane, sum_k t_k (mm)
//   bfl_mm                last vertex to the paraxial focus of an object at infinity (mm)
//   distortion_percent    100 D_h, D_h = (ybar_h - y_ref,h) / y_ref,last (field_maps.h)
//   relative_illumination R_h (field_maps.h), fields where it is known
//   rms_spot_um           the field's RMS spot (spot.h)
//   rms_wavefront_waves   the field's polychromatic RMS wavefront, piston and tilt removed
//   mtf                   the field's polychromatic geometric MTF at frequency_cpmm (cycles/mm)
//                         in the tangential or sagittal direction, or their average (as
//                         OpticStudio's GMTT, GMTS and GMTA operands): the modulus of the
//                         pupil-weighted mean of exp(-2 pi i nu y_i) over the rays of the
//                         wavefront grid (analysis/wave.h's geometric MTF, x_i for sagittal),
//                         wavelengths weighted as the lens's, complex OTFs summed before the
//                         modulus. Geometric: no diffraction (it reaches 1 as the spot shrinks;
//                         analyze --wave prints it beside the diffraction MTF).
//   angular_magnification an afocal lens's paraxial angular magnification M = u'_c / u_c
//                         (paraxial/afocal.h; OpticStudio's AMAG); the targets of an afocal lens
//                         are this and total_track_mm (the others measure an image plane or a
//                         focal length, which it lacks: Error)
// Per-field quantities without a field: a bound holds at every field (distortion as |D_h|, so
// "distortion_percent <= 1" is |D| <= 1 % everywhere); an equality holds at the largest field.
// With a field: the value of that field (signed for distortion).
//
// Solved targets (exact, no residual): efl_mm and f_number are met by the parameterization
// itself, as OpticStudio's solves and CODE V's pickups are: the optimizer holds the lens's focal
// length by solving its last curvature (optimize/variables.h), so efl_mm = F scales the start
// to F (a bound: to the nearest bound when outside it) and is then held to rounding; f_number = N
// sets the aperture EPD = F / N (a pickup on the entrance pupil; the paper's spec f_number in its
// spec mode). In the as-written mode a lens without an efl_mm target gets the default target
// efl_mm = its own paraxial EFL (design_focal_length_mm), so its focal length never changes
// silently. angular_magnification = M (an afocal lens) is solved the same way: the start's last
// curvature is solved for M (a bound: the nearest bound) and the optimizer holds it there
// (optimize/variables.h); an afocal lens without one gets the default target of its own M.
// Their weights are unused.
//
// Residual targets enter Levenberg-Marquardt as a residual block of their own, one residual per
// (target, field) for a per-field bound and one otherwise:
//   r = sqrt(w lambda_T) u_q v,   v = q - t (equality), max(q - t', 0) (<=), max(t' - q, 0) (>=)
// with t' = t moved inside by the design margin m_q (1 % of |t| for the sampled quantities:
// distortion, illumination, spot, wavefront; 0 for the paraxial lengths), so a bound met at the
// optimization sampling stays met at full sampling. u_q puts each quantity in millimetres like
// the spot merit (mm): 1 for lengths, 1e-3 for um, f / 100 per percent of distortion, f per unit
// of illumination, the wavefront unit (mm per wave, analysis/wavefront.h) for waves; lambda_T
// starts at 1 and is raised tenfold per round while a target is violated (optimizer.cpp; the
// first phase, the focus alone, runs without targets).
// Derivatives are exact: forward-mode Jets through the same templated code (trace, paraxial,
// field maps), as the design loss's.
// Pass/fail (report): an equality within 1e-4 max(|t|, 1) (1e-9 relative for the solved ones),
// a bound met exactly, at full sampling.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "lensopt/analysis/field_optics.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/lens/lens.h"
#include "lensopt/optimize/design_sampling.h"
#include "lensopt/optimize/variables.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/system.h"

namespace lensopt {

enum class TargetQuantity {
  kEflMm,
  kFNumber,
  kTotalTrackMm,
  kBflMm,
  kDistortionPercent,
  kRelativeIllumination,
  kRmsSpotUm,
  kRmsWavefrontWaves,
  kMtf,
  kAngularMagnification,
};
// The direction of an MTF target (OpticStudio's GMTT, GMTS, GMTA).
enum class MtfOrientation { kTangential, kSagittal, kAverage };
enum class TargetRelation { kEqual, kAtMost, kAtLeast };

struct DesignTarget {
  TargetQuantity quantity = TargetQuantity::kEflMm;
  TargetRelation relation = TargetRelation::kEqual;
  double value = 0.0;
  double weight = 1.0;
  int field = 0;                // 1-based field; 0: every field (bounds) / the largest (equality)
  double frequency_cpmm = 0.0;  // mtf: the spatial frequency (cycles/mm, > 0); else 0
  MtfOrientation orientation = MtfOrientation::kAverage;  // mtf only
  bool is_default = false;  // the as-written lens's own focal length (no target given)
  std::string where;        // where it was given ("--target", "lens.toml:12:1")
};

// "efl_mm", "f_number", ... (the names of the header).
const char* target_quantity_name(TargetQuantity q);
// Every name, comma-separated, for messages.
const char* target_quantity_names();
// "tangential", "sagittal", "average".
const char* mtf_orientation_name(MtfOrientation o);
// Parses an orientation (also t, s, a); throws Error at `where`.
MtfOrientation parse_mtf_orientation(const std::string& name, const SourceLocation& where);
// The same target of another source replaces this one (quantity, field, and for mtf its
// frequency and orientation).
bool same_target(const DesignTarget& a, const DesignTarget& b);
// Parses a quantity name; throws Error at `where` naming the known ones.
TargetQuantity parse_target_quantity(const std::string& name, const SourceLocation& where);
// The target as the designer writes it: "efl_mm = 100", "distortion_percent[2] <= 1 (weight 3)".
std::string target_text(const DesignTarget& target);
// Parses "NAME=V", "NAME<=V", "NAME>=V" (spaces allowed), optionally followed by
// ",weight=W", ",field=N", and for mtf ",freq=NU" (cycles/mm) and ",orientation=tangential|
// sagittal|average" (`optimize --target`); throws Error at `where` for bad text.
// `validate` false: the caller completes the target (a TOML entry's frequency) and validates it.
DesignTarget parse_target(const std::string& text, const SourceLocation& where,
                          bool validate = true);
// Checks a target (finite value, weight > 0, field >= 0, no field on a whole-lens quantity);
// throws Error at `where`.
void validate_target(const DesignTarget& target, const SourceLocation& where);

inline bool target_is_solved(TargetQuantity q) {
  return q == TargetQuantity::kEflMm || q == TargetQuantity::kFNumber ||
         q == TargetQuantity::kAngularMagnification;
}
inline bool target_per_field(TargetQuantity q) {
  return q == TargetQuantity::kDistortionPercent || q == TargetQuantity::kRelativeIllumination ||
         q == TargetQuantity::kRmsSpotUm || q == TargetQuantity::kRmsWavefrontWaves ||
         q == TargetQuantity::kMtf;
}
// The design margin m_q of a bound (header).
inline double target_margin(const DesignTarget& t) {
  const bool sampled = target_per_field(t.quantity);
  return sampled && t.relation != TargetRelation::kEqual ? 0.01 * std::abs(t.value) : 0.0;
}
// The pass tolerance of an equality (header).
inline double target_tolerance(const DesignTarget& t) {
  return target_is_solved(t.quantity) ? 1e-9 * std::max(std::abs(t.value), 1.0)
                                      : 1e-4 * std::max(std::abs(t.value), 1.0);
}

// The targets a lens is optimized with: `given` (the [optimize] table's and the caller's), and in
// the as-written mode the default efl_mm = the lens's own EFL when none is given.
std::vector<DesignTarget> targets_with_defaults(const Lens& lens,
                                                const std::vector<DesignTarget>& given);

// The start the optimizer works from: `lens` with its solved targets applied (efl_mm scales the
// prescription, f_number sets the aperture; header). Throws Error (naming the target) when a
// solve is impossible (a lens without power, a field of a lens with fewer fields).
Lens apply_target_solves(const Lens& lens, const std::vector<DesignTarget>& targets);

// Checks the per-field targets against the lens's fields (field <= count; a lens without
// written fields has no field to name). Throws Error naming the target.
void check_target_fields(const Lens& lens, const std::vector<DesignTarget>& targets);

// The values of the targets on a traced system, T = double or Jets.
template <typename T>
struct TargetValues {
  std::vector<T> value;  // per target: the reported value (the worst field for a field bound)
  // Per target: the per-field values a bound on every field constrains (else one value).
  std::vector<std::vector<T>> items;
  std::vector<std::vector<char>> item_known;  // 0: no value at that field (illumination unknown)
};

// The wavefront sampling of the rms_wavefront_waves targets: the merit's polar quadrature
// (design_loss.h) in the optimizer, the 32 x 32 grid of the reports.
struct TargetSampling {
  PupilGrid wavefront_grid;
  int threads = 0;
};

namespace detail {

template <typename T>
T target_abs(const T& v) {
  return v < K<T>(0.0) ? -v : v;
}

}  // namespace detail

// Measures `targets` on `sys` (its lens as traced: scaled, fields, aperture). Traces only what the
// targets need (measure_fields with its maps for distortion and illumination, the spot alone
// for rms_spot_um, the wavefront per field for rms_wavefront_waves).
template <typename T>
TargetValues<T> measure_targets(const TraceSystem<T>& sys, const std::vector<DesignTarget>& targets,
                                const TargetSampling& sampling) {
  TargetValues<T> out;
  bool need_maps = false, need_spot = false, need_wave = false;
  for (const DesignTarget& t : targets) {
    need_maps = need_maps || t.quantity == TargetQuantity::kDistortionPercent ||
                t.quantity == TargetQuantity::kRelativeIllumination;
    need_spot = need_spot || t.quantity == TargetQuantity::kRmsSpotUm;
    need_wave = need_wave || t.quantity == TargetQuantity::kRmsWavefrontWaves ||
                t.quantity == TargetQuantity::kMtf;
  }
  FieldOptics<T> fields;
  if (need_maps || need_spot) {
    FieldOpticsOptions fo;
    fo.maps = need_maps;
    fo.threads = sampling.threads;
    fields = measure_fields(sys, fo);
  }
  const int field_count = static_cast<int>(sys.fields_deg.size());
  std::vector<T> wave;
  // Per target (mtf ones) and field: the geometric MTF (header).
  std::vector<std::vector<T>> mtf(targets.size());
  std::vector<std::vector<char>> mtf_known(targets.size());
  if (need_wave) {
    using std::cos;
    using std::sin;
    using std::sqrt;
    RayBundle<T> rays;
    RayRecord<T> record;
    const PupilGrid& grid = sampling.wavefront_grid;
    double omega_sum = 0.0;
    for (int w = 0; w < sys.wavelength_count; ++w)
      omega_sum += sys.wavelength_weights.empty() ? 1.0 : sys.wavelength_weights[w];
    for (int h = 0; h < field_count; ++h) {
      // The polychromatic OTFs (real, imaginary) per mtf target: tangential and sagittal.
      std::vector<T> t_re(targets.size(), K<T>(0.0)), t_im = t_re, s_re = t_re, s_im = t_re;
      bool arrived = true;
      wave.push_back(field_rms_wavefront(
          sys, h, grid, sys.wavelength_weights, rays, record, [&](int w, const Wavefront<T>& wf) {
            const double omega =
                (sys.wavelength_weights.empty() ? 1.0 : sys.wavelength_weights[w]) / omega_sum;
            double a_sum = 0.0;
            for (std::size_t i = 0; i < grid.size(); ++i)
              if (wf.ok[i]) a_sum += grid.weight[i];
            arrived = arrived && a_sum > 0.0;
            if (!(a_sum > 0.0)) return;
            for (std::size_t j = 0; j < targets.size(); ++j) {
              if (targets[j].quantity != TargetQuantity::kMtf) continue;
              const double k = 2.0 * kPi * targets[j].frequency_cpmm;
              for (std::size_t i = 0; i < grid.size(); ++i) {
                if (!wf.ok[i]) continue;
                const double a = omega * grid.weight[i] / a_sum;
                const T py = K<T>(k) * wf.image_y_mm[i], px = K<T>(k) * wf.image_x_mm[i];
                t_re[j] = t_re[j] + K<T>(a) * cos(py);
                t_im[j] = t_im[j] - K<T>(a) * sin(py);
                // A mirrored half grid: each sample stands for (x, y) and (-x, y), whose
                // sagittal phases cancel in the imaginary part.
                s_re[j] = s_re[j] + K<T>(a) * cos(px);
                if (!grid.mirrored) s_im[j] = s_im[j] - K<T>(a) * sin(px);
              }
            }
          }));
      for (std::size_t j = 0; j < targets.size(); ++j) {
        if (targets[j].quantity != TargetQuantity::kMtf) continue;
        auto modulus = [](const T& re, const T& im) {
          const T m2 = re * re + im * im;
          return m2 > K<T>(0.0) ? sqrt(m2) : K<T>(0.0);
        };
        const T mt = modulus(t_re[j], t_im[j]), ms = modulus(s_re[j], s_im[j]);
        const MtfOrientation o = targets[j].orientation;
        mtf[j].push_back(o == MtfOrientation::kTangential ? mt
                         : o == MtfOrientation::kSagittal ? ms
                                                          : K<T>(0.5) * (mt + ms));
        mtf_known[j].push_back(arrived);
      }
    }
  }
  const ParaxialData<T> par = paraxial_data(sys.lens, sys.lens.reference_nm());
  for (std::size_t index = 0; index < targets.size(); ++index) {
    const DesignTarget& t = targets[index];
    std::vector<T> per_field;
    std::vector<char> known;
    T whole = K<T>(0.0);
    switch (t.quantity) {
      case TargetQuantity::kEflMm:
        whole = par.efl_mm;
        break;
      case TargetQuantity::kFNumber:
        whole = par.efl_mm / sys.epd_mm;
        break;
      case TargetQuantity::kTotalTrackMm:
        for (int k = 0; k < sys.lens.surface_count(); ++k) whole = whole + sys.lens.thickness_mm[k];
        break;
      case TargetQuantity::kBflMm:
        whole = par.bfl_mm;
        break;
      case TargetQuantity::kDistortionPercent:
        for (int h = 0; h < field_count; ++h) {
          per_field.push_back(K<T>(100.0) * fields.distortion[h]);
          known.push_back(fields.spots.traced_rays[h] > 0);
        }
        break;
      case TargetQuantity::kRelativeIllumination:
        per_field = fields.relative_illumination;
        known = fields.relative_illumination_known;
        break;
      case TargetQuantity::kRmsSpotUm:
        for (int h = 0; h < field_count; ++h) {
          per_field.push_back(K<T>(1000.0) * fields.spots.rms_spot_mm[h]);
          known.push_back(fields.spots.traced_rays[h] > 0);
        }
        break;
      case TargetQuantity::kRmsWavefrontWaves:
        per_field = wave;
        known.assign(wave.size(), 1);
        break;
      case TargetQuantity::kMtf:
        per_field = mtf[index];
        known = mtf_known[index];
        break;
      case TargetQuantity::kAngularMagnification:
        whole = paraxial_angular_magnification(sys.lens, sys.lens.reference_nm());
        break;
    }
    if (!target_per_field(t.quantity)) {
      out.value.push_back(whole);
      out.items.push_back({whole});
      out.item_known.push_back({1});
      continue;
    }
    // One field (named, or the largest for an equality), or every field for a bound.
    const bool every = t.field == 0 && t.relation != TargetRelation::kEqual;
    const bool distortion_bound =
        t.quantity == TargetQuantity::kDistortionPercent && t.relation != TargetRelation::kEqual;
    if (!every) {
      const int h = t.field > 0 ? std::min(t.field, field_count) - 1 : field_count - 1;
      T v = h >= 0 ? per_field[h] : K<T>(0.0);
      if (distortion_bound) v = detail::target_abs(v);
      out.value.push_back(v);
      out.items.push_back({v});
      out.item_known.push_back({static_cast<char>(h >= 0 && known[h])});
      continue;
    }
    if (distortion_bound)
      for (T& v : per_field) v = detail::target_abs(v);
    // The reported value: the worst known field against the bound.
    int worst = -1;
    for (int h = 0; h < field_count; ++h) {
      if (!known[h]) continue;
      const bool worse = worst < 0 || (t.relation == TargetRelation::kAtMost
                                           ? value_of(per_field[h]) > value_of(per_field[worst])
                                           : value_of(per_field[h]) < value_of(per_field[worst]));
      if (worse) worst = h;
    }
    out.value.push_back(worst >= 0 ? per_field[worst] : K<T>(0.0));
    out.items.push_back(per_field);
    out.item_known.push_back(known);
  }
  return out;
}

// Residuals per target in the optimizer (header): solved targets none; a per-field bound on
// every field one per field of `field_count`; else one.
inline int target_residual_count(const DesignTarget& t, int field_count) {
  if (target_is_solved(t.quantity)) return 0;
  if (target_per_field(t.quantity) && t.field == 0 && t.relation != TargetRelation::kEqual)
    return field_count;
  return 1;
}
int target_residual_count(const std::vector<DesignTarget>& targets, int field_count);

// u_q of the header: the quantity's unit in millimetres of the merit. `focal_length_mm` the held
// focal length, `wave_unit_mm` mm per wave.
double target_unit_mm(TargetQuantity q, double focal_length_mm, double wave_unit_mm);
// The same for a target (mtf: 1 / frequency_cpmm, the length of one cycle).
double target_unit_mm(const DesignTarget& t, double focal_length_mm, double wave_unit_mm);

// The violation v of the header (with the margin when `with_margin`), double or Jet.
template <typename T>
T target_violation(const DesignTarget& t, const T& q, bool with_margin) {
  const double m = with_margin ? target_margin(t) : 0.0;
  switch (t.relation) {
    case TargetRelation::kEqual:
      return q - K<T>(t.value);
    case TargetRelation::kAtMost:
      return q > K<T>(t.value - m) ? q - K<T>(t.value - m) : K<T>(0.0);
    case TargetRelation::kAtLeast:
      return q < K<T>(t.value + m) ? K<T>(t.value + m) - q : K<T>(0.0);
  }
  return K<T>(0.0);
}

// The system the optimizer measures targets on: the lens of variables x (its spec focal length,
// the forward map's scale) at the lens's fields (the written fields as written; `sampling.fields`
// fields 0..hfov in the paper's mode), aperture and object, no scaling.
template <typename T>
TraceSystem<T> target_system(const LensParameterization& param, const TraceLens<T>& lens,
                             const TraceOptions& sampling) {
  TraceOptions topt = sampling;
  topt.scale_to_spec = false;
  const Lens& structure = param.structure();
  SystemSetup setup = structure.specs.mode == SpecMode::kPaper ? specs_setup(structure.specs, topt)
                                                               : lens_setup(structure, topt);
  setup.scale = false;
  return prepare_system(lens, setup, topt);
}

// The least-squares residuals of the residual targets at variables x (header), in target order,
// target_residual_count of them; `lambda` multiplies every weight. Returns false when a value is
// not finite. T = double or a Jet (the optimizer's residual block).
template <typename T>
bool evaluate_targets(const LensParameterization& param, const T* x, GlassMode mode,
                      const std::vector<int>& fixed_glasses, const TraceOptions& sampling,
                      const std::vector<DesignTarget>& targets,
                      const TargetSampling& target_sampling, double lambda, double wave_unit_mm,
                      T* residuals, TargetValues<T>* values = nullptr) {
  using std::sqrt;
  const TraceLens<T> lens = param.to_trace_lens(x, mode, fixed_glasses);
  const TraceSystem<T> sys = target_system(param, lens, sampling);
  const TargetValues<T> v = measure_targets(sys, targets, target_sampling);
  const int field_count = static_cast<int>(sys.fields_deg.size());
  int row = 0;
  bool finite = true;
  for (std::size_t i = 0; i < targets.size(); ++i) {
    const DesignTarget& t = targets[i];
    const int count = target_residual_count(t, field_count);
    if (count == 0) continue;
    const double scale =
        std::sqrt(t.weight * lambda) * target_unit_mm(t, param.focal_length_mm(), wave_unit_mm);
    for (int j = 0; j < count; ++j) {
      const bool known = v.item_known[i][j] != 0;
      const T r = known ? K<T>(scale) * target_violation(t, v.items[i][j], true) : K<T>(0.0);
      finite = finite && std::isfinite(value_of(r));
      if (residuals) residuals[row] = r;
      ++row;
    }
  }
  if (values) *values = v;
  return finite;
}

// One row of the target report.
struct TargetRow {
  DesignTarget target;
  double value = 0.0;  // NaN: not measurable (no ray reached the field)
  bool pass = false;
};
struct TargetReport {
  std::vector<TargetRow> rows;
  bool all_pass() const;
};

// The targets measured on `lens` as `analyze` traces it (prepare_lens_system with `sampling`).
// A lens that cannot be traced gives NaN values that fail.
TargetReport check_targets(const Lens& lens, const std::vector<DesignTarget>& targets,
                           const TraceOptions& sampling);

// Whether a measured value passes (header).
bool target_passes(const DesignTarget& target, double value);

// measure_targets on double is compiled once, in src/optimize/design_double.cpp.
extern template TargetValues<double> measure_targets<double>(const TraceSystem<double>&,
                                                             const std::vector<DesignTarget>&,
                                                             const TargetSampling&);

}  // namespace lensopt
