// Image headers are checked against the pixel limit and the file's size before any pixel buffer
// is allocated (issue 34: a 138-byte PNG whose header said 20000 x 20000 cost 1.2 GB and 5.6 s).
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/image_plugin.h"
#include "core/png_io.h"
#include "error_checks.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/image_limits.h"
#include "lensopt/render/image.h"
#include "test_support.h"

namespace test_render_image_limits {

using namespace lensopt;
namespace fs = std::filesystem;

namespace {

std::uint32_t crc32_of(const unsigned char* data, std::size_t n) {
  std::uint32_t crc = 0xffffffffu;
  for (std::size_t i = 0; i < n; ++i) {
    crc ^= data[i];
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

void put32(std::string& bytes, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>((v >> (24 - 8 * i)) & 0xff);
}

// A valid small PNG whose IHDR then says width x height (CRC fixed): the data stays 8 x 8.
fs::path lying_png(const fs::path& dir, std::uint32_t width, std::uint32_t height) {
  fs::create_directories(dir);
  const fs::path path = dir / ("lie_" + std::to_string(width) + ".png");
  std::vector<float> pixels(8 * 8 * 3, 0.5f);
  std::string error;
  REQUIRE(write_png(path, 8, 8, 3, 8, pixels.data(), error));
  std::string bytes = read_file(path);
  // Signature (8), IHDR length (4), "IHDR" (4), width at 16, height at 20, CRC at 29.
  REQUIRE(bytes.substr(12, 4) == "IHDR");
  put32(bytes, 16, width);
  put32(bytes, 20, height);
  put32(bytes, 29, crc32_of(reinterpret_cast<const unsigned char*>(bytes.data()) + 12, 17));
  write_file_atomic(path, bytes);
  return path;
}

std::string error_of(const fs::path& path) {
  return lensopt::test::error_of([&] { read_image(path); });
}

using lensopt::test::check_contains;

}  // namespace

TEST_CASE("render image limits: a PNG header larger than its file is refused before decoding") {
  const fs::path dir = test::temp_root() / "image_limits";
  const std::vector<std::uint32_t> sides = {20000, 50000};
  std::vector<fs::path> files;
  for (std::uint32_t side : sides) files.push_back(lying_png(dir, side, side));
  const auto t0 = std::chrono::steady_clock::now();
  for (std::size_t k = 0; k < files.size(); ++k) {
    const fs::path& path = files[k];
    const std::string e = error_of(path);
    check_contains(e, path.string());
    check_contains(
        e, fmt::format("its header says {} x {} pixels, but the file has", sides[k], sides[k]));
    // read_png itself checks too (any caller), without allocating for the header's size.
    PngPixels png;
    std::string error;
    CHECK_FALSE(read_png(path, png, error));
    check_contains(error, "a corrupt, truncated or hostile header");
    CHECK(png.pixels.empty());
  }
  // Reading them took seconds and gigabytes before; now only the headers are read.
  CHECK(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < 1.0);
  // The honest 8 x 8 file reads.
  const fs::path ok = lying_png(dir, 8, 8);
  CHECK(read_image(ok).image.width == 8);
}

TEST_CASE("render image limits: the pixel limit refuses large headers; it can be raised") {
  const fs::path dir = test::temp_root() / "image_pixel_limit";
  fs::create_directories(dir);
  FloatImage image(32, 16, 3, 0.25f);
  std::vector<fs::path> files = {dir / "a.png"};
  if (image_plugin_available())
    files.push_back(dir / "a.tif");
  else
    MESSAGE("skipped the TIFF case: OpenImageIO module not available");
  for (const fs::path& path : files) {
    write_image(path, image);
    set_max_image_pixels(511);
    const std::string e = error_of(path);
    check_contains(e, "its header says 32 x 16 = 512 pixels, more than the limit of 511");
    check_contains(e, "--max-image-pixels");
    set_max_image_pixels(512);
    CHECK(read_image(path).image.width == 32);
    set_max_image_pixels(0);  // the default again
    CHECK(max_image_pixels() == kDefaultMaxImagePixels);
  }
}

}  // namespace test_render_image_limits
