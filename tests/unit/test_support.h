// Helpers shared by the unit tests.
#pragma once

#include <doctest/doctest.h>
#include <stdlib.h>  // mkdtemp

#include <cstdlib>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>

namespace lensopt::test {

// The project's source folder (lenses/, catalogs/). Defined in test_support.cpp, the one file
// compiled with the source tree's path, so that ccache shares every other test object between
// work trees and clones.
std::filesystem::path source_dir();

// ../shared (reference data), or nullopt when it is absent: tests that need it then skip,
// saying so with MESSAGE. LENSOPT_SHARED_DIR in the environment takes precedence.
std::optional<std::filesystem::path> shared_dir();

// This process's own temporary folder, made by mkdtemp on first use and removed at exit: tests
// put their files under it, never under a fixed name in /tmp, so concurrent runs (ctest -j,
// several work trees) never share a folder.
inline const std::filesystem::path& temp_root() {
  struct Root {
    std::filesystem::path path;
    Root() {
      std::string pattern =
          (std::filesystem::temp_directory_path() / "lensopt-unit-XXXXXX").string();
      if (!::mkdtemp(pattern.data()))
        throw std::runtime_error("cannot make a temporary folder from " + pattern);
      path = pattern;
    }
    ~Root() {
      std::error_code ignored;
      std::filesystem::remove_all(path, ignored);
    }
  };
  static const Root root;
  return root.path;
}

}  // namespace lensopt::test

// Skips the rest of a test case, with a message, when ../shared is absent.
#define LENSOPT_REQUIRE_SHARED(var)                                         \
  const auto var##_opt = ::lensopt::test::shared_dir();                     \
  if (!var##_opt) {                                                         \
    MESSAGE("skipped: ../shared is absent (reference data not available)"); \
    return;                                                                 \
  }                                                                         \
  const std::filesystem::path var = *var##_opt
