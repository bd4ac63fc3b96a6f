// Atomic output: write to a temporary file beside the target, then rename(2) over it, so a
// reader never sees a half-written lens, image or report.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <string_view>

namespace lensopt {

// Writes `contents` to `path` atomically. Throws Error naming the path on failure.
void write_file_atomic(const std::filesystem::path& path, std::string_view contents);

// Calls `write(temp_path)` to produce the file, then renames it over `path`. The temporary keeps
// the target's extension (so writers that pick a format by extension still work) and is removed
// if `write` throws.
void write_file_atomic_with(const std::filesystem::path& path,
                            const std::function<void(const std::filesystem::path&)>& write);

// Reads a whole file. Throws Error naming the path if it cannot be read.
std::string read_file(const std::filesystem::path& path);

}  // namespace lensopt
