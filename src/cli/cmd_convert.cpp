// lensopt convert IN OUT: between lensopt TOML, the paper's YAML (read only) and Zemax .zmx,
// chosen by the files' extensions. Import warnings (lines a .zmx has that lensopt does not model)
// and the lens's own (glass ranges, a paraxial F-number below 0.5) go to stderr; the output is
// written atomically.
#include <fmt/core.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.h"
#include "lens_checks.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/core/text.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/lens/lens_io.h"

namespace lensopt::cli {
namespace {

struct ConvertCommand {
  std::string input_path;
  std::string output_path;
  std::string output_option;  // -o OUT, as the other commands take their output
};

Lens read_input(const std::filesystem::path& path) {
  const std::string extension = lower_extension(path);
  if (extension == ".zmx") {
    ZmxImport imported = read_zmx(path);
    for (const std::string& warning : imported.warnings)
      fmt::print(stderr, "lensopt convert: warning: {}\n", warning);
    return std::move(imported.lens);
  }
  if (extension == ".toml") return parse_lens_toml(read_file(path), path.string());
  if (extension == ".yml" || extension == ".yaml")
    return parse_lens_yaml(read_file(path), path.string());
  throw Error(SourceLocation{path.string()},
              fmt::format("cannot read '{}' files; convert reads .toml, the paper's .yml/.yaml "
                          "and Zemax .zmx",
                          path.extension().string()));
}

void run_convert(ConvertCommand cmd) {
  if (!cmd.output_option.empty()) {
    if (!cmd.output_path.empty() && cmd.output_path != cmd.output_option)
      throw Error(fmt::format("two outputs: OUT '{}' and -o '{}'; give one", cmd.output_path,
                              cmd.output_option));
    cmd.output_path = cmd.output_option;
  }
  if (cmd.output_path.empty()) throw Error("give the output lens: convert IN OUT (or -o OUT)");
  const std::filesystem::path output(cmd.output_path);
  const std::string out_extension = lower_extension(output);
  // Check the output type before reading, so a bad OUT fails fast.
  if (out_extension == ".yml" || out_extension == ".yaml")
    throw Error(SourceLocation{output.string()},
                "writing the paper's YAML format is not supported; write .toml or .zmx");
  if (out_extension != ".toml" && out_extension != ".zmx")
    throw Error(SourceLocation{output.string()},
                fmt::format("cannot write '{}' files; convert writes .toml and Zemax .zmx",
                            output.extension().string()));
  check_output_file(output, {cmd.input_path});
  const Lens lens = read_input(cmd.input_path);
  check_lens_warnings(lens, "convert", false);
  if (out_extension == ".zmx") {
    write_zmx(lens, output);
  } else {
    write_file_atomic(output, format_lens_toml(lens));
  }
  // An afocal lens has no F-number (no focal length): its summary says afocal instead.
  fmt::print("{} -> {}: {} surfaces, {}, half field {} deg, {} wavelengths\n", cmd.input_path,
             cmd.output_path, lens.surfaces.size(),
             lens.specs.afocal ? std::string("afocal") : fmt::format("f/{}", lens.specs.f_number),
             lens.specs.half_field_deg, lens.specs.wavelengths_nm.size());
}

}  // namespace

void setup_convert(CLI::App& app) {
  auto cmd = std::make_shared<ConvertCommand>();
  CLI::App* sub = app.add_subcommand(
      "convert", "Convert a lens between .toml, the paper's .yml (read) and Zemax .zmx");
  sub->add_option("IN", cmd->input_path, "input lens (.toml, .yml/.yaml or .zmx)")->required();
  sub->add_option("OUT", cmd->output_path, "output lens (.toml or .zmx)");
  sub->add_option("-o,--output", cmd->output_option, "output lens (.toml or .zmx), instead of OUT");
  sub->callback([cmd] { run_convert(*cmd); });
}

}  // namespace lensopt::cli
