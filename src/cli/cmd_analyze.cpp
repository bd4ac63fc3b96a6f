// lensopt analyze LENS: first-order data, spots, distortion, relative illumination, failures.
#include <fmt/core.h>

#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "lens_checks.h"
#include "lensopt/analysis/afocal.h"
#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/chromatic.h"
#include "lensopt/analysis/encircled_energy.h"
#include "lensopt/analysis/forms_image.h"
#include "lensopt/analysis/seidel.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"

namespace lensopt::cli {
namespace {

struct AnalyzeCommand {
  std::string lens_path;
  bool json = false;
  bool strict = false;
  bool no_ray_aiming = false;
  bool no_scale = false;
  bool prescription = false;  // the surface table, first-order data and Seidel sums
  std::string dispersion;     // "" = the lens's own
  std::string mode;           // "" = the lens's own spec mode
  std::string zernike_order = "fringe";
  std::vector<double> colour_band;  // the chromatic focal shift's band LO, HI (nm)
  bool encircled_energy = false;    // geometric and diffraction encircled energy per field
  AnalyzeOptions options;
};

// An afocal lens (Specs::afocal): image space in angle (analysis/afocal.h). The image-plane
// sections (prescription with EFL and Seidel sums in mm, encircled energy, the MTF of --wave) do
// not apply: each is refused by name rather than printed with a focal length it lacks.
void run_afocal(const AnalyzeCommand& cmd, const Lens& lens, const AnalyzeOptions& options) {
  const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
  if (cmd.prescription || cmd.encircled_energy || !cmd.colour_band.empty())
    throw Error(SourceLocation{where},
                fmt::format("{} does not apply to an afocal lens (image space in angle, no "
                            "focal length); analyze reports its angular magnification, pupils, "
                            "output angles, angular spot and plane-wave wavefront",
                            cmd.prescription           ? "--prescription"
                            : !cmd.colour_band.empty() ? "--colour-band"
                                                       : "--encircled-energy"));
  const AfocalReport report = analyze_afocal_lens(lens, options);
  if (cmd.json)
    fmt::print("{}\n", format_afocal_json(report));
  else
    fmt::print("{}", format_afocal_text(report));
  int traced_rays = 0;
  for (const AfocalField& f : report.fields) traced_rays += f.traced_rays;
  const AfocalFirstOrder& fo = report.first_order;
  if (!std::isfinite(fo.angular_magnification) || fo.angular_magnification == 0.0 ||
      traced_rays == 0) {
    fmt::print(
        stderr, "lensopt analyze: error: the afocal analysis failed ({}): {}\n", where,
        traced_rays == 0 ? "no ray leaves the lens" : "the angular magnification is not finite");
    throw ExitCode{2};
  }
  if (report.ray_failures > 0) {
    fmt::print(stderr, "lensopt analyze: warning: {} rays failed ({})\n", report.ray_failures,
               where);
    if (cmd.strict) throw ExitCode{3};
  }
}

void run_analyze(const AnalyzeCommand& cmd) {
  AnalyzeOptions options = cmd.options;
  options.trace.ray_aiming = !cmd.no_ray_aiming;
  options.trace.scale_to_spec = !cmd.no_scale;
  options.wave_options.threads = options.trace.threads;
  options.wave_options.zernike_ordering = parse_zernike_ordering(cmd.zernike_order);
  if (options.wave_options.zernike_terms > 0) options.wave = true;
  if (cmd.dispersion == "abbe") options.dispersion = DispersionModel::kAbbe;
  if (cmd.dispersion == "catalog") options.dispersion = DispersionModel::kCatalog;
  Lens lens = read_lens(cmd.lens_path);
  if (cmd.mode == "paper") lens.specs.mode = SpecMode::kPaper;
  if (cmd.mode == "as-written") lens.specs.mode = SpecMode::kAsWritten;
  check_lens_warnings(lens, "analyze", cmd.strict);
  if (lens.specs.afocal) {
    run_afocal(cmd, lens, options);
    return;
  }
  const AnalysisReport report = analyze_lens(lens, options);
  check_forms_image(report);  // a lens without an image is an error (exit 1), not nulls
  // The designer's sections, each from the system analyze traced (the same preparation).
  std::string extra_text;
  nlohmann::json extra = nlohmann::json::object();
  if (cmd.prescription || cmd.encircled_energy) {
    Lens traced = lens;
    if (options.dispersion) traced.specs.dispersion = *options.dispersion;
    const TraceSystem<double> sys = prepare_lens_system(traced, options.trace);
    if (cmd.prescription) {
      const SeidelReport seidel = seidel_report(sys);
      extra_text += "\n" + format_prescription_text(traced, sys, seidel);
      extra["prescription"] = nlohmann::json::parse(format_prescription_json(traced, sys, seidel));
      const ChromaticFocalShift shift =
          cmd.colour_band.empty()
              ? chromatic_focal_shift(traced, sys)
              : chromatic_focal_shift(traced, sys, cmd.colour_band[0], cmd.colour_band[1], 11);
      const LateralColour lateral = lateral_colour(sys);
      extra_text += "\n" + format_chromatic_text(shift, lateral, report.field_unit);
      extra["chromatic_focal_shift"] = nlohmann::json::parse(format_focal_shift_json(shift));
      extra["lateral_colour"] = nlohmann::json::parse(format_lateral_colour_json(lateral));
    }
    if (cmd.encircled_energy) {
      EncircledEnergyOptions eo;
      eo.wave = options.wave_options;
      if (eo.wave.wavelength_weights.empty())
        eo.wave.wavelength_weights = lens_wavelength_weights(traced, sys.wavelength_count);
      eo.wave.zernike_terms = 0;
      const EncircledEnergy ee = encircled_energy(sys, eo);
      extra_text += "\n" + format_encircled_energy_text(ee, sys.field_values, report.field_unit);
      extra["encircled_energy"] = nlohmann::json::parse(format_encircled_energy_json(ee));
    }
  }
  if (cmd.json) {
    nlohmann::json j = nlohmann::json::parse(format_report_json(report));
    for (auto it = extra.begin(); it != extra.end(); ++it) j[it.key()] = it.value();
    fmt::print("{}\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
  } else {
    fmt::print("{}{}", format_report_text(report), extra_text);
  }
  // A failed analysis (no finite first-order data, or no ray reaches the image) never exits 0.
  int traced = 0;
  for (const FieldReport& f : report.fields) traced += f.traced_rays;
  const bool first_order =
      std::isfinite(report.efl_mm) && std::isfinite(report.epd_mm) && std::isfinite(report.bfl_mm);
  if (!first_order || traced == 0) {
    fmt::print(
        stderr, "lensopt analyze: error: the analysis failed ({}): {}\n", lens.source_path,
        !first_order ? "the paraxial first-order data are not finite" : "no ray reaches the image");
    throw ExitCode{2};
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
  sub->add_option("LENS", cmd->lens_path, "lens file (.toml, the paper's .yml or Zemax .zmx)")
      ->required();
  sub->add_flag("--json", cmd->json, "one JSON object on stdout");
  sub->add_option("--rings", cmd->options.trace.rings, "pupil rings (rings^2 half-pupil rays)")
      ->check(CLI::Range(1, 256));
  sub->add_option("--fields", cmd->options.trace.fields,
                  "field angles from 0 to hfov (paper mode, or a lens without written fields)")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--threads", cmd->options.trace.threads, "threads (0: all cores)")
      ->check(CLI::Range(0, 1024));
  sub->add_flag("--no-ray-aiming", cmd->no_ray_aiming, "start rays on the paraxial pupil");
  sub->add_flag("--no-scale", cmd->no_scale, "trace the prescription as written");
  sub->add_option("--dispersion", cmd->dispersion, "abbe (the paper's) or catalog")
      ->check(CLI::IsMember({"abbe", "catalog"}));
  sub->add_option("--mode", cmd->mode,
                  "spec mode: paper (scale to f = d / (2 tan hfov), EPD = f / N, fields 0..hfov) "
                  "or as-written (the lens's own aperture, fields and object distance)")
      ->check(CLI::IsMember({"paper", "as-written"}));
  sub->add_flag("--wave", cmd->options.wave,
                "wave optics: RMS wavefront, Strehl ratio, diffraction and geometric MTF");
  sub->add_option("--mtf-freqs", cmd->options.mtf_frequencies_cyc_mm,
                  "MTF frequencies in cycles/mm for --wave (default 10,30,50)")
      ->delimiter(',');
  sub->add_option("--pupil-samples", cmd->options.wave_options.pupil_samples,
                  "pupil grid cells across the diameter for --wave (default 128: the MTF within "
                  "~1e-3 of a converged grid; 64 is off by about 0.01 on the Tessar)")
      ->check(CLI::Range(8, 1024));
  sub->add_option("--wavelength-weights", cmd->options.wave_options.wavelength_weights,
                  "weights of the spec wavelengths for --wave (default: the lens's own "
                  "wavelength weights, else equal)")
      ->delimiter(',');
  sub->add_option("--zernike", cmd->options.wave_options.zernike_terms,
                  "Zernike fit of each wavefront with this many terms (implies --wave)")
      ->check(CLI::Range(1, kMaxZernikeTerms));
  sub->add_option("--zernike-order", cmd->zernike_order,
                  "Zernike ordering: fringe (default; unnormalized) or standard (Noll, unit RMS)")
      ->check(CLI::IsMember({"fringe", "standard"}));
  sub->add_flag("--prescription", cmd->prescription,
                "add the surface table, first-order data (EFL, BFL, pupils, working F/#, "
                "magnification), the Seidel sums per surface with primary colour, the "
                "chromatic focal shift and the lateral colour per field");
  sub->add_option("--colour-band", cmd->colour_band,
                  "with --prescription: the chromatic focal shift at 11 wavelengths from LO to HI "
                  "nm (default: at the spec wavelengths)")
      ->delimiter(',')
      ->expected(2);
  sub->add_flag("--encircled-energy", cmd->encircled_energy,
                "encircled energy per field about the centroid: geometric from the rays and "
                "diffraction from the wave-optics PSF (radii holding 50/80/90 %; the curves in "
                "--json)");
  sub->add_flag("--strict", cmd->strict,
                "exit with status 3 if any ray fails; refuse a wavelength outside a glass's range");
  sub->footer(
      "System model: a lens is traced in its spec mode. The paper's lenses (lenses/*.toml, the "
      "paper's YAML) use the paper's mode; a .zmx import or a TOML with a [system] table is "
      "traced as written: wavelengths with weights and a primary (the paraxial reference), "
      "fields by angle, object height, paraxial or real image height with weights and "
      "vignetting factors (VDY, VCX, VCY), aperture by EPD, image-space F/#, object-space NA or "
      "float by stop size, and a finite or infinite object. Surfaces with a semi-diameter are "
      "clear apertures: rays outside are vignetted and counted per field and surface. Colour "
      "channels: < 500 nm B, < 600 nm G, else R; an empty channel borrows the nearest "
      "wavelength. Exit status: 0 ok, 2 the analysis failed (no finite first-order data or no ray "
      "reaching the image), 3 a ray failed under --strict.");
  sub->callback([cmd] { run_analyze(*cmd); });
}

}  // namespace lensopt::cli
