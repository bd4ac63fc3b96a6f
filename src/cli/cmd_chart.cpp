// lensopt chart -o chart.png --size WxH: the built-in synthetic test chart.
// lensopt chart --detection -o DIR --count N: generated driving scenes with COCO boxes.
#include <fmt/core.h>

#include <memory>
#include <string>

#include "commands.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/detection/scenes.h"
#include "lensopt/render/chart.h"
#include "lensopt/render/image.h"

namespace lensopt::cli {
namespace {

struct ChartCommand {
  std::string output;
  std::string size = "1280x720";
  bool no_text = false;
  bool detection = false;
  int count = 32;
  std::uint64_t seed = 1;
};

void run_chart(const ChartCommand& cmd) {
  ChartOptions options;
  if (std::sscanf(cmd.size.c_str(), "%dx%d", &options.width, &options.height) != 2 ||
      cmd.size.find_first_not_of("0123456789x") != std::string::npos) {
    throw Error(fmt::format("--size '{}' must be WIDTHxHEIGHT, e.g. 1280x720", cmd.size));
  }
  if (cmd.detection) {
    SceneSetOptions scenes;
    scenes.width = options.width;
    scenes.height = options.height;
    scenes.count = cmd.count;
    scenes.seed = cmd.seed;
    scenes.validate();
    const DetectionDataset d = write_detection_scenes(cmd.output, scenes);
    fmt::print("wrote {} scenes ({}x{}) with {} boxes to {}/images and {}/annotations.json\n",
               d.images.size(), scenes.width, scenes.height, d.annotations.size(), cmd.output,
               cmd.output);
    return;
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
  sub->add_option("-o,--output", cmd->output,
                  "image file (.png, .jpg, .tif, .exr); with --detection a folder")
      ->required();
  sub->add_option("--size", cmd->size, "WIDTHxHEIGHT (default 1280x720)");
  sub->add_flag("--detection", cmd->detection,
                "a detection dataset instead: --count generated driving scenes with exact boxes "
                "of the paper's six classes, as DIR/images/*.png and DIR/annotations.json (COCO)");
  sub->add_option("--count", cmd->count, "--detection: number of scenes (default 32)");
  sub->add_option("--seed", cmd->seed, "--detection: random seed (default 1)");
  sub->add_flag("--no-text", cmd->no_text, "leave out the text");
  sub->callback([cmd] { run_chart(*cmd); });
}

}  // namespace lensopt::cli
