// The interface between the joint module and its libtorch tasks.
//
// The libtorch tasks (src/joint/torch/) are built as a module of their own, liblensopt_torch.so,
// which the joint module loads with dlopen the first time a task is made (torch_loader.cpp). So
// the lensopt executable, the unit tests' binary and the Python extension do not link libtorch:
// every command but `optimize --joint` starts without loading it (about 0.5 s of CPU and 100 MB
// of mappings saved per process).
//
// The module exports one C symbol, kTorchPluginSymbol, returning a TorchPlugin. Both sides are
// built by the same CMake build with the same compiler and standard library, so C++ types
// (std::string, std::unique_ptr<Task>, lensopt::Error) cross the boundary; the ABI number and the
// sizes below catch a module left over from another build. The module links the lensopt
// libraries it needs statically, with their symbols hidden (-Wl,--exclude-libs,ALL), and is never
// unloaded, so exceptions and virtual calls into it stay valid for the life of the process.
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "lensopt/joint/task.h"

namespace lensopt {

// Raise whenever TorchPlugin or the types it passes (task.h) change.
constexpr int kTorchPluginAbi = 1;

struct TorchPlugin {
  int abi = 0;                        // kTorchPluginAbi of the module's build
  std::size_t task_batch_size = 0;    // sizeof(TaskBatch) there
  std::size_t task_options_size = 0;  // sizeof(TaskOptions) there
  // make_task of task.h (options already validated by the caller).
  std::unique_ptr<Task> (*make_task)(const std::string& spec, const TaskOptions& options) = nullptr;
  // is_torchscript_detector of detector.h.
  bool (*is_torchscript_detector)(const std::filesystem::path& model) = nullptr;
};

// The module's entry point: extern "C" const TorchPlugin* lensopt_torch_plugin();
inline constexpr const char* kTorchPluginSymbol = "lensopt_torch_plugin";
// The module's file name, looked for beside the executable (or the library that holds this
// code), in <libdir>/lensopt of the install, and in the build tree (torch_loader.cpp).
inline constexpr const char* kTorchPluginFile = "liblensopt_torch.so";

}  // namespace lensopt
