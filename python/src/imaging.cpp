// Differentiable image formation in Python (joint/imaging.h): the sampled optics with their
// exact Jet derivatives, and the rendering with its adjoints with respect to the lens variables
// and the scene (for lensopt.torch's autograd.Function).
//
// Scenes come in as float64. The core renders float images, and the rendering is linear in the
// scene, so a float64 scene S is split into S_hi = float(S) and S_lo = float(S - S_hi) and
// R(S) = R(S_hi) + R(S_lo) (likewise the lens gradient, linear in S): double precision for
// gradient checks at the cost of a second pass, taken only when S_lo is not zero.
#include "lensopt/joint/imaging.h"

#include "bindings.h"
#include "lensopt/core/error.h"

namespace lensopt::python {

GlassMode parse_glass_mode(const std::string& s);
std::vector<double> vector_of(
    const py::array_t<double, py::array::c_style | py::array::forcecast>& x, int size);

namespace {

using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

// The hi and lo float parts of an H x W x C float64 scene; lo is empty when it is all zero.
struct SplitScene {
  FloatImage hi, lo;
};

SplitScene split_scene(const DoubleArray& a) {
  if (a.ndim() != 3) throw Error("the scene must be an H x W x C array");
  const int h = static_cast<int>(a.shape(0)), w = static_cast<int>(a.shape(1)),
            c = static_cast<int>(a.shape(2));
  SplitScene s{FloatImage(w, h, c), FloatImage(w, h, c)};
  bool any = false;
  const double* d = a.data();
  for (std::size_t i = 0; i < s.hi.pixels.size(); ++i) {
    s.hi.pixels[i] = static_cast<float>(d[i]);
    s.lo.pixels[i] = static_cast<float>(d[i] - static_cast<double>(s.hi.pixels[i]));
    any = any || s.lo.pixels[i] != 0.0f;
  }
  if (!any) s.lo = FloatImage();
  return s;
}

CropWindow crop_of(const std::optional<std::array<int, 4>>& crop, const SplitScene& s) {
  if (!crop) return CropWindow{0, 0, s.hi.width, s.hi.height};
  return CropWindow{(*crop)[0], (*crop)[1], (*crop)[2], (*crop)[3]};
}

// B x C x H x W float32 images (numpy views of torch tensors: any strides), read without
// conversion; the windows of them a crop reads are copied into FloatImages.
using ImageArray = py::array_t<float, 0>;

CropWindow crop_or_whole(const std::optional<std::array<int, 4>>& crop, int width, int height) {
  if (!crop) return CropWindow{0, 0, width, height};
  return CropWindow{(*crop)[0], (*crop)[1], (*crop)[2], (*crop)[3]};
}

// Item b's pixels of window w (full-image coordinates) into `out` (interleaved, resized).
void copy_window(const py::detail::unchecked_reference<float, 4>& in, py::ssize_t b,
                 const CropWindow& w, FloatImage& out) {
  const int channels = static_cast<int>(in.shape(1));
  if (out.width != w.width || out.height != w.height || out.channels != channels)
    out = FloatImage(w.width, w.height, channels);
  float* dst = out.pixels.data();
  for (int j = 0; j < w.height; ++j)
    for (int i = 0; i < w.width; ++i)
      for (int c = 0; c < channels; ++c) *dst++ = in(b, c, w.y0 + j, w.x0 + i);
}

// The shape of a B x C x H x W batch of images, checked (4 dimensions, none empty).
struct BatchShape {
  py::ssize_t batch = 0;
  int channels = 0, height = 0, width = 0;
};

BatchShape batch_shape(const ImageArray& images) {
  if (images.ndim() != 4) throw Error("the images must be B x C x H x W");
  if (images.shape(0) < 1 || images.shape(1) < 1 || images.shape(2) < 1 || images.shape(3) < 1)
    throw Error("the images must not be empty");
  return BatchShape{images.shape(0), static_cast<int>(images.shape(1)),
                    static_cast<int>(images.shape(2)), static_cast<int>(images.shape(3))};
}

struct PyImaging {
  py::object param_ref;  // keeps the Parameterization alive
  std::unique_ptr<DifferentiableImaging> imaging;
  int variables = 0;
  int grid_size = 0;
};

}  // namespace

void bind_imaging(py::module_& m) {
  py::class_<PyImaging>(
      m, "Imaging",
      "Differentiable image formation of a parameterized lens (the joint optimization's): "
      "prepare(x) samples the optics with exact derivatives; render() and backward() form an "
      "image crop and its adjoints. The full scene spans the sensor diagonal.")
      .def(py::init([](py::object param_obj, const std::string& glass_mode,
                       std::vector<int> fixed_glasses, int rings, int fields, int grid_size,
                       double bin_um, double sigma_bins, int support_bins, int res_factor,
                       bool relative_illumination, bool distortion, bool ray_aiming, int threads) {
             const auto& param = param_obj.cast<const LensParameterization&>();
             DifferentiableImagingOptions o;
             o.sampling.rings = rings;
             o.sampling.fields = fields;
             o.sampling.ray_aiming = ray_aiming;
             o.psf.grid_size = grid_size;
             o.psf.bin_um = bin_um;
             o.psf.sigma_bins = sigma_bins;
             o.psf.support_bins = support_bins;
             o.res_factor = res_factor;
             o.relative_illumination = relative_illumination;
             o.distortion = distortion;
             o.threads = threads;
             o.validate();
             const GlassMode mode = parse_glass_mode(glass_mode);
             if (mode == GlassMode::kFixed && fixed_glasses.empty()) {
               const std::vector<double> x = param.from_lens(param.structure());
               fixed_glasses = param.nearest_glasses(x.data());
             }
             PyImaging p;
             p.param_ref = param_obj;
             p.imaging = std::make_unique<DifferentiableImaging>(param, mode, fixed_glasses, o);
             p.variables = param.size();
             p.grid_size = grid_size;
             return p;
           }),
           py::arg("param"), py::kw_only(), py::arg("glass_mode") = "quantized",
           py::arg("fixed_glasses") = std::vector<int>{}, py::arg("rings") = 8,
           py::arg("fields") = 21, py::arg("grid_size") = 65, py::arg("bin_um") = 4.0,
           py::arg("sigma_bins") = 0.5, py::arg("support_bins") = 3, py::arg("res_factor") = 1,
           py::arg("relative_illumination") = true, py::arg("distortion") = true,
           py::arg("ray_aiming") = true, py::arg("threads") = 0,
           "glass_mode: 'quantized' (nearest catalog glass, straight-through gradient; the "
           "paper's), 'continuous' or 'fixed'. The defaults are the joint optimization's "
           "(8 rings, 21 fields, KDE support 3); rings=32, support_bins=2 give `lensopt "
           "render`'s PSFs.")
      .def_property_readonly("variables", [](const PyImaging& p) { return p.variables; })
      .def(
          "prepare",
          [](PyImaging& p, const DoubleArray& x, bool derivatives) {
            const std::vector<double> v = vector_of(x, p.variables);
            py::gil_scoped_release release;
            p.imaging->prepare(v, derivatives);
          },
          py::arg("x"), py::arg("derivatives") = true,
          "Samples the optics of variables x (with derivatives unless told otherwise).")
      .def(
          "render",
          [](const PyImaging& p, const DoubleArray& scene, std::optional<std::array<int, 4>> crop) {
            const SplitScene s = split_scene(scene);
            const CropWindow c = crop_of(crop, s);
            std::vector<double> out;
            {
              py::gil_scoped_release release;
              out = p.imaging->render_values(s.hi, c);
              if (!s.lo.empty()) {
                const std::vector<double> lo = p.imaging->render_values(s.lo, c);
                for (std::size_t i = 0; i < out.size(); ++i) out[i] += lo[i];
              }
            }
            return to_numpy(std::move(out), {c.height, c.width, s.hi.channels});
          },
          py::arg("scene"), py::arg("crop") = py::none(),
          "The rendered crop (h x w x C float64) of an H x W x C float64 scene; crop = (x0, y0, "
          "w, h) in pixels (None: the whole scene).")
      .def(
          "backward",
          [](const PyImaging& p, const DoubleArray& scene, std::optional<std::array<int, 4>> crop,
             const DoubleArray& grad, bool scene_gradient) {
            const SplitScene s = split_scene(scene);
            const CropWindow c = crop_of(crop, s);
            if (grad.ndim() != 3 || grad.shape(0) != c.height || grad.shape(1) != c.width ||
                grad.shape(2) != s.hi.channels)
              throw Error("the gradient must have the rendered crop's shape h x w x C");
            FloatImage g(c.width, c.height, s.hi.channels);
            for (std::size_t i = 0; i < g.pixels.size(); ++i)
              g.pixels[i] = static_cast<float>(grad.data()[i]);
            std::vector<double> gx(p.variables, 0.0), gs;
            {
              py::gil_scoped_release release;
              p.imaging->backward(s.hi, c, g, gx, scene_gradient ? &gs : nullptr);
              if (!s.lo.empty()) p.imaging->backward(s.lo, c, g, gx, nullptr);
            }
            py::object scene_grad = py::none();
            if (scene_gradient)
              scene_grad = to_numpy(std::move(gs), {s.hi.height, s.hi.width, s.hi.channels});
            return py::make_tuple(to_numpy(std::move(gx), {p.variables}), scene_grad);
          },
          py::arg("scene"), py::arg("crop"), py::arg("grad"), py::arg("scene_gradient") = true,
          "(dL/dx, dL/dscene) for dL/d(rendered crop) = grad (h x w x C; used in float32 "
          "precision). dL/dscene is None unless scene_gradient.")
      .def(
          "render_images",
          [](const PyImaging& p, const ImageArray& images, std::optional<std::array<int, 4>> crop) {
            const auto [batch, channels, height, width] = batch_shape(images);
            const auto in = images.unchecked<4>();
            const CropWindow c = crop_or_whole(crop, width, height);
            py::array_t<float> out({batch, static_cast<py::ssize_t>(channels),
                                    static_cast<py::ssize_t>(c.height),
                                    static_cast<py::ssize_t>(c.width)});
            float* o = out.mutable_data();
            {
              py::gil_scoped_release release;
              const CropWindow w = p.imaging->scene_window(width, height, channels, c);
              FloatImage window;
              const std::size_t pixels = static_cast<std::size_t>(c.width) * c.height;
              for (py::ssize_t b = 0; b < batch; ++b) {
                copy_window(in, b, w, window);
                const std::vector<double> v =
                    p.imaging->render_values(SceneWindow{window, w.x0, w.y0, width, height}, c);
                float* ob = o + static_cast<std::size_t>(b) * channels * pixels;
                for (int ch = 0; ch < channels; ++ch)
                  for (std::size_t k = 0; k < pixels; ++k)
                    ob[ch * pixels + k] = static_cast<float>(v[k * channels + ch]);
              }
            }
            return out;
          },
          py::arg("images"), py::arg("crop") = py::none(),
          "render() of a batch: B x C x H x W float32 images (any strides) -> their crops "
          "B x C x h x w float32 (crop = (x0, y0, w, h); None: the whole images). Reads only the "
          "pixels each crop needs. lensopt.torch's forward on float32 CPU images.")
      .def(
          "scene_window",
          [](const PyImaging& p, int width, int height, int channels,
             std::optional<std::array<int, 4>> crop) {
            const CropWindow w = p.imaging->scene_window(width, height, channels,
                                                         crop_or_whole(crop, width, height));
            return std::array<int, 4>{w.x0, w.y0, w.width, w.height};
          },
          py::arg("width"), py::arg("height"), py::arg("channels"), py::arg("crop") = py::none(),
          "(x0, y0, w, h): the pixels of a width x height image that render_images() and "
          "backward_images() of the crop read (its blurred region plus the kernels' reach).")
      .def(
          "backward_images",
          [](const PyImaging& p, const ImageArray& images, std::optional<std::array<int, 4>> crop,
             const ImageArray& grad, bool lens_gradient, bool image_gradient) {
            const auto [batch, channels, height, width] = batch_shape(images);
            const auto in = images.unchecked<4>();
            const CropWindow c = crop_or_whole(crop, width, height);
            if (grad.ndim() != 4 || grad.shape(0) != batch || grad.shape(1) != channels ||
                grad.shape(2) != c.height || grad.shape(3) != c.width)
              throw Error("the gradient must have the rendered crops' shape B x C x h x w");
            const auto gin = grad.unchecked<4>();
            std::vector<double> gx;
            py::array_t<float> g_images;
            float* gi = nullptr;
            if (image_gradient) {
              g_images = py::array_t<float>({batch, static_cast<py::ssize_t>(channels),
                                             static_cast<py::ssize_t>(height),
                                             static_cast<py::ssize_t>(width)});
              gi = g_images.mutable_data();
            }
            {
              py::gil_scoped_release release;
              const std::size_t plane = static_cast<std::size_t>(width) * height;
              if (gi) std::fill(gi, gi + static_cast<std::size_t>(batch) * channels * plane, 0.0f);
              const CropWindow w = p.imaging->scene_window(width, height, channels, c);
              FloatImage window, g(c.width, c.height, channels);
              std::vector<double> g_window;
              for (py::ssize_t b = 0; b < batch; ++b) {
                copy_window(in, b, w, window);
                float* dst = g.pixels.data();
                for (int j = 0; j < c.height; ++j)
                  for (int i = 0; i < c.width; ++i)
                    for (int ch = 0; ch < channels; ++ch) *dst++ = gin(b, ch, j, i);
                g_window.clear();
                p.imaging->backward(SceneWindow{window, w.x0, w.y0, width, height}, c, g,
                                    lens_gradient ? &gx : nullptr, gi ? &g_window : nullptr);
                if (!gi) continue;
                float* gb = gi + static_cast<std::size_t>(b) * channels * plane;
                const double* src = g_window.data();
                for (int j = 0; j < w.height; ++j)
                  for (int i = 0; i < w.width; ++i)
                    for (int ch = 0; ch < channels; ++ch)
                      gb[ch * plane + static_cast<std::size_t>(w.y0 + j) * width + (w.x0 + i)] =
                          static_cast<float>(*src++);
              }
              if (lens_gradient && gx.empty()) gx.assign(p.variables, 0.0);
            }
            py::object gx_out = py::none(), gi_out = py::none();
            if (lens_gradient) gx_out = to_numpy(std::move(gx), {p.variables});
            if (image_gradient) gi_out = g_images;
            return py::make_tuple(gx_out, gi_out);
          },
          py::arg("images"), py::arg("crop"), py::arg("grad"), py::kw_only(),
          py::arg("lens_gradient") = true, py::arg("image_gradient") = true,
          "backward() of a batch: (dL/dx summed over the batch or None, dL/dimages B x C x H x W "
          "float32 or None) for dL/d(the crops) = grad (B x C x h x w float32, any strides). "
          "Without lens_gradient the optics need no derivatives. lensopt.torch's backward on "
          "float32 CPU images.")
      .def(
          "optics",
          [](const PyImaging& p, bool jacobians) {
            const ImagingOptics& o = p.imaging->optics();
            const int f = static_cast<int>(o.fields_deg.size()), g = p.grid_size;
            const int n = jacobians ? o.variables : 0;
            const std::size_t cells = static_cast<std::size_t>(g) * g;
            std::vector<double> psf(f * kColourChannels * cells, 0.0);
            std::vector<double> d_psf(n > 0 ? psf.size() * n : 0, 0.0);
            for (int h = 0; h < f; ++h)
              for (int c = 0; c < kColourChannels; ++c) {
                const std::size_t base =
                    (static_cast<std::size_t>(h) * kColourChannels + c) * cells;
                std::copy(o.psf[h][c].begin(), o.psf[h][c].end(), psf.begin() + base);
                if (n == 0) continue;
                const auto& box = o.support[h][c];
                const double* d = o.d_psf[h][c].data();
                for (int r = box[0]; r < box[1]; ++r)
                  for (int i = box[2]; i < box[3]; ++i, d += n)
                    std::copy(d, d + n,
                              d_psf.begin() + (base + static_cast<std::size_t>(r) * g + i) * n);
              }
            py::dict out;
            out["fields_deg"] = o.fields_deg;
            auto vec = [](std::vector<double> v) {
              const auto size = static_cast<py::ssize_t>(v.size());
              return to_numpy(std::move(v), {size});
            };
            out["reference_y_mm"] = vec(o.reference_y_mm);
            out["centroid_y_mm"] = vec(o.centroid_y_mm);
            out["relative_illumination"] = vec(o.illumination);
            out["psf"] = to_numpy(std::move(psf), {f, kColourChannels, g, g});
            if (n > 0) {
              auto mat = [f, n](std::vector<double> v) { return to_numpy(std::move(v), {f, n}); };
              out["d_reference_y_mm"] = mat(o.d_reference);
              out["d_centroid_y_mm"] = mat(o.d_centroid);
              out["d_relative_illumination"] = mat(o.d_illumination);
              out["d_psf"] = to_numpy(std::move(d_psf), {f, kColourChannels, g, g, n});
            }
            out["ray_failures"] = o.ray_failures;
            return out;
          },
          py::arg("jacobians") = true,
          "The optics of the last prepare(): per field the PSFs (F x 3 x G x G), y_ref, ybar and "
          "relative illumination, with their Jacobians wrt the lens variables (d_psf F x 3 x G x "
          "G x n, the others F x n) after a prepare with derivatives, unless jacobians=False.")
      .def(
          "optics_backward",
          [](const PyImaging& p, const DoubleArray& grad_psf, const DoubleArray& grad_reference,
             const DoubleArray& grad_centroid, const DoubleArray& grad_illumination) {
            const ImagingOptics& o = p.imaging->optics();
            const int f = static_cast<int>(o.fields_deg.size()), n = o.variables, g = p.grid_size;
            if (n != p.variables)
              throw Error("Imaging.optics_backward needs a prepare(x) with derivatives");
            if (grad_psf.ndim() != 4 || grad_psf.shape(0) != f ||
                grad_psf.shape(1) != kColourChannels || grad_psf.shape(2) != g ||
                grad_psf.shape(3) != g)
              throw Error("grad_psf must be " + std::to_string(f) + " x 3 x " + std::to_string(g) +
                          " x " + std::to_string(g));
            for (const DoubleArray* a : {&grad_reference, &grad_centroid, &grad_illumination})
              if (a->ndim() != 1 || a->shape(0) != f)
                throw Error("the field gradients must have " + std::to_string(f) + " entries");
            std::vector<double> gx(n, 0.0);
            const double* gp = grad_psf.data();
            const double *gr = grad_reference.data(), *gc = grad_centroid.data(),
                         *gi = grad_illumination.data();
            {
              py::gil_scoped_release release;
              const std::size_t cells = static_cast<std::size_t>(g) * g;
              for (int h = 0; h < f; ++h) {
                for (int c = 0; c < kColourChannels; ++c) {
                  const double* gpc =
                      gp + (static_cast<std::size_t>(h) * kColourChannels + c) * cells;
                  const auto& box = o.support[h][c];
                  const double* d = o.d_psf[h][c].data();
                  for (int r = box[0]; r < box[1]; ++r)
                    for (int i = box[2]; i < box[3]; ++i, d += n) {
                      const double v = gpc[static_cast<std::size_t>(r) * g + i];
                      if (v == 0.0) continue;
                      for (int j = 0; j < n; ++j) gx[j] += v * d[j];
                    }
                }
                for (int j = 0; j < n; ++j) {
                  const std::size_t k = static_cast<std::size_t>(h) * n + j;
                  gx[j] += gr[h] * o.d_reference[k] + gc[h] * o.d_centroid[k] +
                           gi[h] * o.d_illumination[k];
                }
              }
            }
            return to_numpy(std::move(gx), {n});
          },
          py::arg("grad_psf"), py::arg("grad_reference_y"), py::arg("grad_centroid_y"),
          py::arg("grad_illumination"),
          "dL/dx (n) for dL/d(the optics of the last prepare()): dL/dpsf (F x 3 x G x G) and "
          "dL/dy_ref, dL/dybar, dL/dRI (F each), by the Jets' derivative parts (needs a prepare "
          "with derivatives). lensopt.torch chains torch's gradients of the PSFs and maps with it.")
      .def(
          "layout",
          [](const PyImaging& p, int width, int height) {
            ImagingLayout l;
            {
              py::gil_scoped_release release;
              l = p.imaging->layout(width, height);
            }
            const int q = static_cast<int>(l.patches.size());
            const int f = q > 0 ? static_cast<int>(l.patches[0].field_weights.size()) : 0;
            const std::size_t cells = static_cast<std::size_t>(p.grid_size) * p.grid_size;
            std::vector<int> radius(q), corner(q * cells);
            std::vector<double> azimuth(q), weights(static_cast<std::size_t>(q) * f), fx(q * cells),
                fy(q * cells);
            for (int k = 0; k < q; ++k) {
              const ImagingPatchLayout& pl = l.patches[k];
              radius[k] = pl.radius;
              azimuth[k] = pl.azimuth_rad;
              std::copy(pl.field_weights.begin(), pl.field_weights.end(),
                        weights.begin() + static_cast<std::size_t>(k) * f);
              std::copy(pl.corner.begin(), pl.corner.end(), corner.begin() + k * cells);
              std::copy(pl.fx.begin(), pl.fx.end(), fx.begin() + k * cells);
              std::copy(pl.fy.begin(), pl.fy.end(), fy.begin() + k * cells);
            }
            auto rows = [](const std::vector<std::vector<double>>& w, int extent) {
              std::vector<double> v;
              for (const auto& row : w) v.insert(v.end(), row.begin(), row.end());
              return to_numpy(std::move(v), {static_cast<py::ssize_t>(w.size()), extent});
            };
            auto ints = [](std::vector<int> v) {
              const auto size = static_cast<py::ssize_t>(v.size());
              return to_numpy(std::move(v), {size});
            };
            const auto g = static_cast<py::ssize_t>(p.grid_size);
            py::dict out;
            out["width"] = l.width;
            out["height"] = l.height;
            out["pitch_mm"] = l.pitch_mm;
            out["axis_x"] = l.axis_x;
            out["axis_y"] = l.axis_y;
            out["window_x"] = rows(l.window_x, l.width);
            out["window_y"] = rows(l.window_y, l.height);
            out["lo_x"] = ints(l.lo_x);
            out["hi_x"] = ints(l.hi_x);
            out["lo_y"] = ints(l.lo_y);
            out["hi_y"] = ints(l.hi_y);
            out["max_radius"] = l.max_radius;
            out["radius"] = ints(std::move(radius));
            out["azimuth_rad"] = to_numpy(std::move(azimuth), {q});
            out["field_weights"] = to_numpy(std::move(weights), {q, f});
            out["corner"] = to_numpy(std::move(corner), {q, g * g});
            out["fx"] = to_numpy(std::move(fx), {q, g * g});
            out["fy"] = to_numpy(std::move(fy), {q, g * g});
            return out;
          },
          py::arg("width"), py::arg("height"),
          "The layout render() uses for a width x height full image under the last prepare(): "
          "sensor geometry (pitch_mm, axis_x, axis_y), the 9 x 9 patches' overlap windows "
          "(window_x 9 x W, window_y 9 x H, their extents lo/hi), and per patch q = py * 9 + px "
          "its kernel radius, azimuth, field weights a_qh (81 x F) and PSF-to-pixel resampling "
          "(corner, fx, fy: 81 x G^2, corner -1 for bins out of reach).")
      .def_property_readonly("timings", [](const PyImaging& p) {
        const ImagingTimings& t = p.imaging->timings();
        py::dict d;
        d["trace_s"] = t.trace_s;
        d["psf_s"] = t.psf_s;
        d["kernels_s"] = t.kernels_s;
        d["render_s"] = t.render_s;
        d["adjoint_s"] = t.adjoint_s;
        return d;
      });
}

}  // namespace lensopt::python
