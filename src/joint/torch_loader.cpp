// make_task, torch_available and is_torchscript_detector: the libtorch tasks, loaded from their
// module liblensopt_torch.so on first use (joint/torch_plugin.h says why).
//
// Where the module is looked for, first found wins:
//   1. $LENSOPT_TORCH_PLUGIN, if set (a path to the file; nothing else is tried);
//   2. beside the running executable (/proc/self/exe): the build tree's lensopt and lensopt_tests;
//   3. beside the shared object that holds this code (dladdr): the Python extension's directory;
//   4. <executable's directory>/<bindir to libdir>/lensopt: an install tree, wherever it was moved;
//   5. the install prefix's <libdir>/lensopt and the build tree's own path, as configured.
#include <dlfcn.h>
#include <fmt/format.h>

#include <filesystem>
#include <mutex>
#include <string>
#include <system_error>
#include <vector>

#include "joint/torch_plugin.h"
#include "lensopt/core/error.h"
#include "lensopt/joint/detector.h"
#include "lensopt/joint/task.h"

namespace lensopt {
namespace {

struct LoadedPlugin {
  const TorchPlugin* plugin = nullptr;
  std::string error;  // why plugin is null
};

std::vector<std::filesystem::path> plugin_candidates() {
  namespace fs = std::filesystem;
  std::vector<fs::path> out;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) out.push_back(exe.parent_path() / kTorchPluginFile);
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&plugin_candidates), &info) != 0 && info.dli_fname &&
      info.dli_fname[0] != '\0') {
    const fs::path object = fs::weakly_canonical(fs::path(info.dli_fname), ec);
    if (!ec) out.push_back(object.parent_path() / kTorchPluginFile);
  }
#ifdef LENSOPT_TORCH_PLUGIN_RELATIVE_DIR
  if (!exe.empty())
    out.push_back((exe.parent_path() / LENSOPT_TORCH_PLUGIN_RELATIVE_DIR / kTorchPluginFile)
                      .lexically_normal());
#endif
#ifdef LENSOPT_TORCH_PLUGIN_INSTALL_DIR
  out.push_back(fs::path(LENSOPT_TORCH_PLUGIN_INSTALL_DIR) / kTorchPluginFile);
#endif
#ifdef LENSOPT_TORCH_PLUGIN_BUILD_PATH
  out.push_back(fs::path(LENSOPT_TORCH_PLUGIN_BUILD_PATH));
#endif
  return out;
}

LoadedPlugin open_plugin(const std::filesystem::path& file) {
  // RTLD_LOCAL: the module's symbols (libtorch's included) do not take part in later lookups;
  // never dlclose'd (torch_plugin.h).
  void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) return {nullptr, fmt::format("{}: {}", file.string(), dlerror())};
  using Entry = const TorchPlugin* (*)();
  auto entry = reinterpret_cast<Entry>(dlsym(handle, kTorchPluginSymbol));
  if (!entry)
    return {nullptr, fmt::format("{}: no symbol {} (not a lensopt torch module)", file.string(),
                                 kTorchPluginSymbol)};
  const TorchPlugin* plugin = entry();
  if (!plugin || plugin->abi != kTorchPluginAbi || plugin->task_batch_size != sizeof(TaskBatch) ||
      plugin->task_options_size != sizeof(TaskOptions) || !plugin->make_task ||
      !plugin->is_torchscript_detector)
    return {nullptr,
            fmt::format("{}: built by another lensopt build (interface {} here, {} there); "
                        "rebuild lensopt",
                        file.string(), kTorchPluginAbi, plugin ? plugin->abi : 0)};
  return {plugin, ""};
}

LoadedPlugin find_plugin() {
#ifndef LENSOPT_WITH_TORCH
  return {
      nullptr,
      "lensopt was built without libtorch (LENSOPT_WITH_TORCH=OFF); rebuild with "
      "-DLENSOPT_WITH_TORCH=ON and Debian's libtorch-dev for the joint optimization's networks"};
#else
  if (const char* env = std::getenv("LENSOPT_TORCH_PLUGIN"); env && env[0] != '\0') {
    LoadedPlugin loaded = open_plugin(env);
    if (!loaded.plugin) loaded.error = "LENSOPT_TORCH_PLUGIN=" + loaded.error;
    return loaded;
  }
  std::string tried;
  for (const std::filesystem::path& file : plugin_candidates()) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec)) {
      tried += fmt::format("\n  {} (absent)", file.string());
      continue;
    }
    LoadedPlugin loaded = open_plugin(file);
    if (loaded.plugin) return loaded;
    tried += "\n  " + loaded.error;
  }
  return {nullptr,
          fmt::format("the joint optimization's networks need lensopt's libtorch module {}, "
                      "which could not be loaded (set LENSOPT_TORCH_PLUGIN to its path); "
                      "tried:{}",
                      kTorchPluginFile, tried)};
#endif
}

const LoadedPlugin& plugin() {
  static std::once_flag once;
  static LoadedPlugin loaded;
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
