// The interface between lensopt and its OpenImageIO module, liblensopt_oiio.so.
//
// OpenImageIO brings about 260 shared objects with it (ffmpeg, GDAL, GStreamer, OpenCV, DCMTK,
// OpenVDB, ...): linked into the executable, the dynamic loader's work on them made every command
// start in about 0.5 s (BENCHMARKS.md, "Start-up without OpenImageIO"). So the only code that uses
// OpenImageIO (src/core/oiio/) is built as a module of its own, which lensopt loads with dlopen the
// first time it needs a format or an operation only OpenImageIO provides:
//   - reading and writing TIFF, EXR and JPEG files (PNG goes through libpng, core/png_io.h,
//   always);
//   - text (FreeType through ImageBufAlgo::render_text): chart labels, export sheets, PNG plots,
//     whose drawing surface (RasterSurface) lives in the module.
// Where the module is looked for: core/plugin.h ($LENSOPT_OIIO_PLUGIN first). Both sides are built
// by the same build, so C++ types cross the boundary (the torch module's rule,
// joint/torch_plugin.h); kImagePluginAbi catches a module left over from another build.
#pragma once

#include <memory>
#include <string>
#include <vector>

namespace lensopt {

// Raise whenever ImagePlugin, RasterSurface or the structs below change.
constexpr int kImagePluginAbi = 1;

// Stored pixel types, the codes of render's ImagePixelType.
enum class StoredPixelType : int { kUint8 = 0, kUint16 = 1, kHalf = 2, kFloat = 3 };

// A file's description as the module read it (an OIIO::ImageSpec with the metadata), opaque here;
// the deleter lives in the module.
using OpaqueImageSpec = std::shared_ptr<const void>;

struct DecodedImage {
  int width = 0;
  int height = 0;
  int depth = 1;
  int channels = 0;
  std::vector<float> pixels;  // interleaved, top row first, associated alpha
  StoredPixelType stored = StoredPixelType::kUint8;
  OpaqueImageSpec spec;
};

struct EncodeRequest {
  int width = 0;
  int height = 0;
  int channels = 0;
  const float* pixels = nullptr;
  const void* spec = nullptr;  // the input's OpaqueImageSpec (metadata, pixel type), or null:
  StoredPixelType stored = StoredPixelType::kUint8;  // then this type
  std::vector<std::string> channel_names;            // empty: the spec's or the default names
};

// An RGBA 8-bit image with premultiplied colour that the raster plot canvas draws on (an
// OIIO::ImageBuf in the module). Colours are premultiplied RGBA floats; drawing composites "over".
class RasterSurface {
 public:
  virtual ~RasterSurface() = default;
  virtual int width() const = 0;
  virtual int height() const = 0;
  virtual void fill(const float rgba[4]) = 0;  // every pixel, replaced
  // The filled box of pixels [x0, x1] x [y0, y1] (inclusive), clipped.
  virtual void box(int x0, int y0, int x1, int y1, const float rgba[4]) = 0;
  // A one-pixel line from (x0, y0) to (x1, y1).
  virtual void line(int x0, int y0, int x1, int y1, const float rgba[4]) = 0;
  // Left-aligned text with its baseline at y; false if the font is not found.
  virtual bool text(int x, int y, const std::string& text, int size_px, const std::string& font,
                    const float rgba[4]) = 0;
  // `flat` (of this module) turned 90 degrees counter-clockwise, its top-left corner at (x0, y0)
  // of this surface, composited over it.
  virtual void over_rotated270(const RasterSurface& flat, int x0, int y0) = 0;
  // An RGB float image (iw x ih) scaled to w x h (nearest sample if pixelated, else filtered) and
  // pasted opaque at (x0, y0).
  virtual void paste_rgb(const float* rgb, int iw, int ih, int x0, int y0, int w, int h,
                         bool pixelated) = 0;
  // RGB floats of the surface box-filtered down to w x h (w * h * 3 values).
  virtual std::vector<float> downsample_rgb(int w, int h) const = 0;
};

struct ImagePlugin {
  int abi = 0;                   // kImagePluginAbi of the module's build
  std::size_t decoded_size = 0;  // sizeof(DecodedImage) there
  std::size_t request_size = 0;  // sizeof(EncodeRequest) there
  // Reads the first subimage; false with OpenImageIO's first line of error.
  bool (*read)(const std::string& path, DecodedImage& out, std::string& error) = nullptr;
  // Width and height from the header; false if the file does not open as an image.
  bool (*read_size)(const std::string& path, int& width, int& height) = nullptr;
  // Writes a file in the format of its extension.
  bool (*write)(const std::string& path, const EncodeRequest& request,
                std::string& error) = nullptr;
  // Decodes every scanline of a written file (core/atomic_file.h's check).
  bool (*verify)(const std::string& path, std::string& error) = nullptr;
  // The pixel type of an OpaqueImageSpec.
  StoredPixelType (*spec_type)(const void* spec) = nullptr;
  // Text onto a float image (channels 1..4) in place; align_right puts the text's right end at x.
  bool (*render_text)(float* pixels, int width, int height, int channels, int x, int y,
                      const std::string& text, int size_px, const std::string& font,
                      const float* colour, bool align_right) = nullptr;
  // The box {xbegin, xend, ybegin, yend} of a text relative to its origin; false without a font.
  bool (*text_size)(const std::string& text, int size_px, const std::string& font,
                    int box[4]) = nullptr;
  std::unique_ptr<RasterSurface> (*make_surface)(int width, int height) = nullptr;
};

// The module's entry point: extern "C" const ImagePlugin* lensopt_oiio_plugin();
inline constexpr const char* kImagePluginSymbol = "lensopt_oiio_plugin";
inline constexpr const char* kImagePluginFile = "liblensopt_oiio.so";

// The loaded module, on first use; throws Error "<what>: lensopt's OpenImageIO module
// liblensopt_oiio.so could not be loaded (...); tried: ..." when it cannot be loaded (`what`
// names the format or operation, e.g. "cannot read a TIFF file").
const ImagePlugin& image_plugin(const std::string& what);
// Whether the module is loaded (without loading it) / can be loaded (loading it).
bool image_plugin_loaded();
bool image_plugin_available();

}  // namespace lensopt
