// Lens files by extension: the one entry point that reads or writes a lens whatever its format.
//   .toml          native TOML (lens/lens_io.h), read and written losslessly
//   .yml / .yaml   the paper's YAML (lens/lens_io.h), read only
//   .zmx           Zemax OpticStudio (formats/zmx.h), read and written
// It sits in formats/ (above paraxial/ and trace/) because the Zemax reader computes the paraxial
// EFL and the stop's pupil; the lens module reads and writes only its own formats.
#pragma once

#include <filesystem>

#include "lensopt/lens/lens.h"

namespace lensopt {

// Reads a lens by file extension (case-insensitive). A .zmx import's warnings (lines lensopt
// does not model) go to stderr. Throws Error with file:line:column; an unknown extension is an
// Error naming the file.
Lens read_lens(const std::filesystem::path& path);

// Writes a lens as .toml or .zmx by extension, atomically; another extension is an Error.
void write_lens(const Lens& lens, const std::filesystem::path& path);

}  // namespace lensopt
