// Helpers shared by the joint optimization's tests.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "lensopt/core/atomic_file.h"

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

// Writes a small TorchScript restorer (a residual 3x3 convolution; forward(images, targets)
// returns the MSE to the targets) to dir/restorer.pt and returns its path; empty without
// libtorch. Defined in test_joint_task.cpp, the one test file with libtorch headers.
std::filesystem::path write_test_torchscript_module(const std::filesystem::path& dir);

}  // namespace lensopt::test
