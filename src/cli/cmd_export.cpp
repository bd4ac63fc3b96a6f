// lensopt export LENS -o DIR: PSFs, the PSF grid, distortion and relative-illumination maps.
#include <fmt/core.h>

#include <memory>
#include <optional>
#include <string>

#include "commands.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/render/export.h"

namespace lensopt::cli {
namespace {

struct ExportCommand {
  std::string lens_path;
  std::string output_dir;
  std::string image_size = "1280x720";
  int res_factor = 1;
  int jobs = 0;
  bool diffraction = false;
  int pupil_samples = kRenderPupilSamples;
};

void run_export(const ExportCommand& cmd) {
  ExportOptions options;
  options.output_dir = cmd.output_dir;
  options.res_factor = cmd.res_factor;
  if (std::sscanf(cmd.image_size.c_str(), "%dx%d", &options.width, &options.height) != 2 ||
      cmd.image_size.find_first_not_of("0123456789x") != std::string::npos) {
    throw Error(
        fmt::format("--image-size '{}' must be WIDTHxHEIGHT, e.g. 1280x720", cmd.image_size));
  }
  options.validate();
  check_output_dir(options.output_dir, {cmd.lens_path});
  const Lens lens = read_lens(cmd.lens_path);
  TraceOptions trace;
  trace.threads = cmd.jobs;
  const ImagingModel model = build_imaging_model(lens, trace);
  for (const std::string& w : model.warnings)
    fmt::print(stderr, "lensopt export: warning: {}\n", w);
  std::optional<DiffractionPsfs> diffraction;
  if (cmd.diffraction) {
    WaveOptions wave;
    wave.pupil_samples = cmd.pupil_samples;
    diffraction = model_diffraction_psfs(model, lens, wave);
    for (const std::string& w : diffraction->warnings)
      fmt::print(stderr, "lensopt export: warning: {}\n", w);
  }
  const ExportSummary summary =
      export_imaging_model(model, options, diffraction ? &*diffraction : nullptr);
  fmt::print("{}: {} files in {} (image {}x{} at {}x: pitch {:.3f} um, patch PSFs up to {} px)\n",
             lens.name, summary.files.size(), cmd.output_dir, options.width, options.height,
             options.res_factor, summary.pitch_um, summary.kernel_size);
  for (const auto& f : summary.files) fmt::print("  {}\n", f.string());
  if (!summary.labels_drawn)
    fmt::print(stderr, "lensopt export: note: no font found: psf_sheet.png has no labels\n");
}

}  // namespace

void setup_export(CLI::App& app) {
  auto cmd = std::make_shared<ExportCommand>();
  CLI::App* sub = app.add_subcommand(
      "export",
      "Sampled PSFs (EXR), a contact sheet (PNG), the PSF grid of an image size, distortion and "
      "relative-illumination maps (EXR) and per-field values (JSON)");
  sub->add_option("LENS", cmd->lens_path, "lens file (.toml, the paper's .yml or Zemax .zmx)")
      ->required();
  sub->add_option("-o,--output", cmd->output_dir, "output folder")->required();
  sub->add_option("--image-size", cmd->image_size, "WIDTHxHEIGHT of the image (default 1280x720)");
  sub->add_option("--res-factor", cmd->res_factor, "simulated resolution factor: 1 or 2")
      ->check(CLI::IsMember({1, 2}));
  sub->add_option("--threads,--jobs,-j", cmd->jobs, "threads (0: all cores; --jobs: old name)")
      ->check(CLI::Range(0, 1024));
  sub->add_flag("--diffraction", cmd->diffraction,
                "also write diffraction PSFs (FFT of the pupil function) beside the geometric "
                "ones: psf/field_HH_diffraction.exr, psf_sheet_diffraction.png");
  sub->add_option("--pupil-samples", cmd->pupil_samples,
                  fmt::format("pupil grid cells across the diameter for --diffraction (default {})",
                              kRenderPupilSamples))
      ->check(CLI::Range(8, 1024));
  sub->callback([cmd] { run_export(*cmd); });
}

}  // namespace lensopt::cli
