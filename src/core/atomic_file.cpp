#include "lensopt/core/atomic_file.h"

#include <fmt/format.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "lensopt/core/error.h"

namespace lensopt {
namespace {

std::filesystem::path temp_path_for(const std::filesystem::path& path) {
  static std::atomic<unsigned> counter{0};
  std::filesystem::path temp = path;
  temp.replace_filename(fmt::format(".{}.tmp{}-{}{}", path.stem().string(),
                                    static_cast<long>(::getpid()), counter++,
                                    path.extension().string()));
  return temp;
}

}  // namespace

void write_file_atomic_with(const std::filesystem::path& path,
                            const std::function<void(const std::filesystem::path&)>& write) {
  if (path.has_parent_path() && !std::filesystem::is_directory(path.parent_path())) {
    throw Error(SourceLocation{path.string()},
                fmt::format("cannot write: directory {} does not exist", path.parent_path().string()));
  }
  const std::filesystem::path temp = temp_path_for(path);
  try {
    write(temp);
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(temp, ignored);
    throw;
  }
  std::error_code ec;
  std::filesystem::rename(temp, path, ec);
  if (ec) {
    std::filesystem::remove(temp, ec);
    throw Error(SourceLocation{path.string()}, "cannot write: rename failed: " + ec.message());
  }
}

void write_file_atomic(const std::filesystem::path& path, std::string_view contents) {
  write_file_atomic_with(path, [&](const std::filesystem::path& temp) {
    std::ofstream out(temp, std::ios::binary);
    if (!out) {
      throw Error(SourceLocation{path.string()},
                  fmt::format("cannot write: {}", std::strerror(errno)));
    }
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    out.close();
    if (!out) throw Error(SourceLocation{path.string()}, "cannot write: short write");
  });
}

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw Error(SourceLocation{path.string()}, fmt::format("cannot read: {}", std::strerror(errno)));
  }
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

}  // namespace lensopt
