// lensopt chart -o chart.png --size WxH: the built-in synthetic test chart.
#include <fmt/core.h>

#include <memory>
#include <string>

#include "commands.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/render/chart.h"
#include "lensopt/render/image.h"

namespace lensopt::cli {
namespace {

struct ChartCommand {
  std::string output;
  std::string size = "1280x720";
  bool no_text = false;
};

void run_chart(const ChartCommand& cmd) {
  ChartOptions options;
  if (std::sscanf(cmd.size.c_str(), "%dx%d", &options.width, &options.height) != 2 ||
      cmd.size.find_first_not_of("0123456789x") != std::string::npos) {
    throw Error(fmt::format("--size '{}' must be WIDTHxHEIGHT, e.g. 1280x720", cmd.size));
  }
  options.text = !cmd.no_text;
  check_output_file(cmd.output);
  const Chart chart = make_test_chart(options);
  write_image(cmd.output, chart.image);
  if (!chart.text_drawn && !cmd.no_text)
    fmt::print(stderr, "lensopt chart: note: {}\n", chart.note);
  fmt::print("wrote {} ({}x{})\n", cmd.output, options.width, options.height);
}

}  // namespace

void setup_chart(CLI::App& app) {
  auto cmd = std::make_shared<ChartCommand>();
  CLI::App* sub = app.add_subcommand(
      "chart",
      "A synthetic test chart: grid, Siemens stars, slanted edges, colour patches and text");
  sub->add_option("-o,--output", cmd->output, "image file (.png, .jpg, .tif, .exr)")->required();
  sub->add_option("--size", cmd->size, "WIDTHxHEIGHT (default 1280x720)");
  sub->add_flag("--no-text", cmd->no_text, "leave out the text");
  sub->callback([cmd] { run_chart(*cmd); });
}

}  // namespace lensopt::cli
