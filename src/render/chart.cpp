#include "lensopt/render/chart.h"

#include <fmt/format.h>

#include <array>
#include <cmath>
#include <vector>

#include "core/image_plugin.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"

namespace lensopt {
namespace {

using Rgb = std::array<float, 3>;

struct Star {
  double cx, cy, radius;
};
struct SlantedSquare {
  double cx, cy, half, plate_half;  // dark square (tilted) on a light plate (axis-aligned)
};
struct Patch {
  double x0, y0, x1, y1;
  Rgb colour;
};

struct Scene {
  double grid_spacing;
  std::vector<Star> stars;
  std::vector<SlantedSquare> squares;
  std::vector<Patch> patches;
  double cos_tilt, sin_tilt;

  Rgb sample(double x, double y) const {
    constexpr float kDark = 0.05f, kLight = 0.95f;
    for (const Patch& p : patches)
      if (x >= p.x0 && x < p.x1 && y >= p.y0 && y < p.y1) return p.colour;
    for (const Star& s : stars) {
      const double dx = x - s.cx, dy = y - s.cy;
      const double r = std::hypot(dx, dy);
      if (r <= s.radius) {
        if (r < 0.04 * s.radius) return {0.5f, 0.5f, 0.5f};  // the unresolvable centre
        const float v = std::sin(18.0 * std::atan2(dy, dx)) >= 0.0 ? kDark : kLight;
        return {v, v, v};
      }
      if (r <= s.radius * 1.04) return {kDark, kDark, kDark};  // ring
    }
    for (const SlantedSquare& q : squares) {
      const double dx = x - q.cx, dy = y - q.cy;
      if (std::abs(dx) <= q.plate_half && std::abs(dy) <= q.plate_half) {
        const double u = dx * cos_tilt + dy * sin_tilt, v = -dx * sin_tilt + dy * cos_tilt;
        const float value = (std::abs(u) <= q.half && std::abs(v) <= q.half) ? kDark : kLight;
        return {value, value, value};
      }
    }
    const double gx = std::fmod(x, grid_spacing), gy = std::fmod(y, grid_spacing);
    if (gx < 1.0 || gy < 1.0) return {0.15f, 0.15f, 0.15f};
    return {0.7f, 0.7f, 0.7f};
  }
};

Scene make_scene(int width, int height) {
  Scene s;
  const double w = width, h = height, m = std::min(w, h);
  const double cx = 0.5 * w, cy = 0.5 * h;
  s.grid_spacing = std::max(4.0, std::round(m / 12.0));
  s.cos_tilt = std::cos(5.0 * kPi / 180.0);
  s.sin_tilt = std::sin(5.0 * kPi / 180.0);
  s.stars.push_back({cx, cy, 0.18 * m});
  for (int sx : {-1, 1})
    for (int sy : {-1, 1}) s.stars.push_back({cx + sx * 0.35 * w, cy + sy * 0.35 * h, 0.1 * m});
  const double half = m / 14.0, plate = m / 10.0;
  s.squares.push_back({cx - 0.225 * w, cy, half, plate});
  s.squares.push_back({cx + 0.225 * w, cy, half, plate});
  s.squares.push_back({cx, cy - 0.3 * h, half, plate});
  s.squares.push_back({cx, cy + 0.3 * h, half, plate});
  const std::array<Rgb, 8> colours = {Rgb{0.9f, 0.1f, 0.1f}, Rgb{0.1f, 0.8f, 0.1f},
                                      Rgb{0.1f, 0.2f, 0.9f}, Rgb{0.1f, 0.8f, 0.8f},
                                      Rgb{0.8f, 0.1f, 0.8f}, Rgb{0.9f, 0.85f, 0.1f},
                                      Rgb{1.0f, 1.0f, 1.0f}, Rgb{0.35f, 0.35f, 0.35f}};
  const double size = m / 18.0;
  const double x0 = 0.02 * w, y0 = cy - 0.5 * size * colours.size();
  for (std::size_t i = 0; i < colours.size(); ++i)
    s.patches.push_back({x0, y0 + i * size, x0 + size, y0 + (i + 1) * size, colours[i]});
  return s;
}

}  // namespace

void ChartOptions::validate() const {
  if (width < 32 || width > 16384 || height < 32 || height > 16384)
    throw Error(
        fmt::format("chart size {}x{} must be within 32..16384 in each direction", width, height));
}

Chart make_test_chart(const ChartOptions& options) {
  options.validate();
  Chart chart;
  chart.image = FloatImage(options.width, options.height, 3);
  const Scene scene = make_scene(options.width, options.height);
  constexpr int kSuper = 4;
#pragma omp parallel for schedule(static)
  for (int j = 0; j < options.height; ++j) {
    for (int i = 0; i < options.width; ++i) {
      Rgb sum = {0, 0, 0};
      for (int sj = 0; sj < kSuper; ++sj) {
        for (int si = 0; si < kSuper; ++si) {
          const Rgb v = scene.sample(i + (si + 0.5) / kSuper, j + (sj + 0.5) / kSuper);
          for (int c = 0; c < 3; ++c) sum[c] += v[c];
        }
      }
      for (int c = 0; c < 3; ++c) chart.image.at(i, j, c) = sum[c] / (kSuper * kSuper);
    }
  }
  if (!options.text) {
    chart.note = "text disabled";
    return chart;
  }
  // Labels through OpenImageIO's text rendering (FreeType with a system font), in the module
  // liblensopt_oiio.so (core/image_plugin.h).
  const ImagePlugin& oiio = image_plugin(
      "the chart's labels (text through OpenImageIO; --no-text "
      "draws the chart without them)");
  const int size = std::max(10, std::min(options.width, options.height) / 30);
  const float ink[3] = {0.05f, 0.05f, 0.05f};
  const std::string title = fmt::format("lensopt test chart {}x{}", options.width, options.height);
  float* pixels = chart.image.pixels.data();
  bool ok = false;
  for (const char* font : {"DejaVuSans", "DejaVu Sans", ""}) {
    ok = oiio.render_text(pixels, options.width, options.height, 3, size / 2, size + size / 2,
                          title, size, font, ink, false);
    if (ok) break;
  }
  if (ok) {
    oiio.render_text(pixels, options.width, options.height, 3, options.width - size / 2,
                     options.height - size / 2, "0123456789 ABCDEFGH abcdefgh", size, "DejaVuSans",
                     ink, true);
    chart.text_drawn = true;
  } else {
    chart.note = "no font found for OpenImageIO's text rendering: the chart has no text";
  }
  return chart;
}

}  // namespace lensopt
