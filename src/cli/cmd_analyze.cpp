// lensopt analyze LENS: first-order data, spots, distortion, relative illumination, failures.
#include <fmt/core.h>

#include <memory>

#include "commands.h"
#include "lensopt/analysis/analyze.h"
#include "lensopt/core/error.h"
#include "lensopt/lens/lens_io.h"

namespace lensopt::cli {
namespace {

struct AnalyzeCommand {
  std::string lens_path;
  bool json = false;
  bool strict = false;
  bool no_ray_aiming = false;
  bool no_scale = false;
  std::string dispersion;  // "" = the lens's own
  AnalyzeOptions options;
};

void run_analyze(const AnalyzeCommand& cmd) {
  AnalyzeOptions options = cmd.options;
  options.trace.ray_aiming = !cmd.no_ray_aiming;
  options.trace.scale_to_spec = !cmd.no_scale;
  options.wave_options.threads = options.trace.threads;
  if (cmd.dispersion == "abbe") options.dispersion = DispersionModel::kAbbe;
  if (cmd.dispersion == "catalog") options.dispersion = DispersionModel::kCatalog;
  const Lens lens = read_lens(cmd.lens_path);
  const AnalysisReport report = analyze_lens(lens, options);
  if (cmd.json) {
    fmt::print("{}\n", format_report_json(report));
  } else {
    fmt::print("{}", format_report_text(report));
  }
  if (report.ray_failures > 0) {
    fmt::print(stderr, "lensopt analyze: warning: {} rays failed ({})\n", report.ray_failures,
               lens.source_path);
    if (cmd.strict) throw ExitCode{3};
  }
}

}  // namespace

void setup_analyze(CLI::App& app) {
  auto cmd = std::make_shared<AnalyzeCommand>();
  CLI::App* sub = app.add_subcommand(
      "analyze", "First-order data, RMS spot per field, distortion, relative illumination");
  sub->add_option("LENS", cmd->lens_path, "lens file (.toml, or the paper's .yml)")->required();
  sub->add_flag("--json", cmd->json, "one JSON object on stdout");
  sub->add_option("--rings", cmd->options.trace.rings, "pupil rings (rings^2 half-pupil rays)")
      ->check(CLI::Range(1, 256));
  sub->add_option("--fields", cmd->options.trace.fields, "field angles from 0 to hfov")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--threads", cmd->options.trace.threads, "threads (0: all cores)")
      ->check(CLI::Range(0, 1024));
  sub->add_flag("--no-ray-aiming", cmd->no_ray_aiming, "start rays on the paraxial pupil");
  sub->add_flag("--no-scale", cmd->no_scale, "trace the prescription as written");
  sub->add_option("--dispersion", cmd->dispersion, "abbe (the paper's) or catalog")
      ->check(CLI::IsMember({"abbe", "catalog"}));
  sub->add_flag("--wave", cmd->options.wave,
                "wave optics: RMS wavefront, Strehl ratio, diffraction and geometric MTF");
  sub->add_option("--mtf-freqs", cmd->options.mtf_frequencies_cyc_mm,
                  "MTF frequencies in cycles/mm for --wave (default 10,30,50)")
      ->delimiter(',');
  sub->add_option("--pupil-samples", cmd->options.wave_options.pupil_samples,
                  "pupil grid cells across the diameter for --wave (default 64)")
      ->check(CLI::Range(8, 1024));
  sub->add_option("--wavelength-weights", cmd->options.wave_options.wavelength_weights,
                  "weights of the spec wavelengths for --wave (default equal)")
      ->delimiter(',');
  sub->add_flag("--strict", cmd->strict, "exit with status 3 if any ray fails");
  sub->callback([cmd] { run_analyze(*cmd); });
}

}  // namespace lensopt::cli
