// Helpers shared by the unit tests.
#pragma once

#include <doctest/doctest.h>

#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>

namespace lensopt::test {

// The project's source folder (lenses/, catalogs/).
inline std::filesystem::path source_dir() { return LENSOPT_SOURCE_DIR; }

// ../shared (reference data), or nullopt when it is absent: tests that need it then skip,
// saying so with MESSAGE.
inline std::optional<std::filesystem::path> shared_dir() {
  std::filesystem::path dir;
  if (const char* env = std::getenv("LENSOPT_SHARED_DIR")) {
    dir = env;
  } else {
    dir = LENSOPT_SHARED_DIR;
  }
  if (std::filesystem::is_directory(dir / "data")) return dir;
  return std::nullopt;
}

}  // namespace lensopt::test

// Skips the rest of a test case, with a message, when ../shared is absent.
#define LENSOPT_REQUIRE_SHARED(var)                                               \
  const auto var##_opt = ::lensopt::test::shared_dir();                          \
  if (!var##_opt) {                                                               \
    MESSAGE("skipped: ../shared is absent (reference data not available)");       \
    return;                                                                       \
  }                                                                               \
  const std::filesystem::path var = *var##_opt
