// Rendering in Python: the imaging model (PSFs, distortion, relative illumination), per-pixel
// distortion and relative-illumination maps, and the renderer on numpy H x W x C images.
#include "lensopt/render/render.h"

#include <fmt/format.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bindings.h"
#include "lensopt/core/error.h"
#include "lensopt/core/image_limits.h"
#include "lensopt/render/diffraction_psf.h"
#include "lensopt/render/image.h"

namespace lensopt::python {
namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;

// H x W or H x W x C numpy -> FloatImage (one copy, the same interleaved layout).
FloatImage image_of(const FloatArray& a) {
  if (a.ndim() != 2 && a.ndim() != 3) throw Error("an image must be an H x W or H x W x C array");
  const int h = static_cast<int>(a.shape(0)), w = static_cast<int>(a.shape(1));
  const int c = a.ndim() == 3 ? static_cast<int>(a.shape(2)) : 1;
  FloatImage img(w, h, c);
  std::copy(a.data(), a.data() + img.pixels.size(), img.pixels.begin());
  return img;
}

py::array_t<float> numpy_of(FloatImage&& img) {
  return to_numpy(std::move(img.pixels), {img.height, img.width, img.channels});
}

struct PyRenderer {
  std::unique_ptr<Renderer> renderer;
  std::vector<std::string> psf_warnings;  // the model's and apply_psf_kind's
};

}  // namespace

void bind_render(py::module_& m) {
  py::class_<PyRenderer>(
      m, "Renderer",
      "Renders images through a lens (`lensopt render`): spatially varying PSF blur on 9 x 9 "
      "patches, relative illumination and distortion. The PSFs are sampled once here.")
      .def(
          py::init([](const Lens& lens, std::optional<int> rings, std::optional<int> fields,
                      int res_factor, bool distortion, bool relative_illumination, int threads,
                      const std::string& psf, int pupil_samples) {
            // `lensopt render`'s sampling: TraceOptions' defaults unless given.
            const TraceOptions defaults;
            const TraceOptions t =
                trace_options(rings.value_or(defaults.rings), fields.value_or(defaults.fields),
                              true, true, threads);
            RenderOptions o;
            o.res_factor = res_factor;
            o.distortion = distortion;
            o.relative_illumination = relative_illumination;
            o.threads = threads;
            o.validate();
            lens.validate();
            const PsfKind kind = parse_psf_kind(psf);
            if (pupil_samples < 8 || pupil_samples > 1024)
              throw Error("pupil_samples must be in [8, 1024], not " +
                          std::to_string(pupil_samples));
            WaveOptions wave;
            wave.pupil_samples = pupil_samples;
            wave.threads = threads;
            py::gil_scoped_release release;
            ImagingModel model = build_imaging_model(lens, t);
            const PsfChoice choice = apply_psf_kind(model, lens, kind, wave);
            // The model's (a spot larger than the geometric PSF window), then the wave
            // analysis's.
            std::vector<std::string> warnings = model.warnings;
            warnings.insert(warnings.end(), choice.warnings.begin(), choice.warnings.end());
            return PyRenderer{std::make_unique<Renderer>(std::move(model), o), std::move(warnings)};
          }),
          py::arg("lens"), py::kw_only(), py::arg("rings") = py::none(),
          py::arg("fields") = py::none(), py::arg("res_factor") = 1, py::arg("distortion") = true,
          py::arg("relative_illumination") = true, py::arg("threads") = 0,
          py::arg("psf") = "geometric", py::arg("pupil_samples") = kRenderPupilSamples,
          "psf (`render --psf`): 'geometric' (ray density), 'diffraction' (FFT of the pupil "
          "function on a pupil_samples grid, `--pupil-samples`) or 'auto' (per field and colour "
          "channel the larger blur, by RMS radius); Renderer.psf says which were used.")
      .def(
          "render",
          [](const PyRenderer& r, const FloatArray& image) {
            FloatImage input = image_of(image);
            RenderResult result;
            {
              py::gil_scoped_release release;
              result = r.renderer->render(std::move(input));
            }
            return numpy_of(std::move(result.image));
          },
          py::arg("image"),
          "The rendered image (H x W x C float32) of a linear-light H x W x C (or H x W) image; "
          "channels 0-2 are R, G, B, further ones are copied.")
      .def(
          "maps",
          [](const PyRenderer& r, int width, int height) {
            // A map of no pixels has no pitch (the diagonal over 0 pixels): refused, like one
            // beyond the image pixel limit (core/image_limits.h).
            if (width < 1 || height < 1)
              throw Error(
                  fmt::format("maps({}, {}): width and height must be at least 1", width, height));
            if (static_cast<std::int64_t>(width) * height > max_image_pixels())
              throw Error(fmt::format("maps({}, {}): more than the image pixel limit of {}", width,
                                      height, max_image_pixels()));
            const ImagingModel& model = r.renderer->model();
            require_relative_illumination(model);
            const SensorGeometry geo = SensorGeometry::make(
                width, height, r.renderer->options().res_factor, model.sensor_diagonal_mm);
            std::vector<double> ri(static_cast<std::size_t>(width) * height), distortion(ri.size()),
                radius(ri.size());
            for (int j = 0; j < height; ++j)
              for (int i = 0; i < width; ++i) {
                const std::size_t k = static_cast<std::size_t>(j) * width + i;
                radius[k] = geo.radius_mm(i, j);
                ri[k] = relative_illumination_at(model, radius[k]);
                distortion[k] = distortion_at(model, radius[k]);
              }
            py::dict d;
            d["radius_mm"] = to_numpy(std::move(radius), {height, width});
            d["relative_illumination"] = to_numpy(std::move(ri), {height, width});
            d["distortion"] = to_numpy(std::move(distortion), {height, width});
            d["pitch_mm"] = geo.pitch_mm;
            return d;
          },
          py::arg("width"), py::arg("height"),
          "Per pixel of a W x H image (H x W arrays): its image height radius_mm, the relative "
          "illumination and the distortion D(r) (a fraction) the renderer applies.")
      .def_property_readonly("fields_deg",
                             [](const PyRenderer& r) { return r.renderer->model().fields_deg; })
      .def_property_readonly("reference_y_mm",
                             [](const PyRenderer& r) { return r.renderer->model().reference_y_mm; })
      .def_property_readonly("centroid_y_mm",
                             [](const PyRenderer& r) { return r.renderer->model().centroid_y_mm; })
      .def_property_readonly("distortion",
                             [](const PyRenderer& r) { return r.renderer->model().distortion; })
      .def_property_readonly(
          "relative_illumination",
          [](const PyRenderer& r) { return r.renderer->model().relative_illumination; })
      .def_property_readonly(
          "psf",
          [](const PyRenderer& r) {
            const ImagingModel& model = r.renderer->model();
            const auto f = static_cast<py::ssize_t>(model.psf_diffraction.size());
            py::array_t<bool> used({f, static_cast<py::ssize_t>(kColourChannels)});
            auto u = used.mutable_unchecked<2>();
            int count = 0;
            for (py::ssize_t h = 0; h < f; ++h)
              for (int k = 0; k < kColourChannels; ++k) {
                u(h, k) = model.psf_diffraction[h][k];
                count += model.psf_diffraction[h][k];
              }
            py::dict d;
            d["kind"] = model.psf_kind;
            d["diffraction"] = used;
            d["diffraction_channels"] = count;
            d["pupil_samples"] = model.psf_pupil_samples;
            d["padding"] = model.psf_padding;
            d["fft_n"] = model.psf_fft_n;
            d["warnings"] = r.psf_warnings;
            return d;
          },
          "The PSFs the renderer uses (render_metrics.json's settings 'psf'): kind ('geometric', "
          "'diffraction' or 'auto'), diffraction (fields x 3 bool: the diffraction PSF is used "
          "for that field and colour channel R, G, B; auto: where its blur is the larger), "
          "diffraction_channels (their count), the diffraction PSFs' pupil_samples, padding and "
          "fft_n (0 for geometric) and the warnings (a spot larger than the geometric PSF window; "
          "the wave analysis's).");

  m.def(
      "read_image",
      [](const std::filesystem::path& path) {
        require_file(path);
        return numpy_of(std::move(read_image(path).image));
      },
      py::arg("path"),
      "Reads a PNG, JPEG, TIFF or EXR image (path: str or os.PathLike) as H x W x C float32 "
      "(0..1); FileNotFoundError for a missing file.");
  m.def(
      "write_image",
      [](const std::filesystem::path& path, const FloatArray& image) {
        const FloatImage img = image_of(image);
        const std::string ext = std::filesystem::path(path).extension().string();
        if (ext == ".exr" || ext == ".EXR")
          write_float_image(path, img);
        else
          write_image(path, img);
      },
      py::arg("path"), py::arg("image"),
      "Writes an H x W x C image atomically (format by extension; EXR as 32-bit float).");
}

}  // namespace lensopt::python
