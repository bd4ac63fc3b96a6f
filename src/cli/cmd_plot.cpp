// lensopt plot LENS --kind layout|spot|fan|field|psf|report|mtf|...|encircled-energy -o
// FILE.svg|.png
#include <fmt/core.h>

#include <memory>

#include "commands.h"
#include "lens_checks.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/plot/plot.h"

namespace lensopt::cli {
namespace {

struct PlotCommand {
  std::string lens_path;
  std::string kind = "report";
  std::string output;
  std::string compare_path;
  plot::PlotOptions options;
};

void run_plot(const PlotCommand& cmd) {
  plot::PlotOptions options = cmd.options;
  options.kind = plot::parse_plot_kind(cmd.kind);
  plot::output_format_for(cmd.output);  // a bad extension fails before any tracing
  options.validate();
  check_output_file(cmd.output, {cmd.lens_path, cmd.compare_path});
  const Lens lens = read_lens(cmd.lens_path);
  check_lens_warnings(lens, "plot", false);
  std::unique_ptr<Lens> compare;
  if (!cmd.compare_path.empty()) compare = std::make_unique<Lens>(read_lens(cmd.compare_path));
  const plot::PlotSummary summary = plot::write_plot(lens, compare.get(), options, cmd.output);
  for (const std::string& w : summary.warnings)
    fmt::print(stderr, "lensopt plot: warning: {}\n", w);
  fmt::print(stderr, "lensopt plot: wrote {} ({} page, {:.0f} x {:.0f} px{})\n", cmd.output,
             cmd.kind, summary.width_px, summary.height_px,
             summary.spot_box_um > 0
                 ? fmt::format(", spot boxes {:g} {}", summary.spot_box_um, summary.spot_box_unit)
                 : std::string());
}

}  // namespace

void setup_plot(CLI::App& app) {
  auto cmd = std::make_shared<PlotCommand>();
  CLI::App* sub = app.add_subcommand(
      "plot", "Lens layout with rays, spot diagrams, ray fans, field curves, PSFs (SVG or PNG)");
  sub->add_option("LENS", cmd->lens_path, "lens file (.toml, the paper's .yml or Zemax .zmx)")
      ->required();
  sub->add_option(
      "--kind,-k", cmd->kind,
      "layout, spot, fan, field, psf, report (default), mtf, through-focus, wavefront, "
      "psf-diffraction, mtf-field, chromatic or encircled-energy (the wave-optics kinds and the "
      "last three draw one lens)");
  sub->add_option("-o,--output", cmd->output, "output file: .svg or .png")->required();
  sub->add_option(
      "--compare", cmd->compare_path,
      "a second lens: overlaid dashed (layout, fans, fields), one more row (spots, PSFs)");
  sub->add_option("--spot-box-um", cmd->options.spot_box_um,
                  "width of every spot-diagram box in um (0: fit the largest spot); give the same "
                  "value to compare lenses across pages");
  sub->add_option("--width", cmd->options.width_px, "page width in px (0: the kind's default)");
  sub->add_option("--pupil-samples", cmd->options.pupil_samples,
                  "wave-optics kinds: pupil grid across the diameter (default 128)")
      ->check(CLI::Range(8, 1024));
  sub->add_option("--mtf-freq", cmd->options.mtf_frequency_cyc_mm,
                  "through-focus: the frequency in cycles/mm (default 30)");
  sub->add_option("--max-freq", cmd->options.max_frequency_cyc_mm,
                  "mtf: the frequency axis's end in cycles/mm (default: the cutoff "
                  "1 / (lambda_min N))");
  sub->add_option("--focus-range", cmd->options.focus_range_mm,
                  "through-focus: shift the image plane over +-this many mm (default 8 lambda "
                  "N^2)");
  sub->add_option("--mtf-freqs", cmd->options.mtf_frequencies_cyc_mm,
                  "mtf-field: the frequencies in cycles/mm (default 10,30,50)")
      ->delimiter(',');
  sub->add_option("--sweep-fields", cmd->options.sweep_fields,
                  "mtf-field and chromatic: field angles from 0 to the largest field (default "
                  "11)");
  sub->add_option_function<std::vector<double>>(
         "--colour-band",
         [cmd](const std::vector<double>& band) {
           if (band.size() != 2) throw CLI::ValidationError("--colour-band", "give LO,HI in nm");
           cmd->options.band_lo_nm = band[0];
           cmd->options.band_hi_nm = band[1];
         },
         "chromatic: the focal shift's band LO,HI in nm (default: the lens's shortest to "
         "longest wavelength)")
      ->delimiter(',');
  sub->add_option("--threads", cmd->options.trace.threads, "threads (0: all cores)")
      ->check(CLI::Range(0, 1024));
  sub->callback([cmd] { run_plot(*cmd); });
}

}  // namespace lensopt::cli
