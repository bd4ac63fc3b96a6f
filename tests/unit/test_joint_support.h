// Helpers shared by the joint optimization's tests.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "lensopt/core/atomic_file.h"
#include "lensopt/detection/scenes.h"
#include "lensopt/joint/joint.h"

namespace lensopt::test {

// A temporary directory of this process (several test runs may share the machine's /tmp).
inline std::filesystem::path joint_temp_dir(const std::string& name) {
  return std::filesystem::temp_directory_path() / (name + "-" + std::to_string(::getpid()));
}

// The cells of a CSV file (the joint log: no quoted commas), row by row.
inline std::vector<std::vector<std::string>> csv_rows(const std::filesystem::path& path) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(read_file(path));
  std::string line;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream ls(line);
    std::string cell;
    while (std::getline(ls, cell, ',')) cells.push_back(cell);
    rows.push_back(cells);
  }
  return rows;
}

// Six generated 192 x 112 scenes (COCO) in dir/data; returns the annotations' path.
inline std::filesystem::path tiny_detection_dataset(const std::filesystem::path& dir) {
  SceneSetOptions s;
  s.count = 6;
  s.width = 192;
  s.height = 112;
  s.seed = 5;
  write_detection_scenes(dir / "data", s);
  return dir / "data" / "annotations.json";
}

// A joint detection run on tiny_detection_dataset(dir) that takes seconds: 64 px crops in
// batches of 2, 3 evaluation crops, coarse sampling, 2 + 2 steps, the log in dir/log.csv.
inline JointOptions tiny_detection_options(const std::filesystem::path& dir) {
  JointOptions o;
  o.task = "detection";
  o.data.annotations = tiny_detection_dataset(dir);
  o.data.crop_px = 64;
  o.data.batch_size = 2;
  o.data.eval_crops = 3;
  o.data.holdout_fraction = 0.34;
  o.imaging.sampling.rings = 4;
  o.imaging.sampling.fields = 5;
  o.imaging.res_factor = 2;
  o.design_sampling.rings = 4;
  o.design_sampling.fields = 3;
  o.task_options.learning_rate = 2e-3;
  o.constant_steps = 2;
  o.decay_steps = 2;
  o.verbose = false;
  o.log_csv = dir / "log.csv";
  return o;
}

// Writes a small TorchScript restorer (a residual 3x3 convolution; forward(images, targets)
// returns the MSE to the targets) to dir/restorer.pt and returns its path; empty without
// libtorch. Defined in test_joint_task.cpp, the one test file with libtorch headers.
std::filesystem::path write_test_torchscript_module(const std::filesystem::path& dir);

}  // namespace lensopt::test
