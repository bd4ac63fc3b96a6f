// Float images in memory and their files: PNG through libpng in the process; JPEG, TIFF and EXR
// through OpenImageIO, in the module liblensopt_oiio.so loaded on first use
// (src/core/image_plugin.h: a process that touches only PNG files never maps OpenImageIO and starts
// in a few milliseconds).
//
// Pixel values are the file's values converted to float (integer formats scaled to [0, 1]); they
// are used as they are, proportional to scene luminance as the paper assumes (no sRGB decoding).
// Writing converts back to the original pixel type (so 8-bit stays 8-bit, 16-bit stays 16-bit,
// half and float stay float; integer formats clamp to [0, 1]) in the format given by the file
// extension, through a temporary file renamed into place (core/atomic_file.h).
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace lensopt {

// Row-major, top row first, channels interleaved (OpenImageIO's layout).
struct FloatImage {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> pixels;

  FloatImage() = default;
  FloatImage(int w, int h, int c, float value = 0.0f)
      : width(w), height(h), channels(c), pixels(static_cast<std::size_t>(w) * h * c, value) {}
  std::size_t index(int x, int y, int c) const {
    return (static_cast<std::size_t>(y) * width + x) * channels + c;
  }
  float& at(int x, int y, int c) { return pixels[index(x, y, c)]; }
  float at(int x, int y, int c) const { return pixels[index(x, y, c)]; }
  bool empty() const { return pixels.empty(); }
};

// How an image file stores its pixels: the pixel type and, for a file OpenImageIO read, the file's
// metadata (OpenImageIO's ImageSpec, kept opaque so that OpenImageIO stays out of lensopt's public
// headers and process). A PNG keeps its bit depth only. An empty spec stands for the format's
// default (see write_image).
class ImageFileSpec {
 public:
  struct Impl;  // defined in render/image.cpp
  ImageFileSpec();
  explicit ImageFileSpec(std::shared_ptr<const Impl> impl);
  bool empty() const { return impl_ == nullptr; }
  const Impl* impl() const { return impl_.get(); }

 private:
  std::shared_ptr<const Impl> impl_;
};

// Stored pixel types (of an ImageFileSpec without metadata).
enum class ImagePixelType { kUint8, kUint16, kHalf, kFloat };
ImageFileSpec image_file_spec(ImagePixelType type);

// An image read from a file, with the file's spec (pixel type, metadata) for writing it back.
struct LoadedImage {
  FloatImage image;
  ImageFileSpec spec;
};

// The extensions lensopt renders, lower case with the dot: .png .jpg .jpeg .tif .tiff .exr.
const std::vector<std::string>& supported_image_extensions();
// Whether a path's extension (any case) is one of them.
bool is_supported_image(const std::filesystem::path& path);
// "PNG", "JPEG", "TIFF", "EXR" from the extension (empty if unsupported).
std::string image_format_name(const std::filesystem::path& path);

// Reads the first subimage of a PNG, JPEG, TIFF or EXR file. Throws Error naming the file for a
// missing, unreadable, empty or corrupt file, an unsupported format or a zero-sized image.
LoadedImage read_image(const std::filesystem::path& path);

// Width and height from the file's header; false if it does not open as an image (or its format
// needs OpenImageIO and the module cannot be loaded).
bool read_image_size(const std::filesystem::path& path, int& width, int& height);

// Writes `image` to `path` (format from the extension) atomically, with the pixel type and
// metadata of `like` (the input's spec); a default spec writes 8-bit for PNG/JPEG, 16-bit for
// TIFF and half for EXR. A PNG is 8-bit for an 8-bit type and 16-bit for any other, and is
// compressed for speed (zlib level 3; LENSOPT_PNG_LEVEL=9 for the smallest files,
// src/core/png_io.h). Throws Error naming the path.
void write_image(const std::filesystem::path& path, const FloatImage& image,
                 const ImageFileSpec& like = ImageFileSpec());

// Writes a float image (EXR or TIFF, 32-bit float) atomically, with the given channel names
// (default: R, G, B, A or Y for one channel).
void write_float_image(const std::filesystem::path& path, const FloatImage& image,
                       const std::vector<std::string>& channel_names = {});

}  // namespace lensopt
