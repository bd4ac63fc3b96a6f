// Image files without OpenImageIO in the process (PNG through libpng, core/png_io.h) and with it
// (EXR through the module liblensopt_oiio.so, core/image_plugin.h).
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <fstream>
#include <random>

#include "core/image_plugin.h"
#include "core/png_io.h"
#include "lensopt/core/error.h"
#include "lensopt/render/image.h"
#include "test_support.h"

namespace test_render_image_io {

using namespace lensopt;
namespace fs = std::filesystem;

namespace {

// An image of random integer samples of `bits` bits, as floats q * (1 / (2^bits - 1)).
FloatImage quantized_image(int w, int h, int channels, int bits, unsigned seed,
                           std::vector<unsigned>& samples) {
  std::mt19937 rng(seed);
  const unsigned top = bits == 16 ? 65535u : 255u;
  std::uniform_int_distribution<unsigned> draw(0, top);
  FloatImage image(w, h, channels);
  samples.resize(image.pixels.size());
  const float scale = 1.0f / static_cast<float>(top);
  for (std::size_t i = 0; i < image.pixels.size(); ++i) {
    samples[i] = draw(rng);
    // Opaque alpha keeps the colour samples exact (alpha is associated in memory).
    if ((channels == 2 || channels == 4) &&
        (i % channels) == static_cast<std::size_t>(channels - 1))
      samples[i] = top;
    image.pixels[i] = static_cast<float>(samples[i]) * scale;
  }
  return image;
}

std::string file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

}  // namespace

TEST_CASE("render image io: libpng round trip is bit-exact at 8 and 16 bits, 1 to 4 channels") {
  const fs::path dir = test::temp_root() / "png_round_trip";
  fs::create_directories(dir);
  for (int bits : {8, 16}) {
    for (int channels = 1; channels <= 4; ++channels) {
      CAPTURE(bits);
      CAPTURE(channels);
      std::vector<unsigned> samples;
      const FloatImage image =
          quantized_image(37, 23, channels, bits, 11u * bits + channels, samples);
      const fs::path path =
          dir / ("img" + std::to_string(bits) + "_" + std::to_string(channels) + ".png");
      write_image(path, image,
                  image_file_spec(bits == 16 ? ImagePixelType::kUint16 : ImagePixelType::kUint8));
      // The header says what was asked for.
      PngPixels header;
      std::string error;
      REQUIRE(read_png_header(path, header, error));
      CHECK(header.width == 37);
      CHECK(header.height == 23);
      CHECK(header.channels == channels);
      CHECK(header.bit_depth == bits);
      // The samples come back exactly, and writing them again gives the same file.
      const LoadedImage back = read_image(path);
      REQUIRE(back.image.width == 37);
      REQUIRE(back.image.height == 23);
      REQUIRE(back.image.channels == channels);
      const float scale = 1.0f / (bits == 16 ? 65535.0f : 255.0f);
      std::size_t wrong = 0;
      for (std::size_t i = 0; i < samples.size(); ++i)
        wrong += back.image.pixels[i] != static_cast<float>(samples[i]) * scale;
      CHECK(wrong == 0);
      const fs::path again =
          dir / ("again" + std::to_string(bits) + "_" + std::to_string(channels) + ".png");
      write_image(again, back.image, back.spec);
      CHECK(file_bytes(again) == file_bytes(path));
    }
  }
}

TEST_CASE("render image io: PNG writing clamps, rounds half up and writes 0 for NaN") {
  FloatImage image(4, 1, 1);
  image.pixels = {-0.5f, 2.0f, std::nanf(""), 127.5f / 255.0f};
  const fs::path path = test::temp_root() / "clamp.png";
  write_image(path, image);
  const LoadedImage back = read_image(path);
  CHECK(back.image.pixels[0] == 0.0f);
  CHECK(back.image.pixels[1] == 1.0f);
  CHECK(back.image.pixels[2] == 0.0f);
  CHECK(std::lround(back.image.pixels[3] * 255.0f) == 128);
}

TEST_CASE("render image io: a truncated or foreign PNG is an error naming the file") {
  std::vector<unsigned> samples;
  const FloatImage image = quantized_image(64, 64, 3, 8, 5u, samples);
  const fs::path good = test::temp_root() / "good.png";
  write_image(good, image);
  const std::string bytes = file_bytes(good);
  const fs::path cut = test::temp_root() / "cut.png";
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  std::string error;
  CHECK_FALSE(verify_png(cut, error));
  CHECK_FALSE(error.empty());
  CHECK_THROWS_WITH_AS(read_image(cut), doctest::Contains("cut.png"), Error);
  const fs::path text = test::temp_root() / "text.png";
  std::ofstream(text) << "not a png at all\n";
  CHECK_THROWS_WITH_AS(read_image(text), doctest::Contains("not a PNG file"), Error);
}

TEST_CASE("render image io: the zlib level changes the size, never the pixels") {
  std::vector<unsigned> samples;
  const FloatImage image = quantized_image(96, 64, 3, 8, 9u, samples);
  std::vector<unsigned char> fast, small;
  std::string error;
  set_png_compression_level(1);
  REQUIRE(encode_png_bytes(96, 64, 3, 8, image.pixels.data(), fast, error));
  set_png_compression_level(9);
  REQUIRE(encode_png_bytes(96, 64, 3, 8, image.pixels.data(), small, error));
  set_png_compression_level(-1);
  CHECK(png_compression_level() ==
        (std::getenv("LENSOPT_PNG_LEVEL") ? png_compression_level() : kDefaultPngLevel));
  CHECK(fast != small);
  const fs::path a = test::temp_root() / "fast.png", b = test::temp_root() / "small.png";
  std::ofstream(a, std::ios::binary).write(reinterpret_cast<const char*>(fast.data()), fast.size());
  std::ofstream(b, std::ios::binary)
      .write(reinterpret_cast<const char*>(small.data()), small.size());
  CHECK(read_image(a).image.pixels == read_image(b).image.pixels);
}

TEST_CASE("render image io: EXR goes through the OpenImageIO module, float-exact") {
  if (!image_plugin_available()) {
    MESSAGE("skipped: liblensopt_oiio.so is not built");
    return;
  }
  FloatImage image(19, 7, 3);
  for (std::size_t i = 0; i < image.pixels.size(); ++i)
    image.pixels[i] = 0.001f * static_cast<float>(i) - 0.05f;  // negatives survive in float EXR
  const fs::path path = test::temp_root() / "float.exr";
  write_float_image(path, image);
  const LoadedImage back = read_image(path);
  REQUIRE(back.image.width == 19);
  REQUIRE(back.image.channels == 3);
  CHECK(back.image.pixels == image.pixels);
  int w = 0, h = 0;
  REQUIRE(read_image_size(path, w, h));
  CHECK((w == 19 && h == 7));
  // A default-spec EXR is half: written back with the input's spec it stays half.
  const fs::path half = test::temp_root() / "half.exr";
  write_image(half, image);
  const LoadedImage h2 = read_image(half);
  CHECK(h2.image.pixels[5] == doctest::Approx(image.pixels[5]).epsilon(1e-3));
}

}  // namespace test_render_image_io
