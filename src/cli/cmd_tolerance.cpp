// lensopt tolerance LENS: Monte-Carlo tolerancing with a focus compensator, a sensitivity table,
// a per-trial CSV and a histogram. Tolerances come from the lens's [tolerance] table, then the
// command line (which wins).
#include <fmt/core.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "commands.h"
#include "lens_checks.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/tolerance/tolerance.h"

namespace lensopt::cli {
namespace {

// --curvature-pct .. --asphere-sag-um, --decenter-mm, --tilt-arcmin, --surface-decenter-mm,
// --surface-tilt-arcmin (Tolerances' order).
constexpr int kToleranceOptionCount = 10;

struct ToleranceCommand {
  std::string lens_path;
  // Values of options given on the command line; the defaults are ToleranceOptions'.
  int trials = 0;
  std::uint64_t seed = 1;
  int jobs = 0;
  std::string csv_path;
  std::string histogram_path;
  bool json = false;
  bool quiet = false;
  bool no_sensitivity = false;
  double max_spot_um = 0;
  std::string distribution = "uniform";
  std::string compensator = "paraxial";
  Tolerances tolerances;
  int rings = 0;
  int fields = 0;
  int sensitivity_rows = 12;
  // Options given on the command line (they override the [tolerance] table).
  CLI::Option* trials_opt = nullptr;
  CLI::Option* seed_opt = nullptr;
  CLI::Option* max_spot_opt = nullptr;
  double inverse_drop_um = 0;
  CLI::Option* inverse_drop_opt = nullptr;
  CLI::Option* distribution_opt = nullptr;
  CLI::Option* compensator_opt = nullptr;
  std::string spot_reference = "centroid";
  CLI::Option* spot_reference_opt = nullptr;
  CLI::Option* rings_opt = nullptr;
  CLI::Option* fields_opt = nullptr;
  CLI::Option* tolerance_opts[kToleranceOptionCount] = {};
};

// A CLI tolerance must be a finite number >= 0; the message names the option.
void check_cli_tolerance(const CLI::Option* opt, double value) {
  if (opt == nullptr || opt->count() == 0) return;
  if (!std::isfinite(value) || value < 0)
    throw Error(
        fmt::format("tolerance {} = {} must be a finite number >= 0 (tolerances are +- "
                    "limits)",
                    opt->get_name(), value));
}

void run_tolerance_command(const ToleranceCommand& cmd) {
  const double cli_values[kToleranceOptionCount] = {cmd.tolerances.curvature_pct,
                                                    cmd.tolerances.glass_thickness_mm,
                                                    cmd.tolerances.air_thickness_mm,
                                                    cmd.tolerances.nd,
                                                    cmd.tolerances.vd_pct,
                                                    cmd.tolerances.asphere_sag_um,
                                                    cmd.tolerances.decenter_mm,
                                                    cmd.tolerances.tilt_arcmin,
                                                    cmd.tolerances.surface_decenter_mm,
                                                    cmd.tolerances.surface_tilt_arcmin};
  for (int i = 0; i < kToleranceOptionCount; ++i)
    check_cli_tolerance(cmd.tolerance_opts[i], cli_values[i]);

  // The outputs are checked before the (long) run; none may replace the lens.
  for (const std::string& out : {cmd.csv_path, cmd.histogram_path})
    if (!out.empty())
      check_output_file(out,
                        {cmd.lens_path, cmd.csv_path == out ? cmd.histogram_path : cmd.csv_path});
  const Lens lens = read_lens(cmd.lens_path);
  check_lens_warnings(lens, "tolerance", false);
  // The lens's [tolerance] table over the defaults (one function for the CLI and Python), then
  // what the command line gives.
  ToleranceOptions options = tolerance_options_for(lens);
  double* targets[kToleranceOptionCount] = {&options.tolerances.curvature_pct,
                                            &options.tolerances.glass_thickness_mm,
                                            &options.tolerances.air_thickness_mm,
                                            &options.tolerances.nd,
                                            &options.tolerances.vd_pct,
                                            &options.tolerances.asphere_sag_um,
                                            &options.tolerances.decenter_mm,
                                            &options.tolerances.tilt_arcmin,
                                            &options.tolerances.surface_decenter_mm,
                                            &options.tolerances.surface_tilt_arcmin};
  for (int i = 0; i < kToleranceOptionCount; ++i)
    if (cmd.tolerance_opts[i]->count() > 0) *targets[i] = cli_values[i];
  if (cmd.distribution_opt->count() > 0)
    options.distribution = parse_tolerance_distribution(cmd.distribution);
  if (cmd.compensator_opt->count() > 0) {
    // A list on the command line replaces the table's: the focus it names (else paraxial), and
    // the compensators beyond focus.
    const CompensatorList list = parse_compensators(cmd.compensator);
    options.compensator = FocusCompensator::kParaxial;
    options.apply(list);
  }
  if (cmd.spot_reference_opt->count() > 0)
    options.spot_reference = parse_spot_reference(cmd.spot_reference);
  if (cmd.max_spot_opt->count() > 0) options.max_spot_um = cmd.max_spot_um;
  if (cmd.inverse_drop_opt->count() > 0) options.inverse_drop_um = cmd.inverse_drop_um;
  if (cmd.trials_opt->count() > 0) options.trials = cmd.trials;
  if (cmd.seed_opt->count() > 0) options.seed = cmd.seed;
  options.jobs = cmd.jobs;
  if (cmd.rings_opt->count() > 0) options.rings = cmd.rings;
  if (cmd.fields_opt->count() > 0) options.fields = cmd.fields;
  options.sensitivity = !cmd.no_sensitivity;
  if (!cmd.quiet) {
    // On a terminal one line rewritten in place; otherwise a line every 5 s and at the end.
    const bool tty = isatty(fileno(stderr)) != 0;
    auto last_line_s = std::make_shared<double>(-1e9);
    options.progress = [tty, last_line_s](int done, int total, double elapsed_s) {
      if (!tty && done < total && elapsed_s - *last_line_s < 5.0) return;
      *last_line_s = elapsed_s;
      const double eta = done > 0 ? elapsed_s * (total - done) / done : 0.0;
      fmt::print(stderr, "{}lensopt tolerance: {}/{} trials ({:.0f} %), {:.1f} s, ETA {:.1f} s{}",
                 tty ? "\r" : "", done, total, 100.0 * done / total, elapsed_s, eta,
                 tty && done < total ? "   " : "\n");
      std::fflush(stderr);
    };
    auto last_sens_s = std::make_shared<double>(-1e9);
    options.sensitivity_progress = [tty, last_sens_s](int done, int total, double elapsed_s) {
      if (!tty && done < total && elapsed_s - *last_sens_s < 5.0) return;
      *last_sens_s = elapsed_s;
      const double eta = done > 0 ? elapsed_s * (total - done) / done : 0.0;
      fmt::print(stderr,
                 "{}lensopt tolerance: sensitivity {}/{} evaluations ({:.0f} %), {:.1f} s, ETA "
                 "{:.1f} s{}",
                 tty ? "\r" : "", done, total, 100.0 * done / total, elapsed_s, eta,
                 tty && done < total ? "   " : "\n");
      std::fflush(stderr);
    };
  }
  options.validate();

  const ToleranceReport report = run_tolerance(lens, options);
  if (!cmd.csv_path.empty()) write_file_atomic(cmd.csv_path, format_trials_csv(report));
  if (!cmd.histogram_path.empty())
    write_file_atomic(cmd.histogram_path, format_tolerance_histogram_svg(report));
  if (cmd.json) {
    fmt::print("{}\n", format_tolerance_json(report));
  } else {
    fmt::print("{}", format_tolerance_text(report, cmd.sensitivity_rows));
  }
}

}  // namespace

void setup_tolerance(CLI::App& app) {
  auto cmd = std::make_shared<ToleranceCommand>();
  CLI::App* sub = app.add_subcommand(
      "tolerance", "Monte-Carlo tolerancing with a refocus compensator and a sensitivity table");
  sub->add_option(
         "LENS", cmd->lens_path,
         "lens file (.toml with an optional [tolerance] table, the paper's .yml or Zemax .zmx)")
      ->required();
  cmd->trials_opt = sub->add_option("--trials", cmd->trials, "Monte-Carlo trials (default 10000)")
                        ->check(CLI::Range(1, 100000000));
  cmd->seed_opt = sub->add_option("--seed", cmd->seed, "random seed (default 1)");
  sub->add_option("--threads,--jobs", cmd->jobs,
                  "threads over trials (0: all cores; --jobs: old name)")
      ->check(CLI::Range(0, 1024));
  sub->add_option("--csv", cmd->csv_path, "per-trial CSV file (written atomically)");
  sub->add_flag("--json", cmd->json, "everything as one JSON object on stdout");
  sub->add_option("--histogram", cmd->histogram_path, "histogram of the mean spot (SVG)");
  cmd->inverse_drop_opt = sub->add_option(
      "--inverse-drop-um", cmd->inverse_drop_um,
      "inverse sensitivity: for each tolerance, the magnitude that alone raises the mean RMS spot "
      "by this many um (the worse sign), a column of the sensitivity table ([tolerance] "
      "inverse_drop_um; default: not computed)");
  cmd->max_spot_opt =
      sub->add_option("--max-spot-um", cmd->max_spot_um, "yield limit on the mean RMS spot (um)")
          ->check(CLI::PositiveNumber);
  cmd->distribution_opt =
      sub->add_option("--distribution", cmd->distribution,
                      "uniform (default) or normal (sigma = tolerance / 2, truncated)")
          ->check(CLI::IsMember({"uniform", "normal"}));
  cmd->compensator_opt = sub->add_option(
      "--compensator", cmd->compensator,
      "compensators, comma-separated: the focus on the last thickness (paraxial, the default; "
      "best-rms; none), image-shift (the image plane moved laterally; needs --spot-reference "
      "nominal), decenter:element=K (group K's decenter x and y, rows tedx<K>), e.g. "
      "\"best-rms,decenter:element=2\"");
  cmd->spot_reference_opt = sub->add_option(
      "--spot-reference", cmd->spot_reference,
      "what each field's RMS spot is taken about: centroid (default, its own centroid) or "
      "nominal (the nominal lens's image point of the field: a displaced image counts)");
  cmd->tolerance_opts[0] = sub->add_option("--curvature-pct", cmd->tolerances.curvature_pct,
                                           "curvature tolerance, +- percent (default 0.2)");
  cmd->tolerance_opts[1] =
      sub->add_option("--glass-thickness-mm", cmd->tolerances.glass_thickness_mm,
                      "glass thickness tolerance, +- mm (default 0.05)");
  cmd->tolerance_opts[2] = sub->add_option("--air-thickness-mm", cmd->tolerances.air_thickness_mm,
                                           "airspace tolerance, +- mm (default 0: off)");
  cmd->tolerance_opts[3] =
      sub->add_option("--nd", cmd->tolerances.nd, "index tolerance, +- (default 5e-4)");
  cmd->tolerance_opts[4] = sub->add_option("--vd-pct", cmd->tolerances.vd_pct,
                                           "Abbe number tolerance, +- percent (default 0.5)");
  cmd->tolerance_opts[5] = sub->add_option(
      "--asphere-sag-um", cmd->tolerances.asphere_sag_um,
      "conic and asphere terms of non-spherical surfaces: +- sag at the clear semi-aperture, um, "
      "each term alone (default 1)");
  cmd->tolerance_opts[6] =
      sub->add_option("--decenter-mm", cmd->tolerances.decenter_mm,
                      "element decenter in x and in y, +- mm (default 0.02; 0: off)");
  cmd->tolerance_opts[7] =
      sub->add_option("--tilt-arcmin", cmd->tolerances.tilt_arcmin,
                      "element tilt about x and about y, +- arcmin (default 1; 0: off)");
  cmd->tolerance_opts[8] = sub->add_option(
      "--surface-decenter-mm", cmd->tolerances.surface_decenter_mm,
      "surface decenter in x and in y (TSDX, TSDY) of each curved surface alone, +- mm "
      "(default 0: off; a sphere's decenter is its tilt, already in --surface-tilt-arcmin)");
  cmd->tolerance_opts[9] = sub->add_option(
      "--surface-tilt-arcmin", cmd->tolerances.surface_tilt_arcmin,
      "surface tilt about x and about y (TSTX, TSTY) of each surface alone: an element's wedge, a "
      "mirror's tilt, +- arcmin (default 1; 0: off)");
  cmd->rings_opt =
      sub->add_option("--rings", cmd->rings,
                      "pupil rings per trial (default 16; the paper's full sampling is 32)")
          ->check(CLI::Range(1, 256));
  cmd->fields_opt =
      sub->add_option("--fields", cmd->fields, "field angles per trial (default 11; full: 21)")
          ->check(CLI::Range(1, 1000));
  sub->add_option("--sensitivity-rows", cmd->sensitivity_rows,
                  "rows of the sensitivity table in the text summary")
      ->check(CLI::Range(0, 100000));
  sub->add_flag("--no-sensitivity", cmd->no_sensitivity, "skip the sensitivity table");
  sub->add_flag("-q,--quiet", cmd->quiet, "no progress on stderr");
  sub->callback([cmd] { run_tolerance_command(*cmd); });
}

}  // namespace lensopt::cli
