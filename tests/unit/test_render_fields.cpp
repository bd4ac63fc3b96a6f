// A lens whose only field is on axis (issue 29): rendered with the on-axis PSF everywhere, no
// distortion and no relative illumination, with a warning; the image is not a constant grey and
// the reported metrics are those of the written image.
#include <doctest/doctest.h>

#include <cmath>
#include <string>

#include "lensopt/formats/lens_file.h"
#include "lensopt/render/distortion_warp.h"
#include "lensopt/render/metrics.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace test_render_fields {

using namespace lensopt;

namespace {

// A test chart: bars and a radial gradient, so a blur and a warp both show.
FloatImage bars(int w, int h) {
  FloatImage im(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float bar = ((x / 8 + y / 16) % 2) ? 0.9f : 0.1f;
      const float ramp = static_cast<float>(x) / static_cast<float>(w);
      im.at(x, y, 0) = bar;
      im.at(x, y, 1) = 0.5f * bar + 0.5f * ramp;
      im.at(x, y, 2) = ramp;
    }
  return im;
}

double spread(const FloatImage& im) {
  double lo = 1e9, hi = -1e9;
  for (float v : im.pixels) {
    lo = std::min(lo, static_cast<double>(v));
    hi = std::max(hi, static_cast<double>(v));
  }
  return hi - lo;
}

}  // namespace

TEST_CASE("render fields: a lens with only an on-axis field renders its blurred image, warned") {
  const Lens lens = read_lens(test::source_dir() / "tests/data/zmx-real/thorlabs_AC254-100-A.zmx");
  const ImagingModel model = build_imaging_model(lens);
  REQUIRE(model.fields_deg.size() == 1);
  CHECK(model.fields_deg[0] == 0.0);
  CHECK(model.relative_illumination[0] == doctest::Approx(1.0));
  bool warned = false;
  for (const std::string& w : model.warnings)
    warned = warned || w.find("one field") != std::string::npos;
  CHECK(warned);

  // The inverse distortion is the identity (with one node it sent every pixel to the axis).
  const SensorGeometry geo = SensorGeometry::make(96, 64, 1, model.sensor_diagonal_mm);
  const InverseDistortion inverse(model.centroid_y_mm, model.reference_y_mm);
  double sx = 0, sy = 0;
  REQUIRE(inverse.source(geo, 5, 7, sx, sy));
  CHECK(sx == doctest::Approx(5.5).epsilon(1e-12));
  CHECK(sy == doctest::Approx(7.5).epsilon(1e-12));
  CHECK(undistorted_radius_mm(model, 3.0) == 3.0);

  const Renderer renderer(model, RenderOptions{});
  const FloatImage input = bars(192, 128);
  const RenderResult result = renderer.render(input);
  // Not a constant image: the bars survive (the on-axis blur of an f/4 achromat is small).
  CHECK(spread(result.image) > 0.5);
  // Distortion and illumination change nothing: the written image is the blurred one ...
  const FloatImage blurred = renderer.blur(input);
  REQUIRE(blurred.pixels.size() == result.image.pixels.size());
  double worst = 0;
  for (std::size_t i = 0; i < blurred.pixels.size(); ++i)
    worst =
        std::max(worst, std::abs(static_cast<double>(blurred.pixels[i] - result.image.pixels[i])));
  CHECK(worst < 1e-5);
  // ... so the reported PSNR is the written image's.
  const double written = psnr_db(input, result.image, 3);
  MESSAGE("reported PSNR ", result.psnr_db, " dB, of the written image ", written, " dB");
  CHECK(result.psnr_db == doctest::Approx(written).epsilon(1e-4));
}

}  // namespace test_render_fields
