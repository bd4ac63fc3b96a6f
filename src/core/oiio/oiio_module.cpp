// liblensopt_oiio.so: every use of OpenImageIO in lensopt (core/image_plugin.h says why it is a
// module). It links OpenImageIO and fmt, nothing of lensopt; errors travel back as strings.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <cmath>

#include "core/image_plugin.h"

namespace lensopt {
namespace {

namespace iba = OIIO::ImageBufAlgo;

// The first line of an OpenImageIO message (some readers add a second, redundant line).
std::string first_line(std::string message) {
  const std::size_t end = message.find('\n');
  if (end != std::string::npos) message.resize(end);
  while (!message.empty() && (message.back() == ' ' || message.back() == '.')) message.pop_back();
  return message.empty() ? std::string("unknown error") : message;
}

OIIO::TypeDesc type_desc(StoredPixelType t) {
  switch (t) {
    case StoredPixelType::kUint16:
      return OIIO::TypeDesc::UINT16;
    case StoredPixelType::kHalf:
      return OIIO::TypeDesc::HALF;
    case StoredPixelType::kFloat:
      return OIIO::TypeDesc::FLOAT;
    default:
      return OIIO::TypeDesc::UINT8;
  }
}

StoredPixelType stored_of(OIIO::TypeDesc t) {
  if (t == OIIO::TypeDesc::UINT16) return StoredPixelType::kUint16;
  if (t == OIIO::TypeDesc::HALF) return StoredPixelType::kHalf;
  if (t == OIIO::TypeDesc::FLOAT || t == OIIO::TypeDesc::DOUBLE) return StoredPixelType::kFloat;
  return StoredPixelType::kUint8;
}

bool read(const std::string& path, DecodedImage& out, std::string& error) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    error = first_line(OIIO::geterror());
    return false;
  }
  auto spec = std::make_shared<OIIO::ImageSpec>(in->spec());
  out.width = spec->width;
  out.height = spec->height;
  out.depth = spec->depth;
  out.channels = spec->nchannels;
  out.stored = stored_of(spec->format);
  if (spec->width <= 0 || spec->height <= 0 || spec->nchannels <= 0 || spec->depth > 1) {
    in->close();
    return true;  // the caller reports the shape
  }
  out.pixels.assign(static_cast<std::size_t>(spec->width) * spec->height * spec->nchannels, 0.f);
  if (!in->read_image(0, 0, 0, spec->nchannels, OIIO::TypeDesc::FLOAT, out.pixels.data())) {
    error = first_line(in->geterror());
    in->close();
    return false;
  }
  in->close();
  // The spec describes the file as it will be written back: drop the reader's bookkeeping.
  spec->erase_attribute("oiio:SubImages");
  out.spec = std::shared_ptr<const void>(spec, spec.get());
  return true;
}

bool read_size(const std::string& path, int& width, int& height) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    (void)OIIO::geterror();
    return false;
  }
  width = in->spec().width;
  height = in->spec().height;
  in->close();
  return true;
}

bool write(const std::string& path, const EncodeRequest& r, std::string& error) {
  OIIO::ImageSpec spec = r.spec
                             ? *static_cast<const OIIO::ImageSpec*>(r.spec)
                             : OIIO::ImageSpec(r.width, r.height, r.channels, type_desc(r.stored));
  spec.width = spec.full_width = r.width;
  spec.height = spec.full_height = r.height;
  spec.x = spec.y = spec.full_x = spec.full_y = 0;
  if (spec.nchannels != r.channels) {
    spec.nchannels = r.channels;
    spec.default_channel_names();
    spec.channelformats.clear();
  }
  if (static_cast<int>(r.channel_names.size()) == r.channels) spec.channelnames = r.channel_names;
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    error = "no image writer for this format (" + first_line(OIIO::geterror()) + ")";
    return false;
  }
  if (!out->open(path, spec)) {
    error = first_line(out->geterror());
    return false;
  }
  if (!out->write_image(OIIO::TypeDesc::FLOAT, r.pixels)) {
    error = first_line(out->geterror());
    out->close();
    return false;
  }
  if (!out->close()) {
    error = first_line(out->geterror());
    return false;
  }
  return true;
}

bool verify(const std::string& path, std::string& error) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    error = first_line(OIIO::geterror());
    return false;
  }
  const OIIO::ImageSpec spec = in->spec();
  std::vector<unsigned char> row(static_cast<std::size_t>(std::max(spec.width, 1)) *
                                 std::max(spec.nchannels, 1) * 4);
  bool ok = spec.width > 0 && spec.height > 0;
  // Scanline by scanline: a whole large image need not be held twice.
  for (int y = spec.y; ok && y < spec.y + spec.height; ++y)
    ok = in->read_scanline(y, 0, OIIO::TypeDesc::UINT8, row.data());
  if (!ok) error = first_line(in->geterror());
  in->close();
  return ok;
}

StoredPixelType spec_type(const void* spec) {
  return stored_of(static_cast<const OIIO::ImageSpec*>(spec)->format);
}

bool render_text(float* pixels, int width, int height, int channels, int x, int y,
                 const std::string& text, int size_px, const std::string& font, const float* colour,
                 bool align_right) {
  OIIO::ImageBuf buf(OIIO::ImageSpec(width, height, channels, OIIO::TypeDesc::FLOAT), pixels);
  const bool ok =
      iba::render_text(buf, x, y, text, size_px, font,
                       {colour, static_cast<OIIO::span<const float>::size_type>(channels)},
                       align_right ? iba::TextAlignX::Right : iba::TextAlignX::Left);
  if (!ok) buf.geterror();  // clear
  return ok;
}

bool text_size(const std::string& text, int size_px, const std::string& font, int box[4]) {
  const OIIO::ROI roi = iba::text_size(text, size_px, font);
  if (!roi.defined()) return false;
  box[0] = roi.xbegin;
  box[1] = roi.xend;
  box[2] = roi.ybegin;
  box[3] = roi.yend;
  return true;
}

class Surface final : public RasterSurface {
 public:
  Surface(int width, int height) : buf_(OIIO::ImageSpec(width, height, 4, OIIO::TypeDesc::UINT8)) {}
  int width() const override { return buf_.spec().width; }
  int height() const override { return buf_.spec().height; }
  void fill(const float rgba[4]) override { iba::fill(buf_, {rgba, 4}); }
  void box(int x0, int y0, int x1, int y1, const float rgba[4]) override {
    iba::render_box(buf_, x0, y0, x1, y1, {rgba, 4}, true, OIIO::ROI(), 1);
  }
  void line(int x0, int y0, int x1, int y1, const float rgba[4]) override {
    iba::render_line(buf_, x0, y0, x1, y1, {rgba, 4}, false, OIIO::ROI(), 1);
  }
  bool text(int x, int y, const std::string& text, int size_px, const std::string& font,
            const float rgba[4]) override {
    return iba::render_text(buf_, x, y, text, size_px, font, {rgba, 4}, iba::TextAlignX::Left,
                            iba::TextAlignY::Baseline, 0, OIIO::ROI(), 1);
  }
  void over_rotated270(const RasterSurface& flat, int x0, int y0) override {
    OIIO::ImageBuf turned = iba::rotate270(static_cast<const Surface&>(flat).buf_);
    turned.specmod().x = x0;
    turned.specmod().y = y0;
    turned.specmod().full_x = x0;
    turned.specmod().full_y = y0;
    OIIO::ROI region = OIIO::roi_intersection(turned.roi(), buf_.roi());
    if (!region.defined() || region.npixels() == 0) return;
    OIIO::ImageBuf composite;
    if (!iba::over(composite, turned, buf_, region, 1)) return;
    // paste() offsets by the source's own origin: move the composite to (0, 0) first.
    composite.specmod().x = composite.specmod().y = 0;
    composite.specmod().full_x = composite.specmod().full_y = 0;
    iba::paste(buf_, region.xbegin, region.ybegin, 0, 0, composite, OIIO::ROI(), 1);
  }
  void paste_rgb(const float* rgb, int iw, int ih, int x0, int y0, int w, int h,
                 bool pixelated) override {
    OIIO::ImageBuf src(OIIO::ImageSpec(iw, ih, 3, OIIO::TypeDesc::FLOAT), const_cast<float*>(rgb));
    OIIO::ImageBuf scaled;
    const OIIO::ROI target(0, w, 0, h, 0, 1, 0, 3);
    const bool ok = pixelated ? iba::resample(scaled, src, false, target, 1)
                              : iba::resize(scaled, src, "", 0, target, 1);
    if (!ok) return;
    // Opaque alpha, then paste.
    const int order[4] = {0, 1, 2, -1};
    const float fill[4] = {0.f, 0.f, 0.f, 1.f};
    OIIO::ImageBuf rgba = iba::channels(scaled, 4, {order, 4}, {fill, 4});
    iba::paste(buf_, x0, y0, 0, 0, rgba, OIIO::ROI(), 1);
  }
  std::vector<float> downsample_rgb(int w, int h) const override {
    OIIO::ImageBuf small;
    const OIIO::ROI target(0, w, 0, h, 0, 1, 0, 4);
    if (w == width() && h == height())
      small.copy(buf_);
    else
      iba::resize(small, buf_, "box", 1.0f, target);
    std::vector<float> out(static_cast<std::size_t>(w) * h * 3);
    small.get_pixels(OIIO::ROI(0, w, 0, h, 0, 1, 0, 3), OIIO::TypeDesc::FLOAT, out.data());
    return out;
  }

 private:
  OIIO::ImageBuf buf_;
};

std::unique_ptr<RasterSurface> make_surface(int width, int height) {
  return std::make_unique<Surface>(width, height);
}

const ImagePlugin kPlugin = [] {
  ImagePlugin p;
  p.abi = kImagePluginAbi;
  p.decoded_size = sizeof(DecodedImage);
  p.request_size = sizeof(EncodeRequest);
  p.read = read;
  p.read_size = read_size;
  p.write = write;
  p.verify = verify;
  p.spec_type = spec_type;
  p.render_text = render_text;
  p.text_size = text_size;
  p.make_surface = make_surface;
  return p;
}();

}  // namespace
}  // namespace lensopt

extern "C" __attribute__((visibility("default"))) const lensopt::ImagePlugin*
lensopt_oiio_plugin() {
  return &lensopt::kPlugin;
}
