#include "lensopt/render/image.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <system_error>

#include "core/image_plugin.h"
#include "core/png_io.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/image_limits.h"
#include "lensopt/core/text.h"

namespace lensopt {

// The pixel type to write and, for a file OpenImageIO read, its spec (metadata).
struct ImageFileSpec::Impl {
  StoredPixelType type = StoredPixelType::kUint8;
  OpaqueImageSpec oiio;  // null for a PNG or a bare pixel type
};

namespace {

StoredPixelType default_pixel_type(const std::string& format) {
  if (format == "EXR") return StoredPixelType::kHalf;
  if (format == "TIFF") return StoredPixelType::kUint16;
  return StoredPixelType::kUint8;
}

// libpng stores 8 or 16 bits: 8-bit stays 8-bit, anything deeper is written as 16-bit.
int png_bits(StoredPixelType type) {
  return type == StoredPixelType::kUint8 ? 8 : 16;
}

void write_through_plugin(const std::filesystem::path& target, const std::filesystem::path& temp,
                          const FloatImage& image, const EncodeRequest& request,
                          const std::string& format) {
  const ImagePlugin& plugin =
      image_plugin(fmt::format("{}: cannot write a {} file", target.string(), format));
  EncodeRequest r = request;
  r.width = image.width;
  r.height = image.height;
  r.channels = image.channels;
  r.pixels = image.pixels.data();
  std::string error;
  if (!plugin.write(temp.string(), r, error))
    throw Error(SourceLocation{target.string()}, fmt::format("cannot write: {}", error));
}

void write_png_file(const std::filesystem::path& target, const std::filesystem::path& temp,
                    const FloatImage& image, int bits) {
  if (image.channels < 1 || image.channels > 4)
    throw Error(SourceLocation{target.string()},
                fmt::format("cannot write: a PNG holds 1 to 4 channels, not {}", image.channels));
  std::string error;
  if (!write_png(temp, image.width, image.height, image.channels, bits, image.pixels.data(), error))
    throw Error(SourceLocation{target.string()}, fmt::format("cannot write: {}", error));
}

}  // namespace

const std::vector<std::string>& supported_image_extensions() {
  static const std::vector<std::string> kExtensions = {".png", ".jpg",  ".jpeg",
                                                       ".tif", ".tiff", ".exr"};
  return kExtensions;
}

bool is_supported_image(const std::filesystem::path& path) {
  return !image_format_name(path).empty();
}

std::string image_format_name(const std::filesystem::path& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".png") return "PNG";
  if (ext == ".jpg" || ext == ".jpeg") return "JPEG";
  if (ext == ".tif" || ext == ".tiff") return "TIFF";
  if (ext == ".exr") return "EXR";
  return "";
}

ImageFileSpec::ImageFileSpec() = default;
ImageFileSpec::ImageFileSpec(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}

ImageFileSpec image_file_spec(ImagePixelType type) {
  return ImageFileSpec(std::make_shared<const ImageFileSpec::Impl>(
      ImageFileSpec::Impl{static_cast<StoredPixelType>(static_cast<int>(type)), nullptr}));
}

LoadedImage read_image(const std::filesystem::path& path) {
  const SourceLocation where{path.string()};
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error(where, "cannot read image: no such file");
  if (std::filesystem::is_directory(path, ec))
    throw Error(where, "cannot read image: it is a directory");
  if (!is_supported_image(path)) {
    throw Error(where, fmt::format("unsupported image format '{}': lensopt renders PNG, JPEG, "
                                   "TIFF and EXR files",
                                   path.extension().string()));
  }
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) throw Error(where, fmt::format("cannot read image: {}", ec.message()));
  if (size == 0) throw Error(where, "cannot read image: the file is empty");

  const std::string format = image_format_name(path);
  LoadedImage loaded;
  FloatImage& image = loaded.image;
  auto file_spec = std::make_shared<ImageFileSpec::Impl>();
  // The header against the pixel limit and the file's size, before any pixel is allocated
  // (core/image_limits.h).
  auto check_header = [&](int width, int height, std::uint64_t min_bytes) {
    const std::string problem = image_header_problem(width, height, size, min_bytes);
    if (!problem.empty()) throw Error(where, fmt::format("cannot read image: {}", problem));
  };
  if (format == "PNG") {
    PngPixels png;
    std::string error;
    if (read_png_header(path, png, error)) {
      // The smallest raw rows of that size (1-bit grey; read_png checks the exact ones again).
      const std::uint64_t raw = static_cast<std::uint64_t>(std::max(png.height, 0)) *
                                (1 + (static_cast<std::uint64_t>(std::max(png.width, 0)) + 7) / 8);
      check_header(png.width, png.height, raw / kMaxDeflateRatio);
    }
    if (!read_png(path, png, error))
      throw Error(where, fmt::format("cannot read image (corrupt or not a PNG file): {}", error));
    if (png.width <= 0 || png.height <= 0 || png.channels <= 0)
      throw Error(where, fmt::format("cannot render a {} x {} x 1 image with {} channels",
                                     png.width, png.height, png.channels));
    image.width = png.width;
    image.height = png.height;
    image.channels = png.channels;
    image.pixels = std::move(png.pixels);
    file_spec->type = png.bit_depth == 16 ? StoredPixelType::kUint16 : StoredPixelType::kUint8;
  } else {
    const ImagePlugin& plugin =
        image_plugin(fmt::format("{}: cannot read a {} file", path.string(), format));
    int header_width = 0, header_height = 0;
    if (plugin.read_size(path.string(), header_width, header_height))
      check_header(header_width, header_height,
                   static_cast<std::uint64_t>(header_width) *
                       static_cast<std::uint64_t>(header_height) / kMaxPixelsPerByte);
    DecodedImage decoded;
    std::string error;
    if (!plugin.read(path.string(), decoded, error)) {
      const bool opened = decoded.width > 0 || decoded.channels > 0;
      throw Error(where, opened ? fmt::format("cannot read image (corrupt or truncated): {}", error)
                                : fmt::format("cannot read image (corrupt or not a {} file): {}",
                                              format, error));
    }
    if (decoded.width <= 0 || decoded.height <= 0 || decoded.channels <= 0 || decoded.depth > 1)
      throw Error(where,
                  fmt::format("cannot render a {} x {} x {} image with {} channels", decoded.width,
                              decoded.height, decoded.depth, decoded.channels));
    image.width = decoded.width;
    image.height = decoded.height;
    image.channels = decoded.channels;
    image.pixels = std::move(decoded.pixels);
    file_spec->type = decoded.stored;
    file_spec->oiio = std::move(decoded.spec);
  }
  // A reader may leave a truncated file's tail undefined: no NaN goes further.
  for (float& v : image.pixels)
    if (!std::isfinite(v)) v = 0.0f;
  loaded.spec = ImageFileSpec(std::move(file_spec));
  return loaded;
}

bool read_image_size(const std::filesystem::path& path, int& width, int& height) {
  if (image_format_name(path) == "PNG") {
    PngPixels header;
    std::string error;
    if (!read_png_header(path, header, error)) return false;
    width = header.width;
    height = header.height;
    return true;
  }
  if (!image_plugin_available()) return false;
  return image_plugin("").read_size(path.string(), width, height);
}

void write_image(const std::filesystem::path& path, const FloatImage& image,
                 const ImageFileSpec& like) {
  const std::string format = image_format_name(path);
  if (format.empty()) {
    throw Error(SourceLocation{path.string()},
                fmt::format("cannot write: unsupported image format '{}' (PNG, JPEG, TIFF, EXR)",
                            path.extension().string()));
  }
  const StoredPixelType type = like.empty() ? default_pixel_type(format) : like.impl()->type;
  if (format == "PNG") {
    write_file_atomic_with(path, [&](const std::filesystem::path& temp) {
      write_png_file(path, temp, image, png_bits(type));
    });
    return;
  }
  EncodeRequest request;
  request.stored = type;
  request.spec = like.empty() ? nullptr : like.impl()->oiio.get();
  write_file_atomic_with(path, [&](const std::filesystem::path& temp) {
    write_through_plugin(path, temp, image, request, format);
  });
}

void write_float_image(const std::filesystem::path& path, const FloatImage& image,
                       const std::vector<std::string>& channel_names) {
  const std::string format = image_format_name(path);
  if (format != "EXR" && format != "TIFF") {
    throw Error(SourceLocation{path.string()}, "float images are written as EXR or TIFF");
  }
  EncodeRequest request;
  request.stored = StoredPixelType::kFloat;
  if (image.channels == 1) request.channel_names = {"Y"};
  if (static_cast<int>(channel_names.size()) == image.channels)
    request.channel_names = channel_names;
  write_file_atomic_with(path, [&](const std::filesystem::path& temp) {
    write_through_plugin(path, temp, image, request, format);
  });
}

}  // namespace lensopt
