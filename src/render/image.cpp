#include "lensopt/render/image.h"

#include <OpenImageIO/imageio.h>
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <system_error>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/text.h"

namespace lensopt {
namespace {

// The first line of an OpenImageIO message (some readers add a second, redundant line).
std::string first_line(std::string message) {
  const std::size_t end = message.find('\n');
  if (end != std::string::npos) message.resize(end);
  while (!message.empty() && (message.back() == ' ' || message.back() == '.')) message.pop_back();
  return message.empty() ? std::string("unknown error") : message;
}

OIIO::TypeDesc default_pixel_type(const std::string& format) {
  if (format == "EXR") return OIIO::TypeDesc::HALF;
  if (format == "TIFF") return OIIO::TypeDesc::UINT16;
  return OIIO::TypeDesc::UINT8;
}

void write_with_oiio(const std::filesystem::path& target, const std::filesystem::path& temp,
                     const FloatImage& image, OIIO::ImageSpec spec) {
  auto out = OIIO::ImageOutput::create(temp.string());
  if (!out) {
    throw Error(SourceLocation{target.string()},
                fmt::format("cannot write: no image writer for this format ({})",
                            first_line(OIIO::geterror())));
  }
  if (!out->open(temp.string(), spec)) {
    throw Error(SourceLocation{target.string()},
                fmt::format("cannot write: {}", first_line(out->geterror())));
  }
  if (!out->write_image(OIIO::TypeDesc::FLOAT, image.pixels.data())) {
    const std::string message = first_line(out->geterror());
    out->close();
    throw Error(SourceLocation{target.string()}, fmt::format("cannot write: {}", message));
  }
  if (!out->close()) {
    throw Error(SourceLocation{target.string()},
                fmt::format("cannot write: {}", first_line(out->geterror())));
  }
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

struct ImageFileSpec::Impl {
  OIIO::ImageSpec spec;
};

ImageFileSpec::ImageFileSpec() = default;
ImageFileSpec::ImageFileSpec(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}

ImageFileSpec image_file_spec(ImagePixelType type) {
  OIIO::TypeDesc desc = OIIO::TypeDesc::UINT8;
  switch (type) {
    case ImagePixelType::kUint8:
      desc = OIIO::TypeDesc::UINT8;
      break;
    case ImagePixelType::kUint16:
      desc = OIIO::TypeDesc::UINT16;
      break;
    case ImagePixelType::kHalf:
      desc = OIIO::TypeDesc::HALF;
      break;
    case ImagePixelType::kFloat:
      desc = OIIO::TypeDesc::FLOAT;
      break;
  }
  // The size is a placeholder: write_image takes width, height and channels from the image.
  return ImageFileSpec(std::make_shared<const ImageFileSpec::Impl>(
      ImageFileSpec::Impl{OIIO::ImageSpec(1, 1, 3, desc)}));
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

  auto in = OIIO::ImageInput::open(path.string());
  if (!in) {
    throw Error(where, fmt::format("cannot read image (corrupt or not a {} file): {}",
                                   image_format_name(path), first_line(OIIO::geterror())));
  }
  LoadedImage loaded;
  auto file_spec = std::make_shared<ImageFileSpec::Impl>(ImageFileSpec::Impl{in->spec()});
  const OIIO::ImageSpec& spec = file_spec->spec;
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 || spec.depth > 1) {
    in->close();
    throw Error(where, fmt::format("cannot render a {} x {} x {} image with {} channels",
                                   spec.width, spec.height, spec.depth, spec.nchannels));
  }
  FloatImage& image = loaded.image;
  image = FloatImage(spec.width, spec.height, spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, image.pixels.data())) {
    const std::string message = first_line(in->geterror());
    in->close();
    throw Error(where, fmt::format("cannot read image (corrupt or truncated): {}", message));
  }
  in->close();
  // A reader may leave a truncated file's tail undefined: no NaN goes further.
  for (float& v : image.pixels)
    if (!std::isfinite(v)) v = 0.0f;
  // The spec describes the file as it will be written back: drop the reader's bookkeeping.
  file_spec->spec.erase_attribute("oiio:SubImages");
  loaded.spec = ImageFileSpec(std::move(file_spec));
  return loaded;
}

void write_image(const std::filesystem::path& path, const FloatImage& image,
                 const ImageFileSpec& like) {
  const std::string format = image_format_name(path);
  if (format.empty()) {
    throw Error(SourceLocation{path.string()},
                fmt::format("cannot write: unsupported image format '{}' (PNG, JPEG, TIFF, EXR)",
                            path.extension().string()));
  }
  OIIO::ImageSpec spec = like.empty() ? OIIO::ImageSpec(image.width, image.height, image.channels,
                                                        default_pixel_type(format))
                                      : like.impl()->spec;
  spec.width = spec.full_width = image.width;
  spec.height = spec.full_height = image.height;
  spec.x = spec.y = spec.full_x = spec.full_y = 0;
  if (spec.nchannels != image.channels) {
    spec.nchannels = image.channels;
    spec.default_channel_names();
    spec.channelformats.clear();
  }
  write_file_atomic_with(
      path, [&](const std::filesystem::path& temp) { write_with_oiio(path, temp, image, spec); });
}

void write_float_image(const std::filesystem::path& path, const FloatImage& image,
                       const std::vector<std::string>& channel_names) {
  const std::string format = image_format_name(path);
  if (format != "EXR" && format != "TIFF") {
    throw Error(SourceLocation{path.string()}, "float images are written as EXR or TIFF");
  }
  OIIO::ImageSpec spec(image.width, image.height, image.channels, OIIO::TypeDesc::FLOAT);
  if (image.channels == 1) spec.channelnames = {"Y"};
  if (static_cast<int>(channel_names.size()) == image.channels) spec.channelnames = channel_names;
  write_file_atomic_with(
      path, [&](const std::filesystem::path& temp) { write_with_oiio(path, temp, image, spec); });
}

}  // namespace lensopt
