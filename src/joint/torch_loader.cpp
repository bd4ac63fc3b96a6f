// make_task, torch_available and is_torchscript_detector: the libtorch tasks, loaded from their
// module liblensopt_torch.so on first use (joint/torch_plugin.h says why).
//
// Where the module is looked for: core/plugin.h ($LENSOPT_TORCH_PLUGIN first).
#include <fmt/format.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>

#include "core/plugin.h"
#include "joint/torch_plugin.h"
#include "lensopt/core/error.h"
#include "lensopt/joint/detector.h"
#include "lensopt/joint/task.h"

namespace lensopt {
namespace {

struct TorchLoad {
  const TorchPlugin* plugin = nullptr;
  std::string error;  // why plugin is null
};

// The table fits this build: same interface number and the same sizes of the passed types.
std::string check_table(const void* table) {
  const auto* plugin = static_cast<const TorchPlugin*>(table);
  if (plugin->abi != kTorchPluginAbi || plugin->task_batch_size != sizeof(TaskBatch) ||
      plugin->task_options_size != sizeof(TaskOptions) || !plugin->make_task ||
      !plugin->is_torchscript_detector)
    return fmt::format(
        "built by another lensopt build (interface {} here, {} there); "
        "rebuild lensopt",
        kTorchPluginAbi, plugin->abi);
  return "";
}

TorchLoad find_plugin() {
#ifndef LENSOPT_WITH_TORCH
  return {
      nullptr,
      "lensopt was built without libtorch (LENSOPT_WITH_TORCH=OFF); rebuild with "
      "-DLENSOPT_WITH_TORCH=ON and Debian's libtorch-dev for the joint optimization's networks"};
#else
  const lensopt::LoadedPlugin loaded =
      load_plugin({kTorchPluginFile, "LENSOPT_TORCH_PLUGIN", kTorchPluginSymbol, check_table});
  if (loaded.table) return {static_cast<const TorchPlugin*>(loaded.table), ""};
  if (std::getenv("LENSOPT_TORCH_PLUGIN")) return {nullptr, loaded.error};
  return {nullptr,
          fmt::format("the joint optimization's networks need lensopt's libtorch module {}, "
                      "which could not be loaded (set LENSOPT_TORCH_PLUGIN to its path); {}",
                      kTorchPluginFile, loaded.error)};
#endif
}

const TorchLoad& plugin() {
  static std::once_flag once;
  static TorchLoad loaded;
  std::call_once(once, [] { loaded = find_plugin(); });
  return loaded;
}

}  // namespace

bool torch_available() {
  return plugin().plugin != nullptr;
}

void require_torch() {
  if (!plugin().plugin) throw Error(plugin().error);
}

std::unique_ptr<Task> make_task(const std::string& spec, const TaskOptions& options) {
  options.validate();
  if (!plugin().plugin) throw Error(fmt::format("task '{}': {}", spec, plugin().error));
  return plugin().plugin->make_task(spec, options);
}

bool is_torchscript_detector(const std::filesystem::path& model) {
  require_torch();
  return plugin().plugin->is_torchscript_detector(model);
}

}  // namespace lensopt
