// The SVG canvas backend and helpers shared by both backends.
#include "lensopt/plot/canvas.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"

namespace lensopt::plot {

double text_width_px(const std::string& text, double size_px) {
  // DejaVu Sans advances: digits and most lower case about 0.6 em, narrow letters less.
  double em = 0;
  for (unsigned char c : text) {
    if ((c & 0xC0) == 0x80) continue;  // UTF-8 continuation byte
    if (c == ' ' || c == '.' || c == ',' || c == ':' || c == 'i' || c == 'l' || c == 'j' ||
        c == '|' || c == '(' || c == ')' || c == '\'' || c == 't' || c == 'f' || c == 'r')
      em += 0.36;
    else if (std::isupper(c) || c == 'm' || c == 'w')
      em += 0.75;
    else
      em += 0.62;
  }
  return em * size_px;
}

bool parse_colour(const std::string& css, float rgb[3]) {
  if (css.size() != 7 || css[0] != '#') return false;
  for (int c = 0; c < 3; ++c) {
    unsigned v = 0;
    for (int k = 0; k < 2; ++k) {
      const char h =
          static_cast<char>(std::tolower(static_cast<unsigned char>(css[1 + 2 * c + k])));
      v <<= 4;
      if (h >= '0' && h <= '9')
        v |= static_cast<unsigned>(h - '0');
      else if (h >= 'a' && h <= 'f')
        v |= static_cast<unsigned>(h - 'a' + 10);
      else
        return false;
    }
    rgb[c] = static_cast<float>(v) / 255.f;
  }
  return true;
}

OutputFormat output_format_for(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".svg") return OutputFormat::kSvg;
  if (ext == ".png") return OutputFormat::kPng;
  throw Error(SourceLocation{path.string(), 0, 0},
              fmt::format("cannot tell the plot format from the extension '{}': use .svg or .png",
                          ext.empty() ? std::string("(none)") : ext));
}

std::unique_ptr<Canvas> make_canvas(const std::filesystem::path& path, double width,
                                    double height) {
  if (output_format_for(path) == OutputFormat::kSvg)
    return std::make_unique<SvgCanvas>(width, height);
  return std::make_unique<RasterCanvas>(width, height);
}

std::string encode_png(const RgbImage& image) {
  std::vector<unsigned char> bytes;
  OIIO::Filesystem::IOVecOutput proxy(bytes);
  auto out = OIIO::ImageOutput::create("png");
  if (!out) throw Error("OpenImageIO has no PNG writer");
  OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
  if (!out->set_ioproxy(&proxy) || !out->open("memory.png", spec))
    throw Error(fmt::format("cannot encode a PNG in memory: {}", out->geterror()));
  std::vector<unsigned char> row8(static_cast<std::size_t>(image.width) * 3);
  for (int y = 0; y < image.height; ++y) {
    const float* row = image.at(0, y);
    for (std::size_t i = 0; i < row8.size(); ++i)
      row8[i] = static_cast<unsigned char>(std::lround(255.f * std::clamp(row[i], 0.f, 1.f)));
    if (!out->write_scanline(y, 0, OIIO::TypeDesc::UINT8, row8.data()))
      throw Error(fmt::format("cannot encode a PNG in memory: {}", out->geterror()));
  }
  out->close();
  return std::string(bytes.begin(), bytes.end());
}

// ---- SVG backend ------------------------------------------------------------------------------

SvgCanvas::SvgCanvas(double width, double height) : Canvas(width, height), doc_(width, height) {}

void SvgCanvas::line(Point a, Point b, const Style& style) {
  doc_.line(a, b, style);
}

void SvgCanvas::polyline(const std::vector<Point>& points, const Style& style) {
  if (points.size() >= 2) doc_.polyline(points, style);
}

void SvgCanvas::polygon(const std::vector<Point>& points, const Style& style) {
  if (points.size() >= 3) doc_.polygon(points, style);
}

void SvgCanvas::circle(Point centre, double radius, const Style& style) {
  doc_.circle(centre, radius, style);
}

void SvgCanvas::rect(Point corner, double width, double height, const Style& style) {
  doc_.rect(corner, width, height, style);
}

void SvgCanvas::dots(const std::vector<Point>& centres, double radius, const std::string& colour,
                     double opacity) {
  doc_.dots(centres, radius, colour, opacity);
}

void SvgCanvas::text(Point at, const std::string& content, const TextStyle& style) {
  const char* anchor = style.anchor == Anchor::kStart    ? "start"
                       : style.anchor == Anchor::kMiddle ? "middle"
                                                         : "end";
  doc_.text(at, content, style.size_px, anchor, style.colour, style.vertical ? -90.0 : 0.0,
            style.bold);
}

void SvgCanvas::image(Point corner, double width, double height, const RgbImage& image,
                      bool pixelated) {
  doc_.image_png(corner, width, height, encode_png(image), pixelated);
}

void SvgCanvas::save(const std::filesystem::path& path) const {
  write_file_atomic(path, doc_.str());
}

}  // namespace lensopt::plot
