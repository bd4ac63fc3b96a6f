// The unit tests' paths: the only test file compiled with the source tree's path
// (LENSOPT_SOURCE_DIR, LENSOPT_SHARED_DIR; CMakeLists.txt), so the other test objects do not
// depend on where the tree is and ccache shares them between work trees.
#include "test_support.h"

#include <cstdlib>
#include <filesystem>
#include <optional>

namespace lensopt::test {

std::filesystem::path source_dir() {
  return LENSOPT_SOURCE_DIR;
}

std::optional<std::filesystem::path> shared_dir() {
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
