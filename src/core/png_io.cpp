// PNG through libpng (core/png_io.h). libpng reports errors by longjmp to the setjmp of the
// function that called it: those functions hold only plain locals across the jump, and every
// buffer they fill was sized before it.
#include "core/png_io.h"

#include <png.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "lensopt/core/image_limits.h"
#include "lensopt/core/text.h"

namespace lensopt {
namespace {

std::atomic<int> g_level{-1};

// libpng's error callback: keeps the message and jumps back to the caller's setjmp.
struct ErrorSink {
  char message[256] = {0};
};

void on_error(png_structp png, png_const_charp message) {
  auto* sink = static_cast<ErrorSink*>(png_get_error_ptr(png));
  if (sink) std::snprintf(sink->message, sizeof(sink->message), "%s", message);
  png_longjmp(png, 1);
}

void on_warning(png_structp, png_const_charp) {}

std::string reason(const ErrorSink& sink, const char* fallback) {
  return sink.message[0] ? std::string(sink.message) : std::string(fallback);
}

// A FILE closed on scope exit.
struct File {
  std::FILE* f = nullptr;
  ~File() {
    if (f) std::fclose(f);
  }
};

enum class ReadMode { kHeader, kPixels, kVerify };

// The reading transforms of png_io.h; returns channels after expansion.
void set_read_transforms(png_structp png, png_infop info) {
  const int colour = png_get_color_type(png, info);
  const int depth = png_get_bit_depth(png, info);
  if (colour == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (colour == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (png_get_valid(png, info, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
}

bool read_impl(const std::filesystem::path& path, PngPixels& out, std::string& error,
               ReadMode mode) {
  File file;
  file.f = std::fopen(path.c_str(), "rb");
  if (!file.f) {
    error = std::strerror(errno);
    return false;
  }
  unsigned char signature[8];
  if (std::fread(signature, 1, 8, file.f) != 8 || png_sig_cmp(signature, 0, 8) != 0) {
    error = "not a PNG file (no PNG signature)";
    return false;
  }
  ErrorSink sink;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &sink, on_error, on_warning);
  if (!png) {
    error = "libpng: out of memory";
    return false;
  }
  png_infop info = png_create_info_struct(png);
  std::vector<unsigned char> bytes;
  std::vector<png_bytep> rows;
  if (!info || setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
    error = reason(sink, "corrupt PNG");
    return false;
  }
  png_init_io(png, file.f);
  png_set_sig_bytes(png, 8);
  // Large images are fine (lensopt renders up to 16384 x 16384): raise libpng's default limits.
  png_set_user_limits(png, 0x7fffffff, 0x7fffffff);
  png_read_info(png, info);
  if (mode != ReadMode::kHeader) {
    // Before any buffer is sized (core/image_limits.h): the pixel limit, and the file must be
    // large enough for its header's raw rows (filter byte + packed samples) at deflate's ratio.
    const std::uint64_t w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    const std::uint64_t bits =
        std::uint64_t{png_get_channels(png, info)} * std::uint64_t{png_get_bit_depth(png, info)};
    const std::uint64_t raw = h * (1 + (w * bits + 7) / 8);
    std::error_code size_error;
    const std::uint64_t file_bytes = std::filesystem::file_size(path, size_error);
    const std::string problem =
        image_header_problem(static_cast<std::int64_t>(w), static_cast<std::int64_t>(h),
                             size_error ? 0 : file_bytes, raw / kMaxDeflateRatio);
    if (!problem.empty()) {
      png_destroy_read_struct(&png, &info, nullptr);
      error = problem;
      return false;
    }
  }
  set_read_transforms(png, info);
  out.width = static_cast<int>(png_get_image_width(png, info));
  out.height = static_cast<int>(png_get_image_height(png, info));
  out.channels = png_get_channels(png, info);
  out.bit_depth = png_get_bit_depth(png, info);
  if (mode == ReadMode::kHeader || out.width <= 0 || out.height <= 0) {
    png_destroy_read_struct(&png, &info, nullptr);
    return true;
  }
  const std::size_t row_bytes = png_get_rowbytes(png, info);
  const bool whole = mode == ReadMode::kPixels || png_get_interlace_type(png, info) != 0;
  bytes.resize(row_bytes * (whole ? out.height : 1));
  if (whole) {
    rows.resize(out.height);
    for (int y = 0; y < out.height; ++y) rows[y] = bytes.data() + row_bytes * y;
    png_read_image(png, rows.data());
  } else {
    for (int y = 0; y < out.height; ++y) png_read_row(png, bytes.data(), nullptr);
  }
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  if (mode == ReadMode::kVerify) return true;

  const std::size_t n = static_cast<std::size_t>(out.width) * out.height * out.channels;
  out.pixels.resize(n);
  if (out.bit_depth == 16) {
    const float scale = 1.0f / 65535.0f;
    for (std::size_t i = 0; i < n; ++i)
      out.pixels[i] = static_cast<float>((bytes[2 * i] << 8) | bytes[2 * i + 1]) * scale;
  } else {
    const float scale = 1.0f / 255.0f;
    for (std::size_t i = 0; i < n; ++i) out.pixels[i] = static_cast<float>(bytes[i]) * scale;
  }
  // Associated alpha in memory.
  if (out.channels == 2 || out.channels == 4) {
    const int a = out.channels - 1;
    for (std::size_t p = 0; p < n; p += out.channels)
      for (int c = 0; c < a; ++c) out.pixels[p + c] *= out.pixels[p + a];
  }
  return true;
}

// Where encoded bytes go: a FILE or a vector.
struct Sink {
  std::FILE* file = nullptr;
  std::vector<unsigned char>* bytes = nullptr;
  bool failed = false;
};

void on_write(png_structp png, png_bytep data, png_size_t length) {
  auto* sink = static_cast<Sink*>(png_get_io_ptr(png));
  if (sink->bytes) {
    sink->bytes->insert(sink->bytes->end(), data, data + length);
  } else if (std::fwrite(data, 1, length, sink->file) != length) {
    sink->failed = true;
    png_error(png, std::strerror(errno ? errno : EIO));
  }
}

void on_flush(png_structp png) {
  auto* sink = static_cast<Sink*>(png_get_io_ptr(png));
  if (sink->file) std::fflush(sink->file);
}

// One row of samples from floats: clamp, scale, round half up; big-endian for 16 bits.
void quantize_row(const float* in, int width, int channels, int bit_depth, unsigned char* out) {
  const float scale = bit_depth == 16 ? 65535.0f : 255.0f;
  const bool alpha = channels == 2 || channels == 4;
  const int a = channels - 1;
  for (int x = 0; x < width; ++x) {
    const float* px = in + static_cast<std::size_t>(x) * channels;
    for (int c = 0; c < channels; ++c) {
      float v = px[c];
      if (alpha && c != a && px[a] > 0.0f) v /= px[a];  // back to unassociated alpha
      float s = std::isnan(v) ? 0.0f : std::clamp(v, 0.0f, 1.0f) * scale + 0.5f;
      s = std::min(s, scale);
      const unsigned q = static_cast<unsigned>(s);
      const std::size_t i = static_cast<std::size_t>(x) * channels + c;
      if (bit_depth == 16) {
        out[2 * i] = static_cast<unsigned char>(q >> 8);
        out[2 * i + 1] = static_cast<unsigned char>(q & 0xff);
      } else {
        out[i] = static_cast<unsigned char>(q);
      }
    }
  }
}

bool encode(Sink& sink, int width, int height, int channels, int bit_depth, const float* pixels,
            std::string& error) {
  if (width <= 0 || height <= 0 || channels < 1 || channels > 4 ||
      (bit_depth != 8 && bit_depth != 16)) {
    error = "cannot encode a PNG of this shape";
    return false;
  }
  static constexpr int kColour[5] = {0, PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_GRAY_ALPHA,
                                     PNG_COLOR_TYPE_RGB, PNG_COLOR_TYPE_RGB_ALPHA};
  const int level = png_compression_level();
  ErrorSink errors;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &errors, on_error, on_warning);
  if (!png) {
    error = "libpng: out of memory";
    return false;
  }
  png_infop info = png_create_info_struct(png);
  std::vector<unsigned char> row(static_cast<std::size_t>(width) * channels * (bit_depth / 8));
  if (!info || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, info ? &info : nullptr);
    error = reason(errors, "cannot encode the PNG");
    return false;
  }
  png_set_write_fn(png, &sink, on_write, on_flush);
  png_set_compression_level(png, level);
  // Level 9 asks for the smallest file: libpng's adaptive choice of filter per row; below, the
  // "up" filter alone (the cheapest; on a render as small as "paeth" within 1 %, BENCHMARKS.md).
  png_set_filter(png, PNG_FILTER_TYPE_BASE, level >= 9 ? PNG_ALL_FILTERS : PNG_FILTER_UP);
  png_set_IHDR(png, info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height),
               bit_depth, kColour[channels], PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  const std::size_t stride = static_cast<std::size_t>(width) * channels;
  for (int y = 0; y < height; ++y) {
    quantize_row(pixels + stride * y, width, channels, bit_depth, row.data());
    png_write_row(png, row.data());
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

int png_compression_level() {
  if (const char* env = std::getenv("LENSOPT_PNG_LEVEL");
      env && env[0] >= '0' && env[0] <= '9' && env[1] == '\0')
    return env[0] - '0';
  const int set = g_level.load();
  return set >= 0 ? set : kDefaultPngLevel;
}

void set_png_compression_level(int level) {
  g_level.store(level >= 0 && level <= 9 ? level : -1);
}

bool read_png(const std::filesystem::path& path, PngPixels& out, std::string& error) {
  return read_impl(path, out, error, ReadMode::kPixels);
}

bool read_png_header(const std::filesystem::path& path, PngPixels& out, std::string& error) {
  return read_impl(path, out, error, ReadMode::kHeader);
}

bool verify_png(const std::filesystem::path& path, std::string& error) {
  PngPixels header;
  return read_impl(path, header, error, ReadMode::kVerify);
}

bool write_png(const std::filesystem::path& path, int width, int height, int channels,
               int bit_depth, const float* pixels, std::string& error) {
  File file;
  file.f = std::fopen(path.c_str(), "wb");
  if (!file.f) {
    error = std::strerror(errno);
    return false;
  }
  Sink sink;
  sink.file = file.f;
  if (!encode(sink, width, height, channels, bit_depth, pixels, error)) return false;
  std::FILE* f = file.f;
  file.f = nullptr;
  const bool flushed = std::fflush(f) == 0 && !std::ferror(f);
  int e = flushed ? 0 : errno;
  const bool closed = std::fclose(f) == 0;
  if (!closed && e == 0) e = errno;
  if (!flushed || !closed) {
    error = std::strerror(e ? e : EIO);
    return false;
  }
  return true;
}

bool encode_png_bytes(int width, int height, int channels, int bit_depth, const float* pixels,
                      std::vector<unsigned char>& bytes, std::string& error) {
  bytes.clear();
  Sink sink;
  sink.bytes = &bytes;
  return encode(sink, width, height, channels, bit_depth, pixels, error);
}

bool is_png_path(const std::filesystem::path& path) {
  return lower_extension(path) == ".png";
}

}  // namespace lensopt
