// load_plugin: the search order of core/plugin.h.
#include "core/plugin.h"

#include <dlfcn.h>
#include <fmt/format.h>

#include <cstdlib>
#include <system_error>

namespace lensopt {
namespace {

LoadedPlugin open_plugin(const std::filesystem::path& file, const PluginRequest& request) {
  void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) return {nullptr, file, fmt::format("{}: {}", file.string(), dlerror())};
  using Entry = const void* (*)();
  auto entry = reinterpret_cast<Entry>(dlsym(handle, request.symbol));
  if (!entry)
    return {
        nullptr, file,
        fmt::format("{}: no symbol {} (not this lensopt module)", file.string(), request.symbol)};
  const void* table = entry();
  const std::string why = !table          ? std::string("the module returned no interface")
                          : request.check ? request.check(table)
                                          : std::string();
  if (!why.empty()) return {nullptr, file, fmt::format("{}: {}", file.string(), why)};
  return {table, file, ""};
}

}  // namespace

std::vector<std::filesystem::path> plugin_candidates(const char* file) {
  namespace fs = std::filesystem;
  std::vector<fs::path> out;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) out.push_back(exe.parent_path() / file);
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&plugin_candidates), &info) != 0 && info.dli_fname &&
      info.dli_fname[0] != '\0') {
    const fs::path object = fs::weakly_canonical(fs::path(info.dli_fname), ec);
    if (!ec) out.push_back(object.parent_path() / file);
  }
#ifdef LENSOPT_PLUGIN_RELATIVE_DIR
  if (!exe.empty())
    out.push_back((exe.parent_path() / LENSOPT_PLUGIN_RELATIVE_DIR / file).lexically_normal());
#endif
#ifdef LENSOPT_PLUGIN_INSTALL_DIR
  out.push_back(fs::path(LENSOPT_PLUGIN_INSTALL_DIR) / file);
#endif
#ifdef LENSOPT_PLUGIN_BUILD_DIR
  out.push_back(fs::path(LENSOPT_PLUGIN_BUILD_DIR) / file);
#endif
  // The same file reached twice (the executable beside its library, the build tree): once.
  std::vector<fs::path> unique;
  for (const fs::path& p : out) {
    bool seen = false;
    for (const fs::path& q : unique) seen = seen || q == p;
    if (!seen) unique.push_back(p);
  }
  return unique;
}

LoadedPlugin load_plugin(const PluginRequest& request) {
  if (const char* env = std::getenv(request.env); env && env[0] != '\0') {
    LoadedPlugin loaded = open_plugin(env, request);
    if (!loaded.table) loaded.error = fmt::format("{}={}", request.env, loaded.error);
    return loaded;
  }
  std::string tried;
  for (const std::filesystem::path& file : plugin_candidates(request.file)) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec)) {
      tried += fmt::format("\n  {} (absent)", file.string());
      continue;
    }
    LoadedPlugin loaded = open_plugin(file, request);
    if (loaded.table) return loaded;
    tried += "\n  " + loaded.error;
  }
  return {nullptr, {}, fmt::format("tried:{}", tried)};
}

}  // namespace lensopt
