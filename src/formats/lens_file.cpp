// Lens files by extension (formats/lens_file.h).
#include "lensopt/formats/lens_file.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <string>
#include <utility>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/text.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/paraxial/solves.h"

namespace lensopt {
namespace {

Lens read_lens_as_written(const std::filesystem::path& path, const std::string& extension) {
  if (extension == ".toml") return parse_lens_toml(read_file(path), path.string());
  if (extension == ".yml" || extension == ".yaml")
    return parse_lens_yaml(read_file(path), path.string());
  // Zemax import (formats/zmx.h); its warnings (ignored lines) go to stderr.
  ZmxImport imported = read_zmx(path);
  for (const std::string& warning : imported.warnings)
    fmt::print(stderr, "lensopt: warning: {}\n", warning);
  return std::move(imported.lens);
}

}  // namespace

Lens read_lens(const std::filesystem::path& path) {
  const std::string extension = lower_extension(path);
  if (extension == ".toml" || extension == ".yml" || extension == ".yaml" || extension == ".zmx")
    // Pickups and solves evaluated on reading (paraxial/solves.h), so every consumer sees
    // the values they define.
    return with_solves(read_lens_as_written(path, extension));
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw Error(SourceLocation{path.string()},
                "it is a directory, not a lens file (.toml, the paper's .yml/.yaml or .zmx)");
  throw Error(SourceLocation{path.string()},
              fmt::format("unknown lens file type '{}'; lensopt reads .toml, the paper's "
                          ".yml/.yaml and Zemax .zmx",
                          path.extension().string()));
}

void write_lens(const Lens& lens, const std::filesystem::path& path) {
  const std::string extension = lower_extension(path);
  if (extension == ".zmx") return write_zmx(lens, path);
  if (extension != ".toml")
    throw Error(SourceLocation{path.string()},
                fmt::format("cannot write a lens as '{}'; lensopt writes lenses as .toml or "
                            "Zemax .zmx",
                            path.extension().string()));
  write_lens_toml(lens, path);
}

}  // namespace lensopt
