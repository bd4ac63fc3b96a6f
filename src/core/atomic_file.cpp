// The output layer (include/lensopt/core/atomic_file.h).
#include "lensopt/core/atomic_file.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>
#include <vector>

#include "core/image_plugin.h"
#include "core/png_io.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/core/text.h"

namespace lensopt {
namespace {

namespace fs = std::filesystem;

fs::path temp_path_for(const fs::path& path) {
  static std::atomic<unsigned> counter{0};
  fs::path temp = path;
  temp.replace_filename(fmt::format(".{}.tmp{}-{}{}", path.stem().string(),
                                    static_cast<long>(::getpid()), counter++,
                                    path.extension().string()));
  return temp;
}

[[noreturn]] void fail(const fs::path& path, const std::string& what) {
  throw Error(SourceLocation{path.string()}, "cannot write: " + what);
}

// fsync(2) of a file by path; `what` failed -> Error naming `target`.
void sync_file(const fs::path& file, const fs::path& target) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail(target, fmt::format("cannot reopen the written file: {}", std::strerror(errno)));
  if (::fsync(fd) != 0 && errno != EINVAL && errno != EROFS) {
    const int e = errno;
    ::close(fd);
    fail(target, fmt::format("fsync failed: {}", std::strerror(e)));
  }
  ::close(fd);
}

// Best effort: makes the rename itself durable.
void sync_dir(const fs::path& dir) {
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

// Image encoders do not all report a short write (a full disk can leave a truncated PNG that was
// "written" without error), so an image is decoded again before it replaces the target.
bool is_image_path(const fs::path& path) {
  const std::string ext = lower_extension(path);
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".tif" || ext == ".tiff" ||
         ext == ".exr";
}

// A PNG through libpng; the other formats through the OpenImageIO module (which wrote them).
void verify_image(const fs::path& temp, const fs::path& target) {
  std::string error;
  bool ok = false;
  if (is_png_path(temp)) {
    ok = verify_png(temp, error);
  } else {
    const ImagePlugin& plugin = image_plugin(fmt::format("{}: cannot check the written {} file",
                                                         target.string(), lower_extension(temp)));
    ok = plugin.verify(temp.string(), error);
  }
  if (!ok)
    fail(target, fmt::format("the written image is incomplete or does not decode ({}); is the "
                             "disk full?",
                             error));
}

fs::path folder_of(const fs::path& path) {
  return path.has_parent_path() ? path.parent_path() : fs::path(".");
}

}  // namespace

void write_file_atomic_with(const fs::path& path,
                            const std::function<void(const fs::path&)>& write) {
  std::error_code ec;
  const fs::path dir = folder_of(path);
  if (!fs::is_directory(dir, ec))
    fail(path, fmt::format("directory {} does not exist", dir.string()));
  if (fs::is_directory(path, ec)) fail(path, "it is a directory");
  const fs::path temp = temp_path_for(path);
  try {
    write(temp);
    // Verify: the writer produced a non-empty regular file and it reached the disk.
    const auto size = fs::file_size(temp, ec);
    if (ec) fail(path, fmt::format("the writer left no file ({})", ec.message()));
    if (size == 0) fail(path, "the writer produced an empty file");
    if (is_image_path(path)) verify_image(temp, path);
    sync_file(temp, path);
  } catch (...) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    throw;
  }
  fs::rename(temp, path, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    fail(path, "rename failed: " + ec.message());
  }
  sync_dir(dir);
}

void write_file_atomic(const fs::path& path, std::string_view contents) {
  std::error_code ec;
  const fs::path dir = folder_of(path);
  if (!fs::is_directory(dir, ec))
    fail(path, fmt::format("directory {} does not exist", dir.string()));
  if (fs::is_directory(path, ec)) fail(path, "it is a directory");
  const fs::path temp = temp_path_for(path);
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) fail(path, std::strerror(errno));
  auto give_up = [&](const std::string& what) {
    ::close(fd);
    std::error_code ignored;
    fs::remove(temp, ignored);
    fail(path, what);
  };
  std::size_t done = 0;
  while (done < contents.size()) {
    const ssize_t n = ::write(fd, contents.data() + done, contents.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      give_up(fmt::format("{} after {} of {} bytes", n < 0 ? std::strerror(errno) : "short write",
                          done, contents.size()));
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 && errno != EINVAL && errno != EROFS)
    give_up(fmt::format("fsync failed: {}", std::strerror(errno)));
  if (::close(fd) != 0) {
    const int e = errno;
    std::error_code ignored;
    fs::remove(temp, ignored);
    fail(path, fmt::format("close failed: {}", std::strerror(e)));
  }
  fs::rename(temp, path, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    fail(path, "rename failed: " + ec.message());
  }
  sync_dir(dir);
}

bool same_file(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  if (fs::exists(a, ec) && fs::exists(b, ec)) {
    const bool eq = fs::equivalent(a, b, ec);
    if (!ec) return eq;
  }
  const fs::path ca = fs::weakly_canonical(a, ec);
  const fs::path cb = fs::weakly_canonical(b, ec);
  return ca.lexically_normal() == cb.lexically_normal();
}

void check_output_file(const fs::path& path, const std::vector<fs::path>& inputs) {
  const SourceLocation where{path.string()};
  if (path.empty()) throw Error("cannot write: an empty output path");
  std::error_code ec;
  const fs::path dir = folder_of(path);
  if (!fs::is_directory(dir, ec))
    throw Error(where, fmt::format("cannot write: directory {} does not exist", dir.string()));
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    throw Error(
        where, fmt::format("cannot write in directory {}: {}", dir.string(), std::strerror(errno)));
  if (fs::is_directory(path, ec)) throw Error(where, "cannot write: it is a directory");
  for (const fs::path& input : inputs) {
    if (!input.empty() && same_file(path, input))
      throw Error(where, fmt::format("refusing to write an output over an input of the same run "
                                     "({}); choose another output path",
                                     input.string()));
  }
}

void check_output_dir(const fs::path& dir, const std::vector<fs::path>& inputs) {
  const SourceLocation where{dir.string()};
  if (dir.empty()) throw Error("cannot write: an empty output folder");
  for (const fs::path& input : inputs) {
    if (!input.empty() && same_file(dir, input))
      throw Error(where, fmt::format("refusing to write into an input of the same run ({}); "
                                     "choose another output folder",
                                     input.string()));
  }
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    throw Error(where, "cannot write output: it exists and is not a directory");
  fs::create_directories(dir, ec);
  if (ec) throw Error(where, fmt::format("cannot create the output directory: {}", ec.message()));
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    throw Error(where,
                fmt::format("cannot write in the output directory: {}", std::strerror(errno)));
}

bool is_temp_file_name(const std::string& name, long* pid) {
  static const std::regex kTemp(R"(^\..*\.tmp([0-9]+)-[0-9]+(\.[^.]*)?$)");
  std::smatch m;
  if (!std::regex_match(name, m, kTemp)) return false;
  if (pid) *pid = std::stol(m[1].str());
  return true;
}

int remove_stale_temp_files(const fs::path& dir, bool recursive) {
  int removed = 0;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return 0;
  auto visit = [&](const fs::directory_entry& e) {
    long pid = 0;
    if (!e.is_regular_file(ec) || !is_temp_file_name(e.path().filename().string(), &pid)) return;
    const bool alive =
        pid == ::getpid() || (::kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM);
    if (alive) return;
    if (fs::remove(e.path(), ec)) ++removed;
  };
  if (recursive) {
    for (fs::recursive_directory_iterator
             it(dir, fs::directory_options::skip_permission_denied, ec),
         end;
         it != end; it.increment(ec)) {
      if (ec) break;
      visit(*it);
    }
  } else {
    for (fs::directory_iterator it(dir, ec), end; it != end; it.increment(ec)) {
      if (ec) break;
      visit(*it);
    }
  }
  return removed;
}

std::string read_file(const fs::path& path) {
  // A folder opens as a stream on Linux and reads as empty text: every format would then report
  // a missing section instead of the user's mistake.
  std::error_code ec;
  if (fs::is_directory(path, ec))
    throw Error(SourceLocation{path.string()}, "cannot read: it is a directory, not a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw Error(SourceLocation{path.string()},
                fmt::format("cannot read: {}", std::strerror(errno)));
  }
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

}  // namespace lensopt
