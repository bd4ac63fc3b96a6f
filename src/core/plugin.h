// Run-time modules (plugins): shared objects built beside the executable that lensopt loads with
// dlopen on first use, so that a heavy dependency is mapped only by the commands that need it.
// Today: liblensopt_torch.so (libtorch, joint/torch_plugin.h) and liblensopt_oiio.so
// (OpenImageIO, core/image_plugin.h). One implementation of where a module is looked for:
//
//   1. $<env>, if set (a path to the file; nothing else is tried);
//   2. beside the running executable (/proc/self/exe): the build tree's lensopt and lensopt_tests;
//   3. beside the shared object that holds this code (dladdr): the Python extension's directory;
//   4. <executable's directory>/<bindir to libdir>/lensopt: an install tree, wherever it was moved;
//   5. the install prefix's <libdir>/lensopt and the build tree, as configured (CMake).
//
// A module exports one C function, `symbol`, returning a pointer to a table of function pointers
// whose first member is an int ABI number; `check` compares the table with the caller's build.
// Modules are opened RTLD_NOW | RTLD_LOCAL (their symbols, and their dependencies', take no part
// in later lookups) and never closed, so tables, exceptions and virtual calls from a module stay
// valid for the life of the process.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace lensopt {

struct PluginRequest {
  const char* file = nullptr;    // file name, e.g. "liblensopt_oiio.so"
  const char* env = nullptr;     // environment variable overriding the search, e.g. "LENSOPT_..."
  const char* symbol = nullptr;  // the entry point: extern "C" const void* symbol()
  // Empty when the table fits this build, else why not (e.g. "interface 2 here, 1 there").
  std::function<std::string(const void* table)> check;
};

struct LoadedPlugin {
  const void* table = nullptr;  // what the entry point returned, checked
  std::filesystem::path file;   // the file it came from
  std::string error;            // why table is null: every candidate tried, one a line
};

// The candidate paths of a module file, in the order above (without the environment variable).
std::vector<std::filesystem::path> plugin_candidates(const char* file);

// Loads the first candidate that opens and passes `check`; not cached (callers keep the result).
LoadedPlugin load_plugin(const PluginRequest& request);

}  // namespace lensopt
