// lensopt optimize LENS -o OUT.toml (or OUT.zmx): baseline spot-size optimization (Ceres
// Levenberg-Marquardt).
#include <fmt/core.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>

#include "commands.h"
#include "lens_checks.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/interrupt.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/core/text.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/optimizer.h"
#include "optimize/summary_json.h"

namespace lensopt::cli {
namespace {

struct OptimizeCommand {
  std::string lens_path;
  std::string output_path;
  bool in_place = false;
  bool json = false;
  bool quiet = false;
  bool compare_adam = false;
  bool no_soft_start = false;
  int adam_steps = 20000;
  bool joint = false;
  std::string glass_search;
  std::string constraints;
  std::string bounds = "auto";
  std::string merit;  // "" = the [optimize] table's, else spot
  int wavefront_pupil_samples = -1;
  std::vector<std::string> freeze;
  std::vector<std::string> vary;
  std::vector<std::string> targets;  // --target, as written
  bool focus_only = false;
  // Command-line overrides (NaN / -1: not given).
  int rings = -1, fields = -1, max_iterations = -1, neighbours = -1, threads = -1;
  double weight_ray_path = NAN, weight_ray_angle = NAN, weight_glass = NAN;
  double min_air_mm = NAN, min_glass_mm = NAN, max_glass_mm = NAN, min_image_clearance_mm = NAN,
         max_ray_angle_deg = NAN, min_virtual_image_mm = NAN, max_virtual_image_mm = NAN;
};

std::string format_constraints(const ConstraintReport& c) {
  std::string out;
  for (const ConstraintReport::Row& r : c.rows) {
    out += fmt::format("    {:<34} {:10.4f}  {} {:8.3f}  {}\n", r.name, r.value,
                       r.is_lower ? ">=" : "<=", r.bound, r.pass ? "pass" : "FAIL");
  }
  out += fmt::format("    {:<34} {:10d}  == {:8d}  {}\n", "ray failures", c.ray_failures, 0,
                     c.ray_failures == 0 ? "pass" : "FAIL");
  return out;
}

// The targets before and after: "    efl_mm = 100        100.0000 -> 100.0000  pass".
std::string format_targets(const TargetReport& start, const TargetReport& final) {
  std::string out;
  for (std::size_t i = 0; i < final.rows.size(); ++i) {
    const TargetRow& r = final.rows[i];
    const double before = i < start.rows.size() ? start.rows[i].value : NAN;
    const bool before_pass = i < start.rows.size() && start.rows[i].pass;
    out += fmt::format("    {:<44} {:>12} {:<4} -> {:>12}  {}\n", target_text(r.target),
                       std::isfinite(before) ? fmt::format("{:.6g}", before) : "n/a",
                       before_pass ? "pass" : "FAIL",
                       std::isfinite(r.value) ? fmt::format("{:.6g}", r.value) : "n/a",
                       r.pass ? "pass" : "FAIL");
  }
  return out;
}

nlohmann::json targets_json(const TargetReport& start, const TargetReport& final) {
  nlohmann::json rows = nlohmann::json::array();
  for (std::size_t i = 0; i < final.rows.size(); ++i) {
    const TargetRow& r = final.rows[i];
    const DesignTarget& t = r.target;
    const char* relation = t.relation == TargetRelation::kEqual    ? "="
                           : t.relation == TargetRelation::kAtMost ? "<="
                                                                   : ">=";
    nlohmann::json row = {{"target", target_text(t)},
                          {"quantity", target_quantity_name(t.quantity)},
                          {"relation", relation},
                          {"bound", t.value},
                          {"weight", t.weight},
                          {"field", t.field > 0 ? nlohmann::json(t.field) : nlohmann::json()},
                          {"default", t.is_default},
                          {"start", nullptr},
                          {"start_pass", false},
                          {"final", std::isfinite(r.value) ? nlohmann::json(r.value) : nullptr},
                          {"pass", r.pass}};
    if (t.quantity == TargetQuantity::kMtf) {
      row["frequency_cpmm"] = t.frequency_cpmm;
      row["orientation"] = mtf_orientation_name(t.orientation);
    }
    if (i < start.rows.size()) {
      if (std::isfinite(start.rows[i].value)) row["start"] = start.rows[i].value;
      row["start_pass"] = start.rows[i].pass;
    }
    rows.push_back(row);
  }
  return rows;
}

nlohmann::json constraints_json(const ConstraintReport& c) {
  nlohmann::json rows = nlohmann::json::array();
  for (const ConstraintReport::Row& r : c.rows)
    rows.push_back({{"name", r.name},
                    {"value", r.value},
                    {"bound", r.bound},
                    {"kind", r.is_lower ? "min" : "max"},
                    {"pass", r.pass}});
  return {{"rows", rows}, {"ray_failures", c.ray_failures}, {"all_pass", c.all_pass()}};
}

// The output path, checked before any work: given, .toml or .zmx, not the input (unless
// --in-place), in a folder that exists and is writable.
std::filesystem::path checked_output_path(const OptimizeCommand& cmd) {
  std::filesystem::path out_path = cmd.output_path;
  if (cmd.in_place) out_path = cmd.lens_path;
  if (out_path.empty())
    throw Error("give -o OUT.toml or OUT.zmx (or --in-place to overwrite the input)");
  if (!cmd.in_place && std::filesystem::exists(out_path) &&
      std::filesystem::equivalent(out_path, cmd.lens_path))
    throw Error(SourceLocation{out_path.string()},
                "refusing to overwrite the input lens; use --in-place to do that");
  const std::string extension = lower_extension(out_path);
  if (extension != ".toml" && extension != ".zmx")
    throw Error(SourceLocation{out_path.string()},
                "the optimized lens is written as .toml or Zemax .zmx");
  check_output_file(out_path);  // the output layer's check: folder exists and is writable
  return out_path;
}

void run_optimize(const OptimizeCommand& cmd) {
  const std::filesystem::path out_path = checked_output_path(cmd);
  const Lens lens = read_lens(cmd.lens_path);
  check_lens_warnings(lens, "optimize", false);
  // One resolution for the CLI and Python (optimizer.h): defaults, bounds, the [optimize] table,
  // then what the command line sets.
  OptimizeOverrides overrides;
  overrides.bounds = parse_bounds_mode(cmd.bounds, SourceLocation{"--bounds"});
  if (!cmd.constraints.empty()) overrides.paper_penalties = cmd.constraints == "paper";
  if (!cmd.merit.empty()) overrides.merit = parse_merit(cmd.merit, SourceLocation{"--merit"});
  if (cmd.wavefront_pupil_samples > 0)
    overrides.wavefront_pupil_samples = cmd.wavefront_pupil_samples;
  if (!cmd.glass_search.empty())
    overrides.glass_search = parse_glass_search(cmd.glass_search, SourceLocation{"--glass-search"});
  overrides.freeze = cmd.freeze;
  if (!cmd.vary.empty()) overrides.vary = cmd.vary;
  for (const std::string& t : cmd.targets)
    overrides.targets.push_back(parse_target(t, SourceLocation{"--target"}));
  if (cmd.focus_only) overrides.focus_only = true;
  if (cmd.no_soft_start) overrides.soft_start = false;
  if (cmd.rings > 0) overrides.rings = cmd.rings;
  if (cmd.fields > 0) overrides.fields = cmd.fields;
  if (cmd.threads >= 0) overrides.threads = cmd.threads;
  if (cmd.max_iterations > 0) overrides.max_iterations = cmd.max_iterations;
  if (cmd.neighbours >= 0) overrides.glass_neighbours = cmd.neighbours;
  auto given = [](double v, std::optional<double>& target) {
    if (!std::isnan(v)) target = v;
  };
  given(cmd.weight_ray_path, overrides.weight_ray_path);
  given(cmd.weight_ray_angle, overrides.weight_ray_angle);
  given(cmd.weight_glass, overrides.weight_glass);
  given(cmd.min_air_mm, overrides.min_air_mm);
  given(cmd.min_glass_mm, overrides.min_glass_mm);
  given(cmd.max_glass_mm, overrides.max_glass_mm);
  given(cmd.min_image_clearance_mm, overrides.min_image_clearance_mm);
  given(cmd.max_ray_angle_deg, overrides.max_ray_angle_deg);
  given(cmd.min_virtual_image_mm, overrides.min_virtual_image_mm);
  given(cmd.max_virtual_image_mm, overrides.max_virtual_image_mm);
  overrides.verbose = !cmd.quiet;
  const ResolvedOptimizeOptions resolved = resolve_optimize_options(lens, overrides);
  OptimizeOptions options = resolved.options;
  const bool paper_bounds = resolved.paper_bounds;
  const bool wavefront = options.loss.merit == DesignMerit::kWavefront;

  if (!cmd.quiet && !cmd.json)
    fmt::print(
        stderr,
        "lensopt optimize: {} bounds: air >= {:.4g} mm, glass {:.4g}..{:.4g} mm, {}, ray "
        "angle <= {:.4g} deg\n",
        paper_bounds ? "the paper's" : "lens-derived", options.loss.min_air_mm,
        options.loss.min_glass_mm, options.loss.max_glass_mm,
        lens.specs.afocal ? std::string("no image plane (afocal: image at infinity)")
        : options.loss.virtual_image()
            ? fmt::format("virtual image {:.4g}..{:.4g} mm before the last surface",
                          options.loss.min_virtual_image_mm, options.loss.max_virtual_image_mm)
            : fmt::format("image clearance >= {:.4g} mm", options.loss.min_image_clearance_mm),
        options.loss.max_ray_angle_deg);

  OptimizeResult result;
  {
    const InterruptScope interrupt;  // SIGINT / SIGTERM: stop after the running iteration
    options.interrupt = interrupt.flag();
    result = optimize_lens(lens, options);
  }

  // A starting lens without catalog glass names gets the result's names anyway.
  write_lens(result.lens, out_path);

  if (cmd.json) {
    nlohmann::json j;
    j["lens"] = lens.name;
    j["output"] = out_path.string();
    add_summary_json(j, summarize(result));  // the keys search's results use too
    if (result.afocal) {
      j["start_rms_angular_spot_mrad"] = result.start_field_angular_spot_mrad;
      j["final_rms_angular_spot_mrad"] = result.final_field_angular_spot_mrad;
    } else {
      j["start_rms_spot_um"] = result.start_field_spot_um;
      j["final_rms_spot_um"] = result.final_field_spot_um;
    }
    j["merit"] = result.afocal ? "angular_spot" : wavefront ? "wavefront" : "spot";
    if (wavefront) {
      j["start_mean_rms_wavefront_waves"] = result.start_wavefront_waves;
      j["final_mean_rms_wavefront_waves"] = result.final_wavefront_waves;
      j["wavefront_pupil_samples"] = options.loss.wavefront_pupil_samples;
    }
    j["targets"] = targets_json(result.start_targets, result.final_targets);
    j["targets_met"] = result.final_targets.all_pass();
    j["start_constraints"] = constraints_json(result.start_constraints);
    j["final_constraints"] = constraints_json(result.final_constraints);
    j["jacobian_evaluations"] = result.jacobian_evaluations;
    j["termination"] = result.termination;
    j["interrupted"] = result.interrupted;
    j["bounds"] = {{"mode", paper_bounds ? "paper" : "lens"},
                   {"min_air_mm", options.loss.min_air_mm},
                   {"min_glass_mm", options.loss.min_glass_mm},
                   {"max_glass_mm", options.loss.max_glass_mm},
                   {"max_ray_angle_deg", options.loss.max_ray_angle_deg}};
    if (!result.afocal) j["bounds"]["min_image_clearance_mm"] = options.loss.min_image_clearance_mm;
    if (options.loss.virtual_image()) {
      j["bounds"]["min_virtual_image_mm"] = options.loss.min_virtual_image_mm;
      j["bounds"]["max_virtual_image_mm"] = options.loss.max_virtual_image_mm;
    }
    j["log"] = result.log;
    j["sampling"] = {{"rings", options.sampling.rings}, {"fields", options.sampling.fields}};
    fmt::print("{}\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
  } else {
    fmt::print("lensopt optimize: {} -> {}\n", cmd.lens_path, out_path.string());
    if (wavefront)
      fmt::print(
          "  mean RMS wavefront (full sampling, piston and tilt removed): {:.5f} -> {:.5f} "
          "waves (the merit)\n",
          result.start_wavefront_waves, result.final_wavefront_waves);
    if (result.afocal) {
      // An afocal lens: the merit in angle, as `analyze` reports it (analysis/afocal.h).
      fmt::print("  mean RMS angular spot (full sampling, afocal): {:.6f} mrad -> {:.6f} mrad{}\n",
                 result.start_angular_spot_mrad, result.final_angular_spot_mrad,
                 result.kept_start ? "  (no improvement found: start kept)" : "");
      fmt::print("  field (index)       before (mrad) after (mrad)\n");
      for (std::size_t h = 0; h < result.final_field_angular_spot_mrad.size(); ++h)
        fmt::print("  {:17d}   {:13.6f} {:12.6f}\n", h,
                   h < result.start_field_angular_spot_mrad.size()
                       ? result.start_field_angular_spot_mrad[h]
                       : 0.0,
                   result.final_field_angular_spot_mrad[h]);
    } else {
      fmt::print("  mean RMS spot (full sampling): {:.3f} um -> {:.3f} um{}\n",
                 result.start_spot_um, result.final_spot_um,
                 result.kept_start ? "  (no improvement found: start kept)" : "");
      fmt::print("  field (deg index)   before (um)   after (um)\n");
      for (std::size_t h = 0; h < result.final_field_spot_um.size(); ++h)
        fmt::print("  {:17d}   {:11.3f}   {:10.3f}\n", h,
                   h < result.start_field_spot_um.size() ? result.start_field_spot_um[h] : 0.0,
                   result.final_field_spot_um[h]);
    }
    if (!result.final_targets.rows.empty())
      fmt::print("  targets (full sampling)                         before          after\n{}",
                 format_targets(result.start_targets, result.final_targets));
    fmt::print("  constraints after (full sampling):\n{}",
               format_constraints(result.final_constraints));
    std::string glasses;
    for (const std::string& g : result.glasses) glasses += (glasses.empty() ? "" : ", ") + g;
    fmt::print("  glasses: {}\n", glasses);
    fmt::print("  {} LM iterations, {} loss evaluations ({} with Jacobian), {:.1f} s; {}\n",
               result.iterations, result.loss_evaluations, result.jacobian_evaluations,
               result.seconds, result.termination);
    for (const std::string& l : result.log) fmt::print("  {}\n", l);
  }

  if (!result.final_targets.all_pass()) {
    std::string failing;
    for (const TargetRow& r : result.final_targets.rows)
      if (!r.pass)
        failing += fmt::format("{}{} (is {:.6g})", failing.empty() ? "" : "; ",
                               target_text(r.target), r.value);
    fmt::print(stderr, "lensopt optimize: warning: the result does not meet its targets: {}\n",
               failing);
  }
  if (!result.final_constraints.all_pass()) {
    std::string failing;
    for (const ConstraintReport::Row& r : result.final_constraints.rows)
      if (!r.pass)
        failing += fmt::format("{}{} = {:.4f} ({} {})", failing.empty() ? "" : "; ", r.name,
                               r.value, r.is_lower ? ">=" : "<=", r.bound);
    if (result.final_constraints.ray_failures > 0)
      failing += fmt::format("{}{} failing rays", failing.empty() ? "" : "; ",
                             result.final_constraints.ray_failures);
    if (lens.specs.afocal)
      fmt::print(stderr,
                 "lensopt optimize: warning: the result does not meet its constraints: {}.\n",
                 failing);
    else
      fmt::print(stderr,
                 "lensopt optimize: warning: the result does not meet its constraints: {}. The "
                 "specs (f/{}, {} deg) may be out of reach for this lens.\n",
                 failing, lens.specs.f_number, lens.specs.half_field_deg);
  }
  if (cmd.compare_adam) {
    // Same loss, sampling and code path: LM (glasses fixed) vs a plain Adam loop.
    OptimizeOptions fixed = options;
    fixed.glass_search = GlassSearch::kNone;
    fixed.verbose = false;
    const OptimizeResult lm = optimize_lens(lens, fixed);
    const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
    const std::vector<double> x0 = param.from_lens(lens);
    const std::vector<int> glasses = param.nearest_glasses(x0.data());
    const std::vector<double> x_lm = param.from_lens(lm.lens);
    const double lm_spot = design_spot_mm(param, x_lm, GlassMode::kFixed, glasses, fixed);
    // The same target for both: within 1 % of LM's final spot; each side's count is the number
    // of loss evaluations (LM: residuals with or without Jacobian; Adam: one gradient each)
    // until its spot first reaches the target.
    const double target_mm = lm_spot * 1.01;
    int lm_evaluations = lm.loss_evaluations;
    for (const auto& [number, spot_mm] : lm.spot_trajectory) {
      if (spot_mm <= target_mm) {
        lm_evaluations = number;
        break;
      }
    }
    const AdamResult adam = adam_on_design_loss(param, x0, GlassMode::kFixed, glasses, fixed, 5e-3,
                                                cmd.adam_steps, target_mm);
    fmt::print(
        "  LM vs Adam (glasses fixed, optimization sampling, target {:.4f} um = LM's final "
        "+ 1 %): LM reached it after {} of its {} loss evaluations; Adam (lr 5e-3) {} "
        "{:.4f} um after {} evaluations ({}{:.1f}x LM's)\n",
        target_mm * 1000, lm_evaluations, lm.loss_evaluations,
        adam.reached ? "reached" : "stopped at", adam.spot_mm * 1000, adam.evaluations,
        adam.reached ? "" : "> ",
        static_cast<double>(adam.evaluations) / std::max(1, lm_evaluations));
  }
  if (result.interrupted) {
    fmt::print(stderr, "lensopt optimize: interrupted; the best lens so far is in {}\n",
               out_path.string());
    throw ExitCode{130};
  }
}

}  // namespace

void setup_optimize(CLI::App& app) {
  auto cmd = std::make_shared<OptimizeCommand>();
  CLI::App* sub = app.add_subcommand(
      "optimize", "Optimize a lens for spot size or wavefront (Ceres Levenberg-Marquardt)");
  sub->add_option("LENS", cmd->lens_path, "starting lens (.toml, the paper's .yml or Zemax .zmx)")
      ->required();
  sub->add_option("-o,--output", cmd->output_path,
                  "optimized lens (.toml or Zemax .zmx), written atomically");
  sub->add_flag("--in-place", cmd->in_place, "overwrite the input lens (TOML)");
  sub->add_flag("--json", cmd->json, "report as one JSON object on stdout");
  sub->add_flag("-q,--quiet", cmd->quiet, "no per-iteration progress on stderr");
  sub->add_option("--glass-search", cmd->glass_search,
                  "none (default: keep the start's glasses) | snap | neighbours")
      ->check(CLI::IsMember({"none", "snap", "neighbours", "neighbors"}));
  sub->add_option("--neighbours", cmd->neighbours, "catalog glasses tried per element")
      ->check(CLI::Range(0, 64));
  sub->add_option("--bounds", cmd->bounds,
                  "auto (default: the paper's bounds for the paper's lenses, else derived from "
                  "the lens: its focal length and start values) | lens | paper")
      ->check(CLI::IsMember({"auto", "lens", "paper"}));
  sub->add_option("--constraints", cmd->constraints,
                  "strict (default: every bound held) or paper (the paper's soft penalties)")
      ->check(CLI::IsMember({"strict", "paper"}));
  sub->add_option("--merit", cmd->merit,
                  "spot (default: the paper's mean RMS spot; an afocal lens's mean RMS "
                  "angular spot) or wavefront (the mean RMS wavefront error, piston and tilt "
                  "removed, exact Jacobian)")
      ->check(CLI::IsMember({"spot", "wavefront"}));
  sub->add_option("--wavefront-pupil-samples", cmd->wavefront_pupil_samples,
                  "pupil samples across the diameter for --merit wavefront: a polar Gauss "
                  "quadrature of n/2 rings x n azimuths per half pupil (default 8)")
      ->check(CLI::Range(4, 256));
  sub->add_option(
         "--freeze", cmd->freeze,
         "variables or groups to hold (c3, s2, defocus, g1, curvatures, spacings, glasses), "
         "overriding the lens file's vary flags")
      ->delimiter(',');
  sub->add_option("--vary", cmd->vary,
                  "variables to free, overriding the lens file's vary flags (c3, s2, g2, "
                  "defocus, a group), and surface-profile variables to add: k3 (conic of "
                  "surface 3), a4_3 (its r^4 term), a2_3 .. a16_3; replaces [optimize] vary")
      ->delimiter(',');
  sub->add_option("--target", cmd->targets,
                  "a design target, repeatable: NAME=V, NAME<=V or NAME>=V with ,weight=W and "
                  ",field=N optional (efl_mm, f_number, total_track_mm, bfl_mm, "
                  "distortion_percent, relative_illumination, rms_spot_um, rms_wavefront_waves, "
                  "mtf with ,freq=NU in cycles/mm and ,orientation=tangential|sagittal|average: "
                  "the geometric MTF; an afocal lens: angular_magnification, total_track_mm); "
                  "replaces the [[optimize.targets]] entry of the same quantity and field")
      ->allow_extra_args(false)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  sub->add_flag("--focus-only", cmd->focus_only,
                "refocus only: every variable but the defocus (the last thickness) held");
  sub->add_flag("--no-soft-start", cmd->no_soft_start,
                "strict constraints: skip the first phase on the paper's soft penalties");
  sub->add_option("--rings", cmd->rings, "pupil rings during optimization (default 8)")
      ->check(CLI::Range(1, 256));
  sub->add_option("--fields", cmd->fields, "fields during optimization (default 11)")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--threads", cmd->threads, "threads (0: all cores)")->check(CLI::Range(0, 1024));
  sub->add_option("--max-iterations", cmd->max_iterations, "LM iterations per round (default 50)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--weight-ray-path", cmd->weight_ray_path, "lambda_RP (default 100)")
      ->check(kFinite);
  sub->add_option("--weight-ray-angle", cmd->weight_ray_angle, "lambda_RA (default 100)")
      ->check(kFinite);
  sub->add_option("--weight-glass", cmd->weight_glass, "lambda_GV (default 0.01)")->check(kFinite);
  sub->add_option("--min-air-mm", cmd->min_air_mm, "smallest air gap (paper: 0.01)")
      ->check(kFinite);
  sub->add_option("--min-glass-mm", cmd->min_glass_mm, "thinnest glass (paper: 1)")->check(kFinite);
  sub->add_option("--max-glass-mm", cmd->max_glass_mm, "thickest glass (paper: 3)")->check(kFinite);
  sub->add_option("--min-image-clearance-mm", cmd->min_image_clearance_mm,
                  "image clearance (paper: 12)")
      ->check(kFinite);
  sub->add_option("--min-virtual-image-mm", cmd->min_virtual_image_mm,
                  "a diverging lens: nearest distance of its virtual image before the last "
                  "surface (default: half the start's)")
      ->check(kFinite);
  sub->add_option("--max-virtual-image-mm", cmd->max_virtual_image_mm,
                  "a diverging lens: farthest distance of its virtual image before the last "
                  "surface (default: twice the start's)")
      ->check(kFinite);
  sub->add_option("--max-ray-angle-deg", cmd->max_ray_angle_deg, "largest ray angle (paper: 60)")
      ->check(kFinite);
  sub->add_flag("--compare-adam", cmd->compare_adam,
                "also report loss evaluations of LM vs a plain Adam loop on the same loss");
  sub->add_option("--adam-steps", cmd->adam_steps,
                  "largest Adam step count for --compare-adam (default 20000)")
      ->check(CLI::Range(1, 100000000));
  sub->add_flag("--joint", cmd->joint,
                "joint lens + network optimization by Adam (options under 'joint', see README)");
  const auto run_joint = setup_optimize_joint(*sub);
  sub->callback([cmd, run_joint] {
    if (!cmd->joint) return run_optimize(*cmd);
    run_joint({cmd->lens_path, cmd->in_place ? cmd->lens_path : cmd->output_path, cmd->in_place,
               cmd->json, cmd->quiet, cmd->threads, cmd->weight_ray_path, cmd->weight_ray_angle,
               cmd->weight_glass, cmd->freeze});
  });
}

}  // namespace lensopt::cli
