// Image header limits (lensopt/core/image_limits.h).
#include "lensopt/core/image_limits.h"

#include <fmt/format.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>

namespace lensopt {
namespace {
std::atomic<std::int64_t> g_max_pixels{0};
}  // namespace

std::int64_t max_image_pixels() {
  if (const char* env = std::getenv("LENSOPT_MAX_IMAGE_PIXELS"); env && *env) {
    char* end = nullptr;
    errno = 0;
    const long long value = std::strtoll(env, &end, 10);
    if (errno == 0 && end && *end == '\0' && value > 0) return value;
  }
  const std::int64_t set = g_max_pixels.load();
  return set > 0 ? set : kDefaultMaxImagePixels;
}

void set_max_image_pixels(std::int64_t pixels) {
  g_max_pixels.store(pixels > 0 ? pixels : 0);
}

std::string image_header_problem(std::int64_t width, std::int64_t height, std::uint64_t file_bytes,
                                 std::uint64_t min_file_bytes) {
  if (width <= 0 || height <= 0) return "";  // the readers report an empty image themselves
  const std::int64_t limit = max_image_pixels();
  // width, height < 2^31 (every format's header field), so the product fits.
  const std::int64_t pixels = width * height;
  if (file_bytes < min_file_bytes)
    return fmt::format(
        "its header says {} x {} pixels, but the file has {} bytes and that many "
        "pixels need at least {} (a corrupt, truncated or hostile header)",
        width, height, file_bytes, min_file_bytes);
  if (pixels > limit)
    return fmt::format(
        "its header says {} x {} = {} pixels, more than the limit of {} (raise it "
        "with --max-image-pixels or LENSOPT_MAX_IMAGE_PIXELS for a giant image)",
        width, height, pixels, limit);
  return "";
}

}  // namespace lensopt
