// Monte-Carlo tolerancing (SPEC "Tolerancing", supplement "Tolerancing Analysis").
//
// The nominal lens is scaled once to the spec focal length (as `analyze` does); tolerances apply
// to that scaled lens, the lens as it would be made. Every trial draws one perturbation per
// toleranced parameter and traces the perturbed lens as it is, never rescaled to the spec (that
// would hide the focal-length error). For parameter p with tolerance limit L_p and a unit draw
// u in [-1, 1]:
//   curvature   c' = c (1 + L u)     L = curvature_pct / 100   (relative; flat surfaces stay flat)
//   thickness   t' = t + L u         L = glass_thickness_mm, or air_thickness_mm for airspaces
//   index       nd' = nd + L u       L = nd
//   Abbe number vd' = vd (1 + L u)   L = vd_pct / 100          (relative)
//   element     decenter dx' = dx + L u (L = decenter_mm) in x and in y, and tilt about x and
//   placement   about y by L u (L = tilt_arcmin / 60 deg), of each element (a run of glasses, a
//               cemented group moves as one) as a whole: every surface of it is decentred by the
//               same amount, or, for a tilt theta about x through its first vertex, surface j
//               (vertex z_j behind the first) is tilted by theta and decentred by -z_j sin(theta)
//               in y (about y: +z_j sin(theta) in x), each with restore_frame (trace/kernel.h);
//               the axial shift z_j (1 - cos theta) ~ z_j theta^2 / 2 (4e-8 z_j at 1 arcmin) is
//               left out. A lens with mirrors or placements of its own gets no such parameters.
//               With a nonzero decenter or tilt tolerance every trial, the nominal too, is
//               traced on the full pupil (no mirror symmetry).
//   surface     decenter in x and in y (TSDX, TSDY; L = surface_decenter_mm) and tilt about x
//   placement   and about y (TSTX, TSTY; L = surface_tilt_arcmin) of one surface alone, about its
//               vertex, the surfaces after it staying where they are (restore_frame): a tilted
//               surface of an element is its wedge, a tilted mirror turns the beam by twice the
//               tilt. Every surface that carries no placement of its own (not the stop, not a
//               coordinate break, not a flat surface's decenter, which moves nothing) gets them;
//               defaults: tilt 1 arcmin (on: each surface's wedge, a fabrication error
//               of the element that its mounting, the element tilt above, does not hold),
//               decenter 0 (off: a sphere decentred by d is the sphere tilted by d / R about
//               its vertex, the same wedge again; turn it on for aspheres, whose decenter is an
//               error of its own). docs/tolerance.md gives the reasons.
//   profile     of every non-spherical surface (conic or even asphere, lens/lens.h), each term on
//               its own, as a sag error at the surface's clear semi-aperture h (below):
//                 k' = k + L_k u,   L_k = L / |dS/dk(h)|,  dS/dk = c^3 h^4 / (2 q (1 + q)^2),
//                 q = sqrt(1 - (1 + k) c^2 h^2)   (not for a flat surface, c = 0: no effect),
//                 a'_2i = a_2i + L_i u,  L_i = L / h^(2i)   (only the nonzero terms a2..a16),
//               L = asphere_sag_um / 1000 mm (default 1 um: a polished or molded asphere's form
//               error), so each term alone moves the rim sag by up to +-L (k to first order).
// Draws: uniform u ~ U[-1, 1) (default, as in the paper), or normal u ~ N(0, 1/2^2) truncated to
// [-1, 1], i.e. the tolerance is the 2-sigma limit. Each trial's generator is std::mt19937_64
// seeded with splitmix64(seed ^ splitmix64(trial index)), and the unit draws are computed from
// its raw 64-bit output (53-bit uniforms, Box-Muller), so a trial is reproducible whatever the
// thread count or the standard library.
//
// Not perturbed: the stop (flat, no curvature), the airspace that ends at the stop (the stop is
// mounted with the group before it; an airspace split by the stop is perturbed on its part after
// the stop), and the last thickness t_{K-1}, which is the focus compensator:
//   paraxial  t_{K-1} = BFL' + (t0_{K-1} - BFL0): the perturbed paraxial focus plus the nominal's
//             defocus (BFL at 587.6 nm);
//   best-rms  t_{K-1} minimizes the mean RMS spot. With the rays traced once to a reference
//             plane at tau = 0 (the paraxial solution), a ray reaches the plane at tau as
//             y + tau m/n, x + tau l/n, so each field's S_h^2(tau) = A_h + 2 B_h tau + C_h tau^2
//             is an exact quadratic and mean_h S_h(tau) is convex; a golden-section search
//             (bracket grown from +-2 % of the image distance, to 1e-9 relative) finds tau;
//   none      t_{K-1} = t0_{K-1}.
// Compensators beyond focus (ToleranceOptions::image_shift, decenter_compensators; OpticStudio's
// compensators, CODE V's), solved per trial after the focus above, each a small least squares:
//   image shift  the image plane moves laterally by s = (s_x, s_y) (mm, image frame), the
//               detector re-registered on the image. It matters only for a merit that is
//               measured on the detector, spot_reference = nominal: each field's RMS radius is
//               then taken about q_h + s, q_h the nominal lens's polychromatic centroid of
//               field h on its own (compensated) image plane (the point the detector expects
//               the image of that field at), so with c_h the trial's centroid
//                 S_h^2 = RMS_h^2 + |c_h - q_h - s|^2
//               (RMS_h about c_h, as in the default spot_reference = centroid). The default
//               reference takes every field about its own centroid: a displaced image costs
//               nothing there, field by field, and one common shift changes nothing (the image
//               shift is refused with it). With the nominal reference a shift removes the part
//               of the image displacement that all fields share (boresight: a decentred element
//               moves the whole image), not the part that differs between fields (a change of
//               distortion, keystone), which stays in the merit. With the best-rms focus, tau
//               and s are solved together. S_h^2 is a convex quadratic in (tau, s_x, s_y) (the
//               through-focus moments, a centroid linear in tau), so the mean of the S_h is
//               convex; Ceres' Levenberg-Marquardt solves residuals r_h = sqrt(phi_h S_h /
//               sum phi) (sum r_h^2 = the mean RMS itself) from the closed-form shift
//               s_0 = sum_h phi_h (c_h - q_h) / sum_h phi_h, never ending above it.
//   decenter     a chosen group of glasses (rows tedx<k>/tedy<k>: `decenter:element=k`)
//               decentred by (d_x, d_y) (mm) on top of its perturbation, as OpticStudio's TEDX
//               and TEDY used as compensators: the mean RMS spot minimized over the decenters
//               by Ceres' line-search BFGS from (0, 0), the gradient by central differences
//               (1e-6 mm) of full traces of the adjusted trial (ray aiming, and the focus and
//               image shift solved inside); a trial ends no worse than uncompensated, so the
//               compensated yield is never below the uncompensated one. (Least squares over the
//               fields, r_h above, is a large-residual problem: Levenberg-Marquardt stalled.)
//               The compensated merit of a pure decenter of group k is the compensated merit
//               of the nominal; with fields on +y only a y decenter is not symmetric (the
//               merit's slope at the nominal is not 0), so that can lie below the nominal's.
// The trial's compensator moves are in TrialResult::compensation, the CSV and the JSON.
// The aperture stop keeps its nominal physical radius: a trial's entrance pupil radius is
// y_stop0 / A' with A' the perturbed paraxial stop magnification (y_stop = A y_0), so a front
// group error changes the pupil as it would on the bench. Ray aiming is redone per trial.
//
// Figures per trial: RMS spot per field and their mean (um), EFL (587.6 nm), the largest
// |distortion| over the fields (%, as analyze: (centroid - paraxial chief height) / paraxial
// height at the last field), ray failures (half-pupil rays, all fields and wavelengths).
// The nominal is evaluated by the same code with every perturbation zero, so a trial with zero
// tolerances equals it exactly.
// Sensitivity: each parameter alone at +L and -L (compensated), the change in mean spot; rows are
// ranked by max(|d+|, |d-|), the first row is what to tighten first.
// Inverse sensitivity (ToleranceOptions::inverse_drop_um, OpticStudio's inverse limit): for each
// parameter the magnitude m at which it alone, at the worse of +m and -m, raises the mean RMS spot
// by the stated drop D: g(m) = max(S(+m), S(-m)) - S_0 = D, bracketed from the limit (doubling or
// halving) and solved by regula falsi (Illinois) to |g - D| <= 1e-4 D (inverse_sensitivity()).
// Statistics: sample mean and standard deviation (n - 1), percentiles by linear interpolation
// between order statistics (p = (n - 1) q), worst = largest mean spot; the yield is the fraction
// of all trials whose mean spot is <= max_spot_um (an untraceable trial counts as a failure, and
// so does a trial whose elements intersect).
// Collisions: each space between two surfaces is checked at the height where it would close
// first (a glass at its element's rim, the larger clear semi-aperture of its two surfaces; an
// air space at the smaller), the edge gap t_k + sag_{k+1}(h) - sag_k(h) (the profiles' sags) and
// the centre thickness t_k; a trial with one below 0 has intersecting elements. Clear
// semi-apertures are the lens's semi-diameters, or the paraxial |y_marginal| + |y_chief| at the
// largest field. Spaces whose nominal gap is already below 0 are not checked.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"

namespace lensopt {

enum class ToleranceDistribution { kUniform, kNormal };
enum class FocusCompensator { kParaxial, kBestRms, kNone };
// What each field's RMS spot is taken about (header, "Compensators beyond focus"): its own
// centroid (default), or the nominal lens's image point of the field (boresight, distortion).
enum class SpotReference { kCentroid, kNominal };

// "uniform" / "normal"; "paraxial" / "best-rms" / "none". parse_* throw Error naming the value.
std::string to_string(ToleranceDistribution distribution);
std::string to_string(FocusCompensator compensator);
ToleranceDistribution parse_tolerance_distribution(const std::string& text);
FocusCompensator parse_focus_compensator(const std::string& text);
std::string to_string(SpotReference reference);  // "centroid" / "nominal"
SpotReference parse_spot_reference(const std::string& text);

// A list of compensators, as `--compensator` and the [tolerance] table's `compensator` give it:
// comma-separated items (or a TOML array of them), each a focus compensator (paraxial,
// best-rms, none; at most one), `image-shift`, or `decenter:element=K` (K >= 1, the group of
// glasses of rows tedx<K>/tedy<K>; each K once). parse_compensators throws Error naming the item.
struct CompensatorList {
  std::optional<FocusCompensator> focus;  // unset: the focus compensator stays as it was
  bool image_shift = false;
  std::vector<int> decenter_elements;  // 1-based group numbers, in the order given
};
CompensatorList parse_compensators(const std::string& text);

// The manufacturing tolerances (+- limits). Defaults: the paper's (Optimax / Schott standard).
struct Tolerances {
  double curvature_pct = 0.2;        // relative curvature, percent
  double glass_thickness_mm = 0.05;  // centre thickness of glass
  double air_thickness_mm = 0.0;     // airspaces: off by default
  double nd = 5e-4;                  // d-line index, absolute
  double vd_pct = 0.5;               // Abbe number, percent
  double asphere_sag_um = 1.0;       // conic and asphere terms: sag at the clear aperture, um
  double decenter_mm = 0.02;         // element decenter in x and in y (TEDX, TEDY), mm
  double tilt_arcmin = 1.0;          // element tilt about x and about y (TETX, TETY), arcmin
  double surface_decenter_mm = 0.0;  // surface decenter in x and y (TSDX, TSDY), mm; 0: off
  double surface_tilt_arcmin = 1.0;  // surface tilt (wedge) about x and y (TSTX, TSTY); 0: off

  // Throws Error naming the first negative or non-finite tolerance.
  void validate() const;
  // Every tolerance multiplied by `factor`.
  Tolerances times(double factor) const;
  static Tolerances zero() { return {0, 0, 0, 0, 0, 0, 0, 0, 0, 0}; }
};

// The tolerance names as used by the [tolerance] table and the command line (--curvature-pct,
// ..., --asphere-sag-um).
const std::vector<std::string>& tolerance_names();

// What a [tolerance] table in a lens TOML may set; unset entries are nullopt.
//   [tolerance]
//   curvature_pct = 0.2, glass_thickness_mm = 0.05, air_thickness_mm = 0.0, nd = 5e-4,
//   vd_pct = 0.5, asphere_sag_um = 1.0, decenter_mm = 0.02, tilt_arcmin = 1,
//   surface_decenter_mm = 0, surface_tilt_arcmin = 1, inverse_drop_um = 1,
//   distribution = "uniform", compensator = "paraxial" (or a list: "best-rms, image-shift",
//   ["paraxial", "decenter:element=2"]; parse_compensators), spot_reference = "centroid",
//   max_spot_um = 20, trials = 10000, seed = 1
struct ToleranceSettings {
  std::optional<double> curvature_pct, glass_thickness_mm, air_thickness_mm, nd, vd_pct,
      asphere_sag_um, decenter_mm, tilt_arcmin, surface_decenter_mm, surface_tilt_arcmin;
  std::optional<double> inverse_drop_um;
  std::optional<ToleranceDistribution> distribution;
  std::optional<FocusCompensator> compensator;  // the focus compensator the list names
  std::optional<CompensatorList> compensators;  // the whole `compensator` list
  std::optional<SpotReference> spot_reference;
  std::optional<double> max_spot_um;
  std::optional<int> trials;
  std::optional<std::uint64_t> seed;

  // Overwrites the tolerances that are set here.
  void apply_to(Tolerances& tolerances) const;
};

// Parses the [tolerance] table of a TOML document (other tables are ignored; no table: all
// unset). An unknown key, a negative tolerance or a wrong type throws Error with
// source_name:line:column naming the key.
ToleranceSettings parse_tolerance_table(std::string_view toml_text, const std::string& source_name);

// The [tolerance] table of a lens: read from its TOML source file when that is readable (exact
// file:line), else from Lens::extra_toml.
ToleranceSettings tolerance_settings_of(const Lens& lens);

struct ToleranceOptions {
  Tolerances tolerances;
  ToleranceDistribution distribution = ToleranceDistribution::kUniform;
  FocusCompensator compensator = FocusCompensator::kParaxial;
  // Compensators beyond focus (header): the lateral image shift, and the decenter of these
  // groups of glasses (1-based, rows tedx<k>); the spot's reference.
  bool image_shift = false;
  std::vector<int> decenter_compensators;
  SpotReference spot_reference = SpotReference::kCentroid;
  int trials = 10000;
  std::uint64_t seed = 1;
  int jobs = 0;  // threads over trials (0: all cores); each trial runs single-threaded
  // The default tolerancing sampling: 16 rings (256 half-pupil rays) x 11 fields (every other
  // one of the paper's 21), 15 wavelengths, ray aiming on. The paper's full sampling is 32 x 21.
  int rings = 16;
  int fields = 11;
  bool ray_aiming = true;
  bool sensitivity = true;
  std::optional<double> max_spot_um;
  // Inverse sensitivity: the magnitude of each parameter that alone raises the mean RMS spot by
  // this much (um), in the sensitivity table; unset: not computed.
  std::optional<double> inverse_drop_um;
  // Called now and then from worker threads (serialized): trials done, total, seconds elapsed.
  std::function<void(int done, int total, double elapsed_s)> progress;
  // The same for the sensitivity table (two evaluations per toleranced parameter), which takes
  // minutes on a lens of hundreds of surfaces.
  std::function<void(int done, int total, double elapsed_s)> sensitivity_progress;

  // Sets the compensators a list names (the focus only when it names one).
  void apply(const CompensatorList& list);
  // "paraxial focus", "best-rms focus, image shift, decenter of group 2", ...
  std::string compensators_text() const;

  // Throws Error for out-of-range values (names the option).
  void validate() const;
};

// The options of tolerancing `lens` before the caller's own: ToleranceOptions' defaults with the
// lens's [tolerance] table applied (tolerances, distribution, compensator, max_spot_um, trials,
// seed; tolerance_settings_of). `lensopt tolerance` and lensopt.tolerance (Python) both start
// from it and set only what their arguments give, so the two cannot differ.
ToleranceOptions tolerance_options_for(const Lens& lens);

// One toleranced number of the lens.
struct ToleranceParameter {
  enum class Kind {
    kCurvature,
    kThickness,
    kNd,
    kVd,
    kConic,
    kAsphere,
    kDecenterX,  // element decenter (TEDX): surface .. last_surface moved by d along x, mm
    kDecenterY,
    kTiltX,  // element tilt (TETX) about its first vertex, radians (limit from tilt_arcmin)
    kTiltY,
    kSurfaceDecenterX,  // surface decenter (TSDX): surface `surface` alone, mm
    kSurfaceDecenterY,
    kSurfaceTiltX,  // surface tilt (TSTX) about its vertex, arcmin: an element's wedge
    kSurfaceTiltY,
  };
  Kind kind = Kind::kCurvature;
  int last_surface = 0;     // kDecenter*, kTilt*: the element's last surface (0-based)
  int surface = 0;          // 0-based surface index (kNd/kVd: the surface the glass follows)
  int term = 0;             // kAsphere: 0 = a2, 1 = a4, ..., 7 = a16
  bool air = false;         // kThickness: an airspace
  double limit = 0;         // +- limit, native units: relative (curvature, vd), mm, index,
                            // conic constant, or mm^(1-2i) (asphere term a_2i)
  std::string name;         // "c1", "t1", "nd1", "vd1", "k1", "a4_1" (1-based surface numbers)
  std::string column;       // CSV column of the drawn perturbation: "dc1_rel", "dt1_mm", "dk1",
                            // "da4_1", ...
  std::string description;  // "surface 1 radius", "element 1 (glass S-LAH64) thickness", ...
  std::string limit_text;   // "0.2 %", "0.05 mm", "0.0005", "1 um sag at h 12.3 mm"
};

// Every parameter of a lens (with zero limits where the tolerance is zero), in a fixed order:
// curvatures, thicknesses, nd, vd, then the profile terms (k, a2..a16 of each non-spherical
// surface), each by surface. The profile limits need the clear semi-apertures (as for the
// collision check).
std::vector<ToleranceParameter> tolerance_parameters(const Lens& lens,
                                                     const Tolerances& tolerances);

struct TrialResult {
  int index = -1;     // -1: the nominal
  bool valid = true;  // false if a field had no traced ray or a number was not finite
  double mean_spot_um = 0;
  std::vector<double> rms_spot_um;  // per field
  double efl_mm = 0;
  double max_abs_distortion_pct = 0;
  int ray_failures = 0;
  double image_distance_mm = 0;       // the compensated last thickness
  bool collision = false;             // elements intersect: a checked edge gap below 0
  double min_edge_gap_mm = 0;         // smallest checked edge gap or centre thickness
  std::vector<double> perturbations;  // per parameter, native units
  // The compensators' moves beyond focus (ToleranceReport::compensation_names): the image
  // shift (x, y, mm) and each decentred group's (x, y, mm); empty without such compensators.
  std::vector<double> compensation;
  // Per field, the polychromatic centroid in the image frame (mm) on the compensated image
  // plane (before any image shift), as the nominal image points q_h are taken.
  std::vector<double> centroid_x_mm, centroid_y_mm;
};

struct SpotStatistics {
  int count = 0;  // valid trials
  double mean = 0, std = 0, p50 = 0, p90 = 0, p95 = 0, p99 = 0, worst = 0, best = 0;
};

struct SensitivityRow {
  int parameter = 0;                         // index into ToleranceReport::parameters
  double plus_um = 0;                        // mean spot change at +limit
  double minus_um = 0;                       // at -limit
  double efl_plus_mm = 0, efl_minus_mm = 0;  // EFL change
  double score_um = 0;                       // max(|plus|, |minus|), the ranking key
  // Inverse sensitivity (ToleranceOptions::inverse_drop_um): the magnitude, native units, that
  // raises the mean spot by the drop (none: not asked, or no magnitude reaches it), and the
  // spot change there.
  std::optional<double> inverse_limit;
  double inverse_spot_um = 0;
};

struct ToleranceReport {
  std::string lens_name;
  std::string source_path;
  double scale = 1;  // applied to the prescription to reach the spec focal length
  // Whether the prescription is scaled to the spec focal length d / (2 tan hfov) (the paper's
  // spec mode); a lens traced as written keeps scale 1 and has no spec focal length (on axis
  // only it would be infinite).
  bool scaled_to_spec = true;
  double spec_focal_length_mm = 0;  // when scaled_to_spec
  ToleranceOptions options;         // as run (progress callback dropped)
  int threads = 1;
  int wavelength_count = 0;
  int rays_per_field_wavelength = 0;
  std::vector<double> fields_deg;
  std::vector<ToleranceParameter> parameters;
  std::vector<std::string> compensation_names;  // "image_shift_x_mm", "comp_dx2_mm", ...
  TrialResult nominal;
  std::vector<TrialResult> trials;
  SpotStatistics spot;          // mean RMS spot over valid trials, um
  std::optional<double> yield;  // fraction in [0, 1], when max_spot_um is set
  int invalid_trials = 0;
  int trials_with_failures = 0;
  int trials_with_collisions = 0;  // elements intersect (counted as failures in the yield)
  double efl_mean_mm = 0, efl_std_mm = 0, efl_min_mm = 0, efl_max_mm = 0;
  double distortion_mean_pct = 0, distortion_worst_pct = 0;
  std::vector<SensitivityRow> sensitivity;  // ranked, largest first
  double elapsed_s = 0;                     // Monte-Carlo trials only
  double ms_per_trial = 0;                  // wall time per trial with `threads` threads
  double sensitivity_s = 0;
};

// The nominal, prepared once: evaluates perturbations and draws trials.
class ToleranceModel {
 public:
  ToleranceModel(const Lens& lens, const ToleranceOptions& options);
  ~ToleranceModel();
  ToleranceModel(const ToleranceModel&) = delete;
  ToleranceModel& operator=(const ToleranceModel&) = delete;

  const std::vector<ToleranceParameter>& parameters() const;
  double scale() const;
  const Lens& scaled_lens() const;  // the nominal at the spec focal length
  std::vector<double> fields_deg() const;
  int wavelength_count() const;
  int rays_per_field_wavelength() const;
  // The names of TrialResult::compensation's entries.
  std::vector<std::string> compensation_names() const;

  // The perturbations of trial `index` (per parameter, native units), from (seed, index) alone.
  std::vector<double> draw(int index) const;
  // Traces the nominal with `perturbations` applied (all zero: the nominal), compensated.
  // Thread-safe; single-threaded.
  TrialResult evaluate(const std::vector<double>& perturbations) const;
  // The traced lens of a trial before its focus compensation (the perturbations applied).
  TraceLens<double> perturbed_trace_lens(const std::vector<double>& perturbations) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct InverseSensitivity {
  std::optional<double> limit;  // the magnitude (native units), or none if none reaches the drop
  double spot_change_um = 0;    // max(S(+m), S(-m)) - S_0 at that magnitude
  int evaluations = 0;          // traced trials
};
// The inverse sensitivity of one parameter (see the header): nominal_spot_um is S_0.
InverseSensitivity inverse_sensitivity(const ToleranceModel& model, int parameter, double drop_um,
                                       double nominal_spot_um);

// Runs the Monte-Carlo trials and the sensitivity table.
ToleranceReport run_tolerance(const Lens& lens, const ToleranceOptions& options);

// Statistics of values (NaN-free): mean, sample std, interpolated percentiles, extremes.
SpotStatistics spot_statistics(std::vector<double> values);

// Per-trial CSV: trial, valid, mean_spot_um, efl_mm, max_abs_distortion_pct, ray_failures,
// image_distance_mm, spot_um_<field> per field, then each parameter's perturbation. Numbers are
// written as the shortest text that reads back exactly; the file depends only on the inputs and
// the seed. An invalid trial's figures are empty cells.
std::string format_trials_csv(const ToleranceReport& report);
std::string format_tolerance_text(const ToleranceReport& report, int sensitivity_rows = 12);
// Everything, including each trial (no NaN: missing values are null).
std::string format_tolerance_json(const ToleranceReport& report);
// Histogram of the trials' mean RMS spot with the nominal, p90, p99 and max-spot lines.
std::string format_tolerance_histogram_svg(const ToleranceReport& report, int bins = 40);

}  // namespace lensopt
