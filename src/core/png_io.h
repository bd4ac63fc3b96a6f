// PNG files through libpng, without OpenImageIO (core/image_plugin.h says why): the format lensopt
// renders, charts and plots in, read and written in the process that needs it.
//
// Samples: 8 or 16 bits, 1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA) channels, interleaved, top
// row first. Reading expands palettes and 1/2/4-bit grey to 8 bits and a tRNS chunk to an alpha
// channel; a sample s of b bits becomes the float s * (1 / (2^b - 1)). Writing clamps to [0, 1],
// scales by 2^b - 1 and rounds half up (NaN writes 0). Alpha is associated in memory (colour
// premultiplied on read, divided by alpha where alpha > 0 on write), as OpenImageIO did before.
//
// Compression: zlib level png_compression_level() (default kDefaultPngLevel = 3) with the "up" row
// filter: a 1280 x 720 render encodes in 28 ms instead of 95 ms at libpng's and OpenImageIO's
// defaults (level 6, every filter tried per row), for a file 13 % larger (BENCHMARKS.md, "Start-up
// without OpenImageIO"). LENSOPT_PNG_LEVEL=0..9 in the environment sets the level (9: every filter
// tried, the smallest files, about 4x the default's time).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace lensopt {

constexpr int kDefaultPngLevel = 3;

struct PngPixels {
  int width = 0;
  int height = 0;
  int channels = 0;
  int bit_depth = 8;  // 8 or 16
  std::vector<float> pixels;
};

// The zlib level in use: LENSOPT_PNG_LEVEL if set to 0..9, else set_png_compression_level's, else
// kDefaultPngLevel.
int png_compression_level();
void set_png_compression_level(int level);  // 0..9; -1 restores the default

// Decodes a PNG file into `out`; false with a one-line reason in `error` for a file that is not
// a PNG, is truncated or corrupt.
bool read_png(const std::filesystem::path& path, PngPixels& out, std::string& error);
// Reads only the header: width, height, channels (after expansion) and bit depth.
bool read_png_header(const std::filesystem::path& path, PngPixels& out, std::string& error);
// Decodes every row and discards it (a written file is checked complete); false with the reason.
bool verify_png(const std::filesystem::path& path, std::string& error);

// Encodes `pixels` (width * height * channels floats) as a PNG of `bit_depth` (8 or 16) bits to a
// file or to bytes; false with the reason (e.g. a full disk) in `error`.
bool write_png(const std::filesystem::path& path, int width, int height, int channels,
               int bit_depth, const float* pixels, std::string& error);
bool encode_png_bytes(int width, int height, int channels, int bit_depth, const float* pixels,
                      std::vector<unsigned char>& bytes, std::string& error);

// Whether a path ends in .png (any case).
bool is_png_path(const std::filesystem::path& path);

}  // namespace lensopt
