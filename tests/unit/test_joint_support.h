// Helpers shared by the joint optimization's tests.
#pragma once

#include <filesystem>

namespace lensopt::test {

// Writes a small TorchScript restorer (a residual 3x3 convolution; forward(images, targets)
// returns the MSE to the targets) to dir/restorer.pt and returns its path; empty without
// libtorch. Defined in test_joint_task.cpp, the one test file with libtorch headers.
std::filesystem::path write_test_torchscript_module(const std::filesystem::path& dir);

}  // namespace lensopt::test
