// Baseline spot-size optimization with Ceres Levenberg-Marquardt (and a plain Adam loop on the
// same loss for comparison).
//
// Phases (Levenberg-Marquardt needs a smooth loss, and quantized glasses are not):
//   focus: the defocus alone, one LM round (a perturbed start is mostly out of focus);
//   0. strict constraints only (soft_start): fixed glasses, the paper's soft penalties, to find
//      the basin of a good design before the strict bounds are imposed;
//   A. fixed glasses: the start's glasses snapped to the catalog and held; curvatures and
//      spacings optimized, with constraint continuation: each bound the start violates is moved
//      in stages from the start's own extreme to its target, so the design walks into the
//      feasible set instead of being thrown out of its basin;
//   B. continuous glasses (unless --glass-search none): g free with the glass-variable loss, its
//      weight growing tenfold per round (annealed onto catalog glasses), then snapped and
//      re-optimized; kept only if it beats A with every constraint met;
//   C. neighbours (--glass-search neighbours): per element, the k catalog glasses
//      nearest in whitened (nd, vd) space are tried, each with a short re-optimization; an
//      improvement that meets every constraint is kept; repeated until a pass finds none.
// Each phase runs rounds of LM; between rounds the per-field weights of design_loss.h are
// recomputed (iteratively reweighted least squares on the paper's mean RMS) and the weight of a
// still-violated constraint is multiplied by 10. Bounds carry a small design margin.
#pragma once

#include <atomic>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/lens/lens.h"
#include "lensopt/optimize/design_loss.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/optimize/variables.h"

namespace lensopt {

enum class GlassSearch { kNone, kSnap, kNeighbours };

struct OptimizeOptions {
  TraceOptions sampling;   // optimization sampling (default: 8 rings, 11 fields)
  DesignLossOptions loss;  // paper weights and bounds
  // Default none: the start's glasses (snapped to the catalog) are kept. On the perturbed starts
  // snap and neighbours took 1.5x and 2.7x the CPU time and found no better glasses
  // (BENCHMARKS.md).
  GlassSearch glass_search = GlassSearch::kNone;
  int glass_neighbours = 4;         // catalog glasses tried per element in phase 3
  std::vector<std::string> freeze;  // variable names or groups to hold fixed
  // Surface-profile variables added to the lens's own ("k3", "a4_3": conic of surface 3, its a4);
  // variables.h normalizes them. Profile terms not named keep the start's values.
  std::vector<std::string> vary;
  // The designer's targets (optimize/targets.h): [[optimize.targets]] and --target. The
  // as-written mode adds the default efl_mm = the lens's own EFL (targets_with_defaults).
  std::vector<DesignTarget> targets;
  // Refocus only: every variable but the defocus (the last thickness) held.
  bool focus_only = false;
  int max_iterations = 50;  // LM iterations per round
  int max_rounds = 4;       // reweighting rounds per phase
  bool soft_start = true;   // strict constraints: run the paper's soft penalties first
  bool verbose = true;      // progress on stderr
  const std::atomic<bool>* interrupt = nullptr;  // set (e.g. by SIGINT) to stop early

  OptimizeOptions();
  void validate() const;
};

// Constraint check of a lens at some sampling.
struct ConstraintReport {
  struct Row {
    std::string name;  // "air gap 2-3", "glass 1-2", "image clearance", "ray angle", ...
    double value;      // the extreme found (mm or deg)
    double bound;      // the bound it is held to
    bool is_lower;     // value must be >= bound (else <= bound)
    bool pass;
  };
  std::vector<Row> rows;
  int ray_failures = 0;
  bool all_pass() const;
};
ConstraintReport check_constraints(const Lens& lens, const DesignLossOptions& loss,
                                   const TraceOptions& sampling);

struct OptimizeResult {
  Lens lens;                 // optimized lens (catalog glasses)
  double start_spot_um = 0;  // full sampling
  double final_spot_um = 0;  // full sampling
  std::vector<double> start_field_spot_um, final_field_spot_um;
  // With the wavefront merit: the mean RMS wavefront (waves, piston and tilt removed) at full
  // sampling (the lens's spec mode, 32 x 32 pupil grid); 0 with the spot merit.
  double start_wavefront_waves = 0, final_wavefront_waves = 0;
  // An afocal lens (Specs::afocal; design_loss.h): the merit is the mean RMS angular spot (mrad)
  // at full sampling, as `analyze` reports it (analysis/afocal.h), and per field; the spots above
  // (an image plane's) are then 0 and empty.
  bool afocal = false;
  double start_angular_spot_mrad = 0, final_angular_spot_mrad = 0;
  std::vector<double> start_field_angular_spot_mrad, final_field_angular_spot_mrad;
  ConstraintReport start_constraints, final_constraints;
  // The targets (with the default efl_mm of an as-written lens) on the start as given and on the
  // result, at full sampling.
  TargetReport start_targets, final_targets;
  std::vector<std::string> glasses;  // per element (a split element once)
  int iterations = 0;                // LM iterations, all phases
  int loss_evaluations = 0;          // residual evaluations (with or without Jacobian)
  int jacobian_evaluations = 0;
  // (evaluation number, mean spot l_S in mm at the optimization sampling) of every LM evaluation
  // in order, all phases: how many evaluations LM needed to reach a given spot.
  std::vector<std::pair<int, double>> spot_trajectory;
  double seconds = 0;
  std::string termination;  // Ceres's last termination message / interrupt
  bool interrupted = false;
  bool kept_start = false;       // optimization did not improve; the start is returned
  std::vector<std::string> log;  // phase summaries
};

// What an optimization achieved, as `lensopt optimize --json` and every `lensopt search`
// candidate report it (one set of names: optimize/summary_json.h writes and reads them).
// Spots are at full sampling; +inf when rays fail (JSON null).
struct OptimizeSummary {
  double start_spot_um = 0;  // JSON start_mean_rms_spot_um (not written for an afocal lens)
  double final_spot_um = 0;  // JSON final_mean_rms_spot_um
  // An afocal lens: JSON afocal = true, start_ / final_mean_rms_angular_spot_mrad in place of
  // the spots (+inf when rays fail: JSON null).
  bool afocal = false;
  double start_angular_spot_mrad = 0, final_angular_spot_mrad = 0;
  bool constraints_met = false;  // every constraint met at full sampling and the spot finite
  std::string failing;           // JSON failing_constraints: "ray angle = 61.2 (<= 60); ..."
  std::vector<std::string> glasses;
  int iterations = 0;
  int loss_evaluations = 0;
  bool kept_start = false;
  double seconds = 0;
};

// The summary of `result` (non-finite spots become +inf).
OptimizeSummary summarize(const OptimizeResult& result);

// The constraints that fail, as one line: "name = value (>= bound); ...; N failing rays".
std::string failing_constraints(const ConstraintReport& report);

// Never behind the start: the result is ordered against the start by (every constraint met at
// full sampling, then mean RMS spot at full sampling), and the start is returned (kept_start)
// when it is not behind. Glasses come from the lens's own catalog (Lens::catalog_name); a start of
// model glasses takes the catalog whose glasses lie nearest to its (nd, vd) (the paper's "ohara"
// for the paper's lenses), and the result names it, so the written lens reads back.
OptimizeResult optimize_lens(const Lens& start, const OptimizeOptions& options);

// Which bounds a lens is optimized with: the paper's (min glass 1 mm, max glass 3 mm, image
// clearance 12 mm, ... for the paper's 50 mm lenses), or bounds derived from the lens itself.
enum class BoundsMode { kAuto, kLens, kPaper };

// The paper's lenses keep the paper's bounds under BoundsMode::kAuto: a lens read from the
// paper's YAML (.yml / .yaml) or naming the paper's catalog ("ohara").
bool is_paper_lens(const Lens& lens);

// Bounds derived from a lens's focal length f (the spec focal length) and its own start values,
// with s = f / 50 mm (the paper's bounds are for 50 mm lenses) and the start's extremes over
// every traced ray at full sampling (travel per space, largest ray angle):
//   min air       = min(s * paper, 0.5 * start's thinnest air gap)
//   min glass     = min(s * paper, 0.5 * start's thinnest glass)
//   max glass     = max(s * paper, 1.5 * start's thickest glass)
//   min clearance = min(s * paper, 0.75 * start's image clearance)   (from the start's BFL)
//   max ray angle = max(paper, start's largest angle + 2 deg), at most 85 deg
// so the start itself meets them; the weights and the rest of `paper` are kept. The extremes are
// those of the rays that trace (a failed ray counts up to its failing surface); a start with a
// glass or air space that no ray crosses has no bound to derive from: Error, naming the space
// and what to give instead (the bounds, or --bounds paper), never a silent fallback.
DesignLossOptions lens_derived_bounds(const Lens& lens, const DesignLossOptions& paper);

// The bounds `mode` selects for a lens (kAuto: the paper's for is_paper_lens, else derived).
DesignLossOptions bounds_for(const Lens& lens, const DesignLossOptions& paper, BoundsMode mode);

// "auto", "lens" or "paper" (`optimize --bounds`); throws Error at `where` otherwise.
BoundsMode parse_bounds_mode(const std::string& name, const SourceLocation& where);
// "none", "snap", "neighbours" (or "neighbors"); throws Error at `where` otherwise.
GlassSearch parse_glass_search(const std::string& name, const SourceLocation& where);
std::string glass_search_name(GlassSearch search);
// "spot" or "wavefront" (DesignLossOptions::merit); throws Error at `where` otherwise.
DesignMerit parse_merit(const std::string& name, const SourceLocation& where);

// The catalog the optimizer takes glasses from: the lens's own; for a lens of model glasses, the
// paper's ("ohara") for the paper's lenses, else the shipped catalog whose glasses lie nearest to
// the lens's (nd, vd). The Python Parameterization and `--compare-adam` use it too.
std::string glass_catalog_for(const Lens& lens);

// What a caller sets on one optimization; every member left unset (nullopt) keeps the value
// resolve_optimize_options derives. `lensopt optimize` and lensopt.optimize (Python) fill this
// from their arguments and resolve it with the same function, so the two cannot differ.
struct OptimizeOverrides {
  BoundsMode bounds = BoundsMode::kAuto;
  std::optional<bool> paper_penalties;  // --constraints paper (true) / strict (false)
  std::optional<DesignMerit> merit;
  std::optional<int> wavefront_pupil_samples;
  std::optional<GlassSearch> glass_search;
  std::vector<std::string> freeze;               // added to the [optimize] table's
  std::optional<std::vector<std::string>> vary;  // replaces the [optimize] table's
  std::optional<bool> soft_start;
  // Added to the [optimize] table's targets; one of the same quantity and field replaces it.
  std::vector<DesignTarget> targets;
  std::optional<bool> focus_only;
  std::optional<int> rings, fields, threads, max_iterations, max_rounds, glass_neighbours;
  std::optional<double> weight_ray_path, weight_ray_angle, weight_glass;
  std::optional<double> min_air_mm, min_glass_mm, max_glass_mm, min_image_clearance_mm,
      max_ray_angle_deg;
  // A diverging lens's virtual-image distance bounds (design_loss.h; --min-virtual-image-mm,
  // --max-virtual-image-mm): Error on a lens without a virtual image (EFL > 0, afocal).
  std::optional<double> min_virtual_image_mm, max_virtual_image_mm;
  std::optional<bool> verbose;
};

struct ResolvedOptimizeOptions {
  OptimizeOptions options;    // validated
  bool paper_bounds = false;  // the paper's bounds (else derived from the lens)
};

// The options of optimizing `lens`, in this order: OptimizeOptions' defaults; the bounds
// `overrides.bounds` selects (bounds_for: the paper's for the paper's lenses, else derived from
// the lens, with the solved targets applied: apply_target_solves); the lens file's [optimize] table
// (its TOML source, else Lens::extra_toml; Error with file:line:column for a bad key); then every
// override that is set. Validated.
ResolvedOptimizeOptions resolve_optimize_options(const Lens& lens,
                                                 const OptimizeOverrides& overrides);

// A plain Adam loop on the paper's l_lens with the same variables, sampling and code path, for
// the LM comparison. Stops after `max_steps` or when the mean spot (optimization sampling) is at
// or below `target_spot_mm`. Returns the loss evaluations used and the spot reached.
struct AdamResult {
  int evaluations = 0;
  double spot_mm = 0;
  bool reached = false;
  std::vector<double> x;
};
AdamResult adam_on_design_loss(const LensParameterization& param, std::vector<double> x,
                               GlassMode mode, const std::vector<int>& fixed_glasses,
                               const OptimizeOptions& options, double learning_rate, int max_steps,
                               double target_spot_mm);

// Spot of variables at the optimization sampling (double), mm.
double design_spot_mm(const LensParameterization& param, const std::vector<double>& x,
                      GlassMode mode, const std::vector<int>& fixed_glasses,
                      const OptimizeOptions& options);

}  // namespace lensopt
