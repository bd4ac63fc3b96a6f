// Differentiable imaging for the joint optimization (joint/imaging.h): a rendered crop equals the
// Renderer's full image restricted to it, the adjoint's gradient w.r.t. every lens variable
// matches central finite differences, and a uniform scene stays uniform.
//
// Reduced sampling throughout (8 rings, 5 fields): the test is of the derivatives, not the
// optics, and stays within a few seconds.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "lensopt/core/error.h"
#include "lensopt/glass/glass.h"
#include "lensopt/joint/imaging.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/variables.h"
#include "lensopt/render/render.h"
#include "test_support.h"

using namespace lensopt;

namespace {

Lens joint_lens(const char* name) {
  return read_lens(test::source_dir() / "lenses" / (std::string(name) + ".toml"));
}

TraceOptions joint_sampling() {
  TraceOptions t;
  t.rings = 8;
  t.fields = 5;
  return t;
}

// A random RGB scene, smoothed a little (a 3-tap box per axis) so the warp's bicubic taps see
// an image rather than pure noise, values in [0, 1].
FloatImage random_scene(int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  FloatImage raw(width, height, 3);
  for (float& v : raw.pixels) v = u(rng);
  FloatImage out(width, height, 3);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i)
      for (int c = 0; c < 3; ++c) {
        float sum = 0;
        for (int dj = -1; dj <= 1; ++dj)
          for (int di = -1; di <= 1; ++di)
            sum += raw.at(std::clamp(i + di, 0, width - 1), std::clamp(j + dj, 0, height - 1), c);
        out.at(i, j, c) = sum / 9.0f;
      }
  return out;
}

struct Setup {
  Lens lens;
  LensParameterization param;
  std::vector<double> x;
  std::vector<int> glasses;
  explicit Setup(const char* name)
      : lens(joint_lens(name)), param(lens, GlassSpace(*load_catalog("ohara"))) {
    x = param.from_lens(lens);
    glasses = param.nearest_glasses(x.data());
  }
};

DifferentiableImagingOptions joint_options(bool ri, bool distortion) {
  DifferentiableImagingOptions o;
  o.sampling = joint_sampling();
  o.relative_illumination = ri;
  o.distortion = distortion;
  return o;
}

}  // namespace

TEST_CASE("joint imaging: a crop equals the Renderer's full image restricted to it") {
  Setup s("doublet");
  const FloatImage scene = random_scene(240, 180, 7);
  const Lens lens_x = s.param.to_lens(s.x.data(), GlassMode::kFixed, s.glasses);
  const ImagingModel model = build_imaging_model(lens_x, joint_sampling());
  for (const bool effects : {true, false}) {
    DifferentiableImaging imaging(s.param, GlassMode::kFixed, s.glasses,
                                  joint_options(effects, effects));
    imaging.prepare(s.x);
    RenderOptions ro;
    ro.relative_illumination = effects;
    ro.distortion = effects;
    const Renderer renderer(model, ro);
    const FloatImage full = renderer.render(scene).image;
    const CropWindow crops[] = {
        {100, 70, 64, 48}, {0, 0, 64, 48}, {176, 132, 64, 48}, {0, 100, 240, 40}};
    for (const CropWindow& crop : crops) {
      const FloatImage out = imaging.render(scene, crop);
      REQUIRE(out.width == crop.width);
      REQUIRE(out.height == crop.height);
      REQUIRE(out.channels == 3);
      double worst = 0;
      for (int j = 0; j < crop.height; ++j)
        for (int i = 0; i < crop.width; ++i)
          for (int c = 0; c < 3; ++c)
            worst = std::max(worst, static_cast<double>(std::abs(
                                        out.at(i, j, c) - full.at(crop.x0 + i, crop.y0 + j, c))));
      INFO("effects ", effects, " crop at (", crop.x0, ", ", crop.y0, "): max |diff| ", worst);
      // The Renderer works in float: float kernels (rel. 6e-8 each), float accumulation of the
      // ~4 window terms, float RI factors and warp offsets (exact to ~1e-6 px here): a few
      // float ulps of values <= 1 (measured: 1.2e-7 with RI and distortion, 6e-8 without).
      CHECK(worst < 1e-6);
    }
  }
}

TEST_CASE("joint imaging: a uniform scene stays uniform in the blurred crop") {
  Setup s("tessar");
  DifferentiableImaging imaging(s.param, GlassMode::kFixed, s.glasses, joint_options(false, false));
  imaging.prepare(s.x);
  const FloatImage scene(200, 150, 3, 0.625f);
  for (const CropWindow& crop : {CropWindow{0, 0, 200, 150}, CropWindow{150, 100, 50, 50}}) {
    const std::vector<double> out = imaging.render_values(scene, crop);
    double worst = 0;
    for (double v : out) worst = std::max(worst, std::abs(v - 0.625));
    INFO("crop at (", crop.x0, ", ", crop.y0, "): max |v - 0.625| ", worst);
    CHECK(worst < 1e-12);
  }
}
