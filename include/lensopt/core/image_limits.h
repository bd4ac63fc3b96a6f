// Limits on image headers, checked before any pixel buffer is allocated (issue 34). A file's
// header states its width and height; decoding allocates for them (a float per sample) before it
// finds out the data is missing, so a 138-byte PNG whose header says 20000 x 20000 cost 1.2 GB and
// 5.6 s. A header is refused when
//   - the file is too small to hold that many pixels: deflate (PNG) never compresses more than
//     1032 : 1, so a PNG needs at least (raw bytes) / kMaxDeflateRatio bytes; for the formats
//     OpenImageIO reads (TIFF, EXR, JPEG, whose codecs differ) a file needs at least one byte per
//     kMaxPixelsPerByte pixels, far beyond what any of their codecs reaches on a real image; or
//   - width x height exceeds max_image_pixels() (default kDefaultMaxImagePixels = 16384^2, the
//     largest image lensopt makes; `render --max-image-pixels N` or LENSOPT_MAX_IMAGE_PIXELS=N
//     raise it for giant images).
#pragma once

#include <cstdint>
#include <string>

namespace lensopt {

inline constexpr std::int64_t kDefaultMaxImagePixels = 16384LL * 16384LL;
inline constexpr std::uint64_t kMaxDeflateRatio = 1032;
inline constexpr std::uint64_t kMaxPixelsPerByte = 65536;

// LENSOPT_MAX_IMAGE_PIXELS if set to a positive integer, else set_max_image_pixels's, else the
// default.
std::int64_t max_image_pixels();
void set_max_image_pixels(std::int64_t pixels);  // <= 0 restores the default

// Empty when a width x height image whose decoded data need at least `min_file_bytes` bytes of
// file may be decoded from a file of `file_bytes`; else the reason, naming the limit (what a
// read_image error says after the file name).
std::string image_header_problem(std::int64_t width, std::int64_t height, std::uint64_t file_bytes,
                                 std::uint64_t min_file_bytes);

}  // namespace lensopt
