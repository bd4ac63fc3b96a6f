// Differentiable imaging for the joint optimization (joint/imaging.h): a rendered crop equals the
// Renderer's full image restricted to it, the adjoint's gradient w.r.t. every lens variable
// matches central finite differences, and a uniform scene stays uniform.
//
// Reduced sampling throughout (8 rings, 5 fields): the test is of the derivatives, not the
// optics, and stays within a few seconds.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/joint/imaging.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/variables.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace test_joint_imaging {

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

// RGB with and without RI and distortion, at the 2x resolution factor, a grey and an RGBA image
// (the alpha channel is only warped).
TEST_CASE("joint imaging: a crop equals the Renderer's full image restricted to it") {
  Setup s("doublet");
  const FloatImage rgb = random_scene(240, 180, 7);
  FloatImage grey(240, 180, 1), rgba(240, 180, 4);
  for (int j = 0; j < 180; ++j)
    for (int i = 0; i < 240; ++i) {
      grey.at(i, j, 0) = rgb.at(i, j, 1);
      for (int c = 0; c < 3; ++c) rgba.at(i, j, c) = rgb.at(i, j, c);
      rgba.at(i, j, 3) = rgb.at(239 - i, j, 0);
    }
  const Lens lens_x = s.param.to_lens(s.x.data(), GlassMode::kFixed, s.glasses);
  const ImagingModel model =
      build_imaging_model(lens_x, joint_sampling(), DifferentiableImagingOptions().psf);
  struct Case {
    bool effects;
    int res_factor;
    const FloatImage* scene;
  };
  for (const Case& k : {Case{true, 1, &rgb}, Case{false, 1, &rgb}, Case{true, 2, &rgb},
                        Case{true, 1, &grey}, Case{true, 1, &rgba}}) {
    DifferentiableImagingOptions options = joint_options(k.effects, k.effects);
    options.res_factor = k.res_factor;
    DifferentiableImaging imaging(s.param, GlassMode::kFixed, s.glasses, options);
    imaging.prepare(s.x);
    RenderOptions ro;
    ro.relative_illumination = k.effects;
    ro.distortion = k.effects;
    ro.res_factor = k.res_factor;
    const Renderer renderer(model, ro);
    const FloatImage& scene = *k.scene;
    const FloatImage full = renderer.render(scene).image;
    const CropWindow crops[] = {
        {100, 70, 64, 48}, {0, 0, 64, 48}, {176, 132, 64, 48}, {0, 100, 240, 40}};
    for (const CropWindow& crop : crops) {
      const FloatImage out = imaging.render(scene, crop);
      REQUIRE(out.width == crop.width);
      REQUIRE(out.height == crop.height);
      REQUIRE(out.channels == scene.channels);
      double worst = 0;
      for (int j = 0; j < crop.height; ++j)
        for (int i = 0; i < crop.width; ++i)
          for (int c = 0; c < scene.channels; ++c)
            worst = std::max(worst, static_cast<double>(std::abs(
                                        out.at(i, j, c) - full.at(crop.x0 + i, crop.y0 + j, c))));
      INFO("effects ", k.effects, " res ", k.res_factor, " channels ", scene.channels, " crop at (",
           crop.x0, ", ", crop.y0, "): max |diff| ", worst);
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

// The acceptance test of issue 7: dL/dx by the adjoint against central differences (prepare()
// re-run at x +- h) for every variable of the Doublet and the Tessar, RI and distortion on, two
// losses: L1 = sum W . R (fixed random W) and L2 = mean (R - T)^2. Relative error < 1e-4
// (measured: <= 4.9e-6). It holds because nothing in x -> R jumps: the KDE support is 3 bins
// (joint_psf_options), and kernel radii and field weights only add zeros or stay put.
TEST_CASE("joint imaging: gradients w.r.t. every lens variable match finite differences") {
  for (const std::string name : {"doublet", "tessar"}) {
    Setup s(name.c_str());
    // Continuous glasses so every glass variable acts (quantized ones have no finite difference).
    const GlassMode mode = GlassMode::kContinuous;
    DifferentiableImagingOptions options = joint_options(true, true);
    DifferentiableImaging imaging(s.param, mode, {}, options);
    const FloatImage scene = random_scene(240, 180, 11);
    const CropWindow crop{150, 20, 64, 48};  // off axis, across patch seams
    const int n = s.param.size();
    const std::size_t count = static_cast<std::size_t>(crop.width) * crop.height * 3;
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<double> weights(count), target(count);
    for (double& w : weights) w = u(rng);
    for (int j = 0; j < crop.height; ++j)
      for (int i = 0; i < crop.width; ++i)
        for (int c = 0; c < 3; ++c)
          target[(static_cast<std::size_t>(j) * crop.width + i) * 3 + c] =
              scene.at(crop.x0 + i, crop.y0 + j, c);
    // L1 = sum W R, L2 = mean (R - T)^2.
    auto losses = [&](const std::vector<double>& r) {
      double l1 = 0, l2 = 0;
      for (std::size_t k = 0; k < count; ++k) {
        l1 += weights[k] * r[k];
        l2 += (r[k] - target[k]) * (r[k] - target[k]);
      }
      return std::array<double, 2>{l1, l2 / count};
    };
    imaging.prepare(s.x);
    const std::vector<double> r0 = imaging.render_values(scene, crop);
    std::array<std::vector<double>, 2> grads;
    for (int loss = 0; loss < 2; ++loss) {
      FloatImage g(crop.width, crop.height, 3);
      for (std::size_t k = 0; k < count; ++k)
        g.pixels[k] =
            static_cast<float>(loss == 0 ? weights[k] : 2.0 * (r0[k] - target[k]) / count);
      // The float gradient image is the exact G of these losses for the FD below.
      if (loss == 1) {
        for (std::size_t k = 0; k < count; ++k) target[k] = r0[k] - 0.5 * count * g.pixels[k];
      } else {
        for (std::size_t k = 0; k < count; ++k) weights[k] = g.pixels[k];
      }
      imaging.backward(scene, crop, g, grads[loss]);
      REQUIRE(static_cast<int>(grads[loss].size()) == n);
    }
    std::array<double, 2> worst{0, 0};
    std::array<std::string, 2> worst_name;
    std::string table;
    for (int j = 0; j < n; ++j) {
      // Central differences: truncation ~h^2, rounding ~1e-16 |L| / h; 1e-6 balances them
      // (1e-5 leaves 2e-4 of truncation error on the defocus, 1e-7 4e-5 of rounding).
      const double h = 1e-6 * std::max(1.0, std::abs(s.x[j]));
      std::vector<double> xp = s.x, xm = s.x;
      xp[j] += h;
      xm[j] -= h;
      imaging.prepare(xp, false);  // values only: the same values as with Jets, faster
      const auto lp = losses(imaging.render_values(scene, crop));
      imaging.prepare(xm, false);
      const auto lm = losses(imaging.render_values(scene, crop));
      for (int loss = 0; loss < 2; ++loss) {
        const double fd = (lp[loss] - lm[loss]) / (2 * h);
        const double ad = grads[loss][j];
        const double rel = std::abs(ad - fd) / std::max({std::abs(fd), std::abs(ad), 1e-300});
        table += fmt::format("{} L{}: adjoint {:.9g} FD {:.9g} rel {:.2e}\n",
                             s.param.variables()[j].name, loss + 1, ad, fd, rel);
        if (rel > worst[loss]) {
          worst[loss] = rel;
          worst_name[loss] = s.param.variables()[j].name;
        }
      }
    }
    for (int loss = 0; loss < 2; ++loss) {
      INFO(name, " L", loss + 1, ": worst relative error ", worst[loss], " at ", worst_name[loss]);
      CHECK(worst[loss] < 1e-4);
    }
  }
}

// A grey image is blurred by the channels' mean kernel, so with G / 3 on each channel of the
// RGB image (R = G = B = the grey one) the RGB loss is the grey loss: the two adjoints (the grey
// one is not covered by the finite differences above) must give the same gradient.
TEST_CASE("joint imaging: the grey image's gradient is the RGB one's with equal channels") {
  Setup s("doublet");
  DifferentiableImaging imaging(s.param, GlassMode::kContinuous, {}, joint_options(true, true));
  imaging.prepare(s.x);
  const FloatImage rgb_random = random_scene(240, 180, 5);
  FloatImage grey(240, 180, 1), rgb(240, 180, 3);
  for (int j = 0; j < 180; ++j)
    for (int i = 0; i < 240; ++i) {
      grey.at(i, j, 0) = rgb_random.at(i, j, 0);
      for (int c = 0; c < 3; ++c) rgb.at(i, j, c) = rgb_random.at(i, j, 0);
    }
  const CropWindow crop{20, 110, 80, 60};
  FloatImage g_grey(crop.width, crop.height, 1), g_rgb(crop.width, crop.height, 3);
  std::mt19937 rng(9);
  std::uniform_int_distribution<int> u(-256, 256);  // k / 256: G and G / 3 exact in float
  for (int j = 0; j < crop.height; ++j)
    for (int i = 0; i < crop.width; ++i) {
      const float v = static_cast<float>(u(rng)) / 256.0f;
      g_grey.at(i, j, 0) = 3.0f * v;
      for (int c = 0; c < 3; ++c) g_rgb.at(i, j, c) = v;
    }
  std::vector<double> dx_grey, dx_rgb;
  imaging.backward(grey, crop, g_grey, dx_grey);
  imaging.backward(rgb, crop, g_rgb, dx_rgb);
  double scale = 0;
  for (double v : dx_rgb) scale = std::max(scale, std::abs(v));
  REQUIRE(scale > 0);
  for (int j = 0; j < s.param.size(); ++j) {
    INFO(s.param.variables()[j].name, ": grey ", dx_grey[j], " RGB ", dx_rgb[j]);
    CHECK(std::abs(dx_grey[j] - dx_rgb[j]) <= 1e-9 * scale);
  }
}

// prepare(x, false) samples the same optics in double (to rounding: the double tracer is built
// with FMA), and backward() then refuses to run.
TEST_CASE("joint imaging: values-only prepare renders the same crop and has no backward") {
  Setup s("tessar");
  DifferentiableImaging imaging(s.param, GlassMode::kQuantized, {}, joint_options(true, true));
  const FloatImage scene = random_scene(200, 150, 4);
  const CropWindow crop{120, 30, 48, 40};
  imaging.prepare(s.x);
  const std::vector<double> with_jets = imaging.render_values(scene, crop);
  imaging.prepare(s.x, false);
  const std::vector<double> values_only = imaging.render_values(scene, crop);
  REQUIRE(with_jets.size() == values_only.size());
  double worst = 0;
  for (std::size_t i = 0; i < with_jets.size(); ++i)
    worst = std::max(worst, std::abs(with_jets[i] - values_only[i]));
  INFO("max |difference| ", worst);
  CHECK(worst < 1e-12);
  std::vector<double> grad;
  CHECK_THROWS_AS(imaging.backward(scene, crop, imaging.render(scene, crop), grad), Error);
}

// The scene gradient is the adjoint of the (linear) rendering: <G, A S> = <A^T G, S> for random
// S and G, with RI and distortion, on a crop near a corner (the border reflection folds back).
TEST_CASE("joint imaging: the scene gradient is the rendering's adjoint") {
  Setup s("doublet");
  for (const int channels : {3, 4}) {
    CAPTURE(channels);
    DifferentiableImaging imaging(s.param, GlassMode::kQuantized, s.glasses,
                                  joint_options(true, true));
    imaging.prepare(s.x, true);
    FloatImage scene = random_scene(120, 90, 11);
    if (channels == 4) {
      FloatImage rgba(scene.width, scene.height, 4);
      for (int j = 0; j < scene.height; ++j)
        for (int i = 0; i < scene.width; ++i)
          for (int c = 0; c < 4; ++c) rgba.at(i, j, c) = c < 3 ? scene.at(i, j, c) : 0.5f;
      scene = rgba;
    }
    const CropWindow crop{2, 3, 40, 30};
    FloatImage grad(crop.width, crop.height, channels);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (float& v : grad.pixels) v = u(rng);
    const std::vector<double> rendered = imaging.render_values(scene, crop);
    std::vector<double> grad_x, grad_scene;
    imaging.backward(scene, crop, grad, grad_x, &grad_scene);
    REQUIRE(grad_scene.size() == scene.pixels.size());
    double lhs = 0, rhs = 0, scale = 0;
    for (std::size_t i = 0; i < rendered.size(); ++i) {
      lhs += grad.pixels[i] * rendered[i];
      scale += std::abs(grad.pixels[i] * rendered[i]);
    }
    for (std::size_t i = 0; i < scene.pixels.size(); ++i) rhs += grad_scene[i] * scene.pixels[i];
    CHECK(std::abs(lhs - rhs) <= 1e-12 * scale);
    // The lens gradient is the one backward() without the scene gradient gives.
    std::vector<double> plain;
    imaging.backward(scene, crop, grad, plain);
    for (std::size_t j = 0; j < plain.size(); ++j) CHECK(grad_x[j] == doctest::Approx(plain[j]));
  }
}

// A window of the scene that holds scene_window() renders a crop exactly as the whole scene (the
// same bits), its backward gives the same lens gradient and the scene gradient restricted to the
// window (zero outside it), the scene gradient alone needs no derivatives, and a window that
// misses a pixel the crop reads is an error. Crops at a corner (the reflection folds back into
// the window) and inside; RGB and RGBA.
TEST_CASE("joint imaging: a window of the scene renders and differentiates as the whole") {
  Setup s("doublet");
  DifferentiableImaging imaging(s.param, GlassMode::kQuantized, s.glasses,
                                joint_options(true, true));
  imaging.prepare(s.x, true);
  for (const int channels : {3, 4}) {
    FloatImage rgb = random_scene(200, 120, 21);
    FloatImage scene(rgb.width, rgb.height, channels);
    for (int j = 0; j < scene.height; ++j)
      for (int i = 0; i < scene.width; ++i)
        for (int c = 0; c < channels; ++c)
          scene.at(i, j, c) = c < 3 ? rgb.at(i, j, c) : 0.25f + 0.5f * rgb.at(i, j, 0);
    for (const CropWindow crop :
         {CropWindow{0, 0, 40, 30}, CropWindow{150, 85, 50, 35}, CropWindow{80, 40, 36, 28}}) {
      CAPTURE(channels);
      CAPTURE(crop.x0);
      const CropWindow w = imaging.scene_window(scene.width, scene.height, channels, crop);
      CHECK(w.x0 <= crop.x0);
      CHECK(w.y0 <= crop.y0);
      CHECK(w.x0 + w.width >= crop.x0 + crop.width);
      CHECK(w.y0 + w.height >= crop.y0 + crop.height);
      FloatImage window(w.width, w.height, channels);
      for (int j = 0; j < w.height; ++j)
        for (int i = 0; i < w.width; ++i)
          for (int c = 0; c < channels; ++c) window.at(i, j, c) = scene.at(w.x0 + i, w.y0 + j, c);
      const SceneWindow view{window, w.x0, w.y0, scene.width, scene.height};
      const std::vector<double> whole = imaging.render_values(scene, crop);
      CHECK(imaging.render_values(view, crop) == whole);
      FloatImage grad(crop.width, crop.height, channels);
      std::mt19937 rng(7);
      std::uniform_real_distribution<float> u(-1.0f, 1.0f);
      for (float& v : grad.pixels) v = u(rng);
      std::vector<double> gx_whole, gs_whole, gx_window, gs_window, gs_only;
      imaging.backward(scene, crop, grad, gx_whole, &gs_whole);
      imaging.backward(view, crop, grad, &gx_window, &gs_window);
      CHECK(gx_window == gx_whole);
      REQUIRE(gs_window.size() == window.pixels.size());
      double outside = 0;
      for (int j = 0; j < scene.height; ++j)
        for (int i = 0; i < scene.width; ++i)
          for (int c = 0; c < channels; ++c) {
            const double v = gs_whole[scene.index(i, j, c)];
            if (i < w.x0 || j < w.y0 || i >= w.x0 + w.width || j >= w.y0 + w.height)
              outside = std::max(outside, std::abs(v));
            else
              CHECK(gs_window[window.index(i - w.x0, j - w.y0, c)] == v);
          }
      CHECK(outside == 0.0);
      imaging.backward(view, crop, grad, nullptr, &gs_only);
      CHECK(gs_only == gs_window);
      // One column short on the right (or the left): an error naming the window.
      if (w.x0 + w.width < scene.width || w.x0 > 0) {
        const int x0 = w.x0 > 0 ? w.x0 + 1 : w.x0;
        FloatImage narrow(w.width - 1, w.height, channels);
        const SceneWindow short_view{narrow, x0, w.y0, scene.width, scene.height};
        CHECK_THROWS_WITH_AS(imaging.render_values(short_view, crop),
                             doctest::Contains("does not hold the pixels"), Error);
      }
    }
  }
  // The scene gradient alone after a values-only prepare: the same as with derivatives (to the
  // last bits of the optics, which the values-only sampling computes in double, not as Jets).
  const FloatImage scene = random_scene(200, 120, 22);
  const CropWindow crop{60, 30, 40, 30};
  FloatImage grad(crop.width, crop.height, 3);
  for (std::size_t i = 0; i < grad.pixels.size(); ++i)
    grad.pixels[i] = static_cast<float>(std::sin(0.3 * static_cast<double>(i)));
  const SceneWindow view{scene, 0, 0, scene.width, scene.height};
  std::vector<double> with_jets, values_only;
  imaging.backward(view, crop, grad, nullptr, &with_jets);
  imaging.prepare(s.x, false);
  imaging.backward(view, crop, grad, nullptr, &values_only);
  REQUIRE(values_only.size() == with_jets.size());
  double worst = 0, scale = 0;
  for (std::size_t i = 0; i < with_jets.size(); ++i) {
    worst = std::max(worst, std::abs(values_only[i] - with_jets[i]));
    scale = std::max(scale, std::abs(with_jets[i]));
  }
  INFO("max |difference| ", worst, " of ", scale);
  CHECK(scale > 0);
  CHECK(worst <= 1e-12 * scale);
  std::vector<double> gx;
  CHECK_THROWS_AS(imaging.backward(view, crop, grad, &gx, &values_only), Error);
}

}  // namespace test_joint_imaging
