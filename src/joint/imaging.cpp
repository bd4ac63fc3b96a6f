// Differentiable image formation (joint/imaging.h): the rendering of a crop in double and the
// public class; the optics sampled with Jets are in optics_sampling.cpp, the patch kernels in
// patch_kernels.cpp, the adjoint in imaging_backward.cpp (src/joint/imaging_detail.h).
//
// Rendering a crop (full-image coordinates; the Renderer's steps, in double: the blocks of
// render/overlap_add.h, the inverse map of render/distortion_warp.h, the mixing of
// render/psf_resample.h):
//   out(p) = sum_taps k(u - i) k(v - j) B'(clamp(i), clamp(j)),  (u, v) = s(p) - 1/2,
//   s(p) = a + (p + 1/2 - a) rho(r')/r',  rho = interp((ybar_h, y_ref,h), r') (extended),
//   B'(p) = R(r(p)) B(p),  R = interp((y_ref,h, R_h), r) (clamped),
//   B(p) = sum_q w_q(p) (K_q * S_ext)(p),  S_ext the scene reflected at the borders,
// with k the Keys cubic (core/interpolate.h) and black where s(p) leaves the image. Only the
// region of B the crop's taps reach is computed: per patch q whose window meets it, the window
// extent inside the region plus r_q on each side, convolved by FFT (render/fft.h) in double.
// Adjoint, for G = dL/d(out):
//   dL/dB'(t) = sum_p k k G(p)              (the warp's transpose: a scatter),
//   dL/du(p) = sum_c G(p, c) sum_taps k'(u - i) k(v - j) B'(c)   (and v),
//   dL/drho(p) = (dL/du (p_x + 1/2 - a_x) + dL/dv (p_y + 1/2 - a_y)) / r'  (pixels per mm),
//   then to ybar_k, ybar_k+1, y_ref,k, y_ref,k+1 by the piece's partials;
//   dL/dB(p, c) = R(p) dL/dB'(p, c),  dL/dR(p) = sum_c dL/dB'(p, c) B(p, c), then to R_k, R_k+1,
//   y_ref,k, y_ref,k+1;
//   dL/dK_q[c](d) = sum_p w_q(p) dL/dB(p, c) S_ext(p - d)  (a correlation, by FFT: the product
//   of the spectrum of (w_q dL/dB) and the conjugate spectrum of the scene block).
// backward() recomputes B unless render() of the same crop, scene (hashed) and prepare() left it
// in a small cache; it always needs the scene blocks' spectra for the correlations.
// Grey images (1 or 2 channels) use the mean kernel (K_q[0] + K_q[1] + K_q[2]) / 3: its gradient
// goes 1/3 to each. Further channels (alpha) are not blurred or dimmed, only warped.
#include "lensopt/joint/imaging.h"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstring>
#include <limits>

#include "imaging_detail.h"
#include "lensopt/analysis/afocal.h"
#include "lensopt/core/error.h"
#include "lensopt/core/interpolate.h"
#include "lensopt/core/threads.h"
#include "lensopt/render/distortion_warp.h"
#include "render/overlap_add.h"

namespace lensopt {

void DifferentiableImagingOptions::validate() const {
  sampling.validate();
  psf.validate();
  if (res_factor != 1 && res_factor != 2)
    throw Error(fmt::format("resolution factor {} must be 1 or 2", res_factor));
  if (threads < 0 || threads > 1024)
    throw Error(fmt::format("threads = {} must be in [0, 1024]", threads));
}

namespace imaging_detail {

void check_inputs(const SceneWindow& scene, const CropWindow& crop) {
  if (scene.pixels.empty() || scene.width <= 0 || scene.height <= 0)
    throw Error("joint imaging: empty scene image");
  if (crop.width <= 0 || crop.height <= 0 || crop.x0 < 0 || crop.y0 < 0 ||
      crop.x0 + crop.width > scene.width || crop.y0 + crop.height > scene.height) {
    throw Error(fmt::format("crop {}x{} at ({}, {}) is not inside the {}x{} scene", crop.width,
                            crop.height, crop.x0, crop.y0, scene.width, scene.height));
  }
}

CropWindow read_window(const CropPlan& p, const Geometry& g) {
  const int x0 = std::max(0, p.rx0 - g.max_radius),
            x1 = std::min(g.width, p.rx0 + p.rw + g.max_radius);
  const int y0 = std::max(0, p.ry0 - g.max_radius),
            y1 = std::min(g.height, p.ry0 + p.rh + g.max_radius);
  return CropWindow{x0, y0, x1 - x0, y1 - y0};
}

void check_window(const SceneWindow& scene, const CropPlan& p, const Geometry& g) {
  const CropWindow w = read_window(p, g);
  const FloatImage& px = scene.pixels;
  if (w.x0 < scene.x0 || w.y0 < scene.y0 || w.x0 + w.width > scene.x0 + px.width ||
      w.y0 + w.height > scene.y0 + px.height) {
    throw Error(fmt::format(
        "joint imaging: the scene window {}x{} at ({}, {}) does not hold the pixels {}x{} at "
        "({}, {}) that crop {}x{} at ({}, {}) reads",
        px.width, px.height, scene.x0, scene.y0, w.width, w.height, w.x0, w.y0, p.crop.width,
        p.crop.height, p.crop.x0, p.crop.y0));
  }
}

WarpTaps warp_taps(const CropPlan& p, const Geometry& g, std::size_t k, bool derivatives) {
  WarpTaps w;
  const int x0 = static_cast<int>(std::floor(p.u[k])), y0 = static_cast<int>(std::floor(p.v[k]));
  keys_weights(p.u[k] - x0, w.wx);
  keys_weights(p.v[k] - y0, w.wy);
  if (derivatives) {
    keys_weight_derivatives(p.u[k] - x0, w.dwx);
    keys_weight_derivatives(p.v[k] - y0, w.dwy);
  }
  for (int m = 0; m < 4; ++m) {
    const int y = std::clamp(y0 - 1 + m, 0, g.height - 1) - p.ry0;
    for (int t = 0; t < 4; ++t) {
      const int x = std::clamp(x0 - 1 + t, 0, g.width - 1) - p.rx0;
      w.index[m][t] = static_cast<std::size_t>(y) * p.rw + x;
    }
  }
  return w;
}

const std::vector<double>& task_kernel(const Geometry& g, const CropPlan& p, const BlurTask& t) {
  const PatchKernels& pk = g.patches[t.q];
  return p.colours == kColourChannels ? pk.kernel[t.c] : pk.grey;
}

}  // namespace imaging_detail

using namespace imaging_detail;

std::shared_ptr<const CropPlan> DifferentiableImaging::State::plan(int channels,
                                                                   const CropWindow& crop,
                                                                   const Geometry& g) const {
  const int colours = colour_channel_count(channels);
  auto same = [&](const PlanEntry& e) {
    return e.width == g.width && e.height == g.height && e.colours == colours &&
           e.crop.x0 == crop.x0 && e.crop.y0 == crop.y0 && e.crop.width == crop.width &&
           e.crop.height == crop.height;
  };
  {
    std::lock_guard<std::mutex> lock(plan_mutex);
    for (const PlanEntry& e : plan_cache)
      if (same(e)) return e.plan;
  }
  auto made = std::make_shared<const CropPlan>(make_plan(channels, crop, g));
  std::lock_guard<std::mutex> lock(plan_mutex);
  if (plan_cache.size() >= kPlanEntries) plan_cache.erase(plan_cache.begin());
  plan_cache.push_back(PlanEntry{g.width, g.height, colours, crop, made});
  return made;
}

CropPlan DifferentiableImaging::State::make_plan(int channels, const CropWindow& crop,
                                                 const Geometry& g) const {
  CropPlan p;
  p.crop = crop;
  p.colours = colour_channel_count(channels);
  p.warp = options.distortion;
  const int width = g.width, height = g.height;
  const SensorGeometry& geo = g.layout.geometry;
  int x_lo = crop.x0, x_hi = crop.x0 + crop.width, y_lo = crop.y0, y_hi = crop.y0 + crop.height;
  if (p.warp) {
    const std::vector<double>& ybar = optics.centroid_y_mm;
    const std::vector<double>& yref = optics.reference_y_mm;
    for (std::size_t h = 1; h < ybar.size(); ++h) {
      if (!(ybar[h] > ybar[h - 1])) {
        throw Error(fmt::format(
            "cannot apply distortion: the image heights of fields {:.2f} and {:.2f} deg do not "
            "increase ({:.6f}, {:.6f} mm)",
            optics.fields_deg[h - 1], optics.fields_deg[h], ybar[h - 1], ybar[h]));
      }
    }
    const InverseDistortion inverse(ybar, yref);
    const std::size_t count = static_cast<std::size_t>(crop.width) * crop.height;
    p.u.assign(count, std::numeric_limits<double>::quiet_NaN());
    p.v.assign(count, std::numeric_limits<double>::quiet_NaN());
    x_lo = width;
    x_hi = 0;
    y_lo = height;
    y_hi = 0;
    for (int j = 0; j < crop.height; ++j) {
      for (int i = 0; i < crop.width; ++i) {
        double sx, sy;
        if (!inverse.source(geo, crop.x0 + i, crop.y0 + j, sx, sy)) continue;
        const std::size_t k = static_cast<std::size_t>(j) * crop.width + i;
        p.u[k] = sx - 0.5;
        p.v[k] = sy - 0.5;
        const int fx = static_cast<int>(std::floor(p.u[k])),
                  fy = static_cast<int>(std::floor(p.v[k]));
        x_lo = std::min(x_lo, std::clamp(fx - 1, 0, width - 1));
        x_hi = std::max(x_hi, std::clamp(fx + 2, 0, width - 1) + 1);
        y_lo = std::min(y_lo, std::clamp(fy - 1, 0, height - 1));
        y_hi = std::max(y_hi, std::clamp(fy + 2, 0, height - 1) + 1);
      }
    }
    if (x_hi <= x_lo || y_hi <= y_lo) {  // every sample black
      x_lo = crop.x0;
      x_hi = crop.x0 + 1;
      y_lo = crop.y0;
      y_hi = crop.y0 + 1;
    }
  }
  p.rx0 = x_lo;
  p.ry0 = y_lo;
  p.rw = x_hi - x_lo;
  p.rh = y_hi - y_lo;
  constexpr int n = PsfGrid::kPatches;
  for (int py = 0; py < n; ++py) {
    const int y0 = std::max(g.lo_y[py], y_lo), y1 = std::min(g.hi_y[py], y_hi);
    if (y1 <= y0) continue;
    for (int px = 0; px < n; ++px) {
      const int x0 = std::max(g.lo_x[px], x_lo), x1 = std::min(g.hi_x[px], x_hi);
      if (x1 <= x0) continue;
      const int q = g.layout.patch_index(px, py);
      for (int c = 0; c < p.colours; ++c) {
        BlurTask t;
        t.q = q;
        t.c = c;
        t.x0 = x0;
        t.x1 = x1;
        t.y0 = y0;
        t.y1 = y1;
        t.radius = g.patches[q].radius;
        t.nx = fft_size(x1 - x0 + 2 * t.radius);
        t.ny = fft_size(y1 - y0 + 2 * t.radius);
        p.tasks.push_back(t);
      }
    }
  }
  return p;
}

std::uint64_t DifferentiableImaging::State::scene_hash(const SceneWindow& scene, const CropPlan& p,
                                                       const Geometry& g) const {
  const CropWindow w = read_window(p, g);
  const FloatImage& px = scene.pixels;
  std::uint64_t h = 1469598103934665603ull;
  for (int j = w.y0; j < w.y0 + w.height; ++j) {
    const float* row = px.pixels.data() + px.index(w.x0 - scene.x0, j - scene.y0, 0);
    const std::size_t count = static_cast<std::size_t>(w.width) * px.channels;
    for (std::size_t i = 0; i < count; ++i) {
      std::uint32_t bits;
      std::memcpy(&bits, row + i, sizeof bits);
      h = (h ^ bits) * 1099511628211ull;
    }
  }
  return h;
}

void DifferentiableImaging::State::blur_region(
    const SceneWindow& scene, const CropPlan& p, const Geometry& g, std::vector<double>* blurred,
    std::vector<std::vector<std::complex<double>>>* spectra) const {
  const std::size_t plane = static_cast<std::size_t>(p.rw) * p.rh;
  const int channels = scene.pixels.channels;
  if (blurred) {
    blurred->assign(plane * channels, 0.0);
    // Channels that are not blurred (alpha): copied.
    for (int c = p.colours; c < channels; ++c)
      for (int j = 0; j < p.rh; ++j)
        for (int i = 0; i < p.rw; ++i)
          (*blurred)[plane * c + static_cast<std::size_t>(j) * p.rw + i] =
              scene.pixels.at(p.rx0 - scene.x0 + i, p.ry0 - scene.y0 + j, c);
  }
  const int tasks = static_cast<int>(p.tasks.size());
  if (spectra) spectra->assign(tasks, {});
  const int nthreads = thread_count(options.threads);
  // Each task's windowed output in its own buffer, added in task order afterwards: the sum does
  // not depend on which thread ran which task (runs are reproducible to the last bit).
  std::vector<std::vector<double>> outputs(blurred ? tasks : 0);
#pragma omp parallel for schedule(dynamic, 1) num_threads(nthreads)
  for (int ti = 0; ti < tasks; ++ti) {
    const BlurTask& t = p.tasks[ti];
    const int r = t.radius;
    OverlapAddBuffers buffers(t.ny, t.nx);
    // K^ first (the buffers are its scratch), then the scene block
    // [x0 - r, x1 + r) x [y0 - r, y1 + r), reflected at the borders, and its spectrum.
    std::vector<std::complex<double>> kernel;
    if (blurred) kernel_spectrum(task_kernel(g, p, t).data(), r, buffers, kernel);
    load_reflected_block(scene.pixels, scene.x0, scene.y0, scene.width, scene.height, t.c, t.x0 - r,
                         t.y0 - r, t.x1 - t.x0 + 2 * r, t.y1 - t.y0 + 2 * r, buffers);
    if (spectra) {
      const std::complex<double>* s = buffers.complex_spectrum();
      (*spectra)[ti].assign(s, s + buffers.spectrum_size());
    }
    if (!blurred) continue;
    convolve_loaded_block(kernel.data(), buffers);
    const int px = t.q % PsfGrid::kPatches, py = t.q / PsfGrid::kPatches;
    std::vector<double>& out = outputs[ti];
    out.assign(static_cast<std::size_t>(t.x1 - t.x0) * (t.y1 - t.y0), 0.0);
    add_windowed_block(buffers, r, t.x0, t.x1, t.y0, t.y1, g.window_x[px], g.window_y[py],
                       out.data(), t.x1 - t.x0, t.x0, t.y0);
  }
  if (!blurred) return;
  for (int ti = 0; ti < tasks; ++ti) {
    const BlurTask& t = p.tasks[ti];
    const double* src = outputs[ti].data();
    for (int j = t.y0; j < t.y1; ++j) {
      double* dst = blurred->data() + plane * t.c + static_cast<std::size_t>(j - p.ry0) * p.rw +
                    (t.x0 - p.rx0);
      for (int i = 0; i < t.x1 - t.x0; ++i) dst[i] += *src++;
    }
  }
}

DifferentiableImaging::DifferentiableImaging(const LensParameterization& param, GlassMode mode,
                                             std::vector<int> fixed_glasses,
                                             DifferentiableImagingOptions options)
    : state_(new State(param, mode, std::move(fixed_glasses), std::move(options))) {
  state_->options.validate();
  // A render of the image plane (the one policy for afocal lenses, analysis/afocal.h).
  refuse_afocal(param.structure(),
                "joint image formation (optimize --joint, lensopt.Imaging, "
                "lensopt.torch.ImageFormation)");
  const Specs& specs = param.structure().specs;
  validate_wavelength_channels(specs.wavelength_channels,
                               static_cast<int>(specs.wavelengths_nm.size()));
  state_->sensor_diagonal_mm = specs.sensor_diagonal_mm;
}

DifferentiableImaging::~DifferentiableImaging() {
  delete state_;
}

ImagingTimings DifferentiableImaging::timings() const {
  return state_->timings.snapshot();
}

void DifferentiableImaging::prepare(const std::vector<double>& x, bool derivatives) {
  State& s = *state_;
  if (static_cast<int>(x.size()) != s.param.size()) {
    throw Error(fmt::format("joint imaging: {} variables given, the lens has {}", x.size(),
                            s.param.size()));
  }
  ImagingTimings t;
  Optics optics = sample_optics(s.param, s.mode, s.fixed_glasses, s.options, x, derivatives, t);
  s.timings.trace_s.store(t.trace_s);
  s.timings.psf_s.store(t.psf_s);
  for (std::size_t h = 1; h < optics.reference_y_mm.size(); ++h) {
    if (!(optics.reference_y_mm[h] > optics.reference_y_mm[h - 1])) {
      throw Error("cannot render: the paraxial image heights do not increase with the field");
    }
  }
  std::lock_guard<std::mutex> lock(s.mutex);
  s.optics = std::move(optics);
  s.geometries.clear();
  s.prepared = true;
  ++s.generation;
  std::lock_guard<std::mutex> forward_lock(s.forward_mutex);
  s.forward_cache.clear();
  std::lock_guard<std::mutex> plan_lock(s.plan_mutex);
  s.plan_cache.clear();
}

FloatImage DifferentiableImaging::render(const FloatImage& scene, const CropWindow& crop) const {
  const std::vector<double> values = render_values(scene, crop);
  FloatImage out(crop.width, crop.height, scene.channels);
  for (std::size_t i = 0; i < values.size(); ++i) out.pixels[i] = static_cast<float>(values[i]);
  return out;
}

std::vector<double> DifferentiableImaging::render_values(const FloatImage& scene,
                                                         const CropWindow& crop) const {
  return render_values(whole(scene), crop);
}

CropWindow DifferentiableImaging::scene_window(int width, int height, int channels,
                                               const CropWindow& crop) const {
  if (channels <= 0) throw Error(fmt::format("joint imaging: {} channels", channels));
  check_inputs(SceneWindow{FloatImage(1, 1, channels), 0, 0, width, height}, crop);
  const State& s = *state_;
  const std::shared_ptr<Geometry> g = s.geometry(width, height);
  return read_window(*s.plan(channels, crop, *g), *g);
}

std::vector<double> DifferentiableImaging::render_values(const SceneWindow& scene,
                                                         const CropWindow& crop) const {
  const auto start = Clock::now();
  check_inputs(scene, crop);
  const State& s = *state_;
  const std::shared_ptr<Geometry> g = s.geometry(scene.width, scene.height);
  const std::shared_ptr<const CropPlan> plan = s.plan(scene.pixels.channels, crop, *g);
  const CropPlan& p = *plan;
  check_window(scene, p, *g);
  std::vector<double> b;
  s.blur_region(scene, p, *g, &b, nullptr);
  {
    State::ForwardEntry e;
    e.generation = s.generation;
    e.scene_hash = s.scene_hash(scene, p, *g);
    e.width = scene.width;
    e.height = scene.height;
    e.channels = scene.pixels.channels;
    e.crop = crop;
    e.blurred = std::make_shared<const std::vector<double>>(b);
    std::lock_guard<std::mutex> lock(s.forward_mutex);
    if (s.forward_cache.size() >= State::kForwardEntries)
      s.forward_cache.erase(s.forward_cache.begin());
    s.forward_cache.push_back(std::move(e));
  }
  const std::size_t plane = static_cast<std::size_t>(p.rw) * p.rh;
  const SensorGeometry& geo = g->layout.geometry;
  // Relative illumination on the colour channels.
  if (s.options.relative_illumination) {
    for (int j = 0; j < p.rh; ++j) {
      for (int i = 0; i < p.rw; ++i) {
        const double ri = interpolate_linear(s.optics.reference_y_mm, s.optics.illumination,
                                             geo.radius_mm(p.rx0 + i, p.ry0 + j), false);
        for (int c = 0; c < p.colours; ++c)
          b[plane * c + static_cast<std::size_t>(j) * p.rw + i] *= ri;
      }
    }
  }
  const int channels = scene.pixels.channels;
  std::vector<double> out(static_cast<std::size_t>(crop.width) * crop.height * channels, 0.0);
  auto at = [&](int i, int j, int c) -> double& {
    return out[(static_cast<std::size_t>(j) * crop.width + i) * channels + c];
  };
  if (!p.warp) {
    for (int j = 0; j < crop.height; ++j)
      for (int i = 0; i < crop.width; ++i)
        for (int c = 0; c < channels; ++c)
          at(i, j, c) = (b[plane * c + static_cast<std::size_t>(crop.y0 + j - p.ry0) * p.rw +
                           (crop.x0 + i - p.rx0)]);
  } else {
    for (int j = 0; j < crop.height; ++j) {
      for (int i = 0; i < crop.width; ++i) {
        const std::size_t k = static_cast<std::size_t>(j) * crop.width + i;
        if (std::isnan(p.u[k])) continue;
        const WarpTaps w = warp_taps(p, *g, k, false);
        for (int c = 0; c < channels; ++c) {
          const double* bc = b.data() + plane * c;
          double acc = 0;
          for (int m = 0; m < 4; ++m)
            for (int t = 0; t < 4; ++t) acc += w.wy[m] * w.wx[t] * bc[w.index[m][t]];
          at(i, j, c) = acc;
        }
      }
    }
  }
  s.timings.render_s.store(seconds_since(start));
  return out;
}

const ImagingOptics& DifferentiableImaging::optics() const {
  if (!state_->prepared) throw Error("DifferentiableImaging: call prepare(x) before optics()");
  return state_->optics;
}

ImagingLayout DifferentiableImaging::layout(int width, int height) const {
  if (width <= 0 || height <= 0)
    throw Error(fmt::format("joint imaging: image size {}x{} must be positive", width, height));
  const std::shared_ptr<Geometry> g = state_->geometry(width, height);
  ImagingLayout l;
  l.width = width;
  l.height = height;
  l.pitch_mm = g->layout.geometry.pitch_mm;
  l.axis_x = g->layout.geometry.axis_x;
  l.axis_y = g->layout.geometry.axis_y;
  l.window_x = g->window_x;
  l.window_y = g->window_y;
  l.lo_x = g->lo_x;
  l.hi_x = g->hi_x;
  l.lo_y = g->lo_y;
  l.hi_y = g->hi_y;
  l.max_radius = g->max_radius;
  l.patches.resize(g->patches.size());
  for (std::size_t q = 0; q < g->patches.size(); ++q) {
    const PatchKernels& pk = g->patches[q];
    ImagingPatchLayout& p = l.patches[q];
    p.radius = pk.radius;
    p.azimuth_rad = g->layout.azimuth_rad[q];
    p.field_weights = g->layout.field_weights[q];
    p.corner = pk.resampling.corner;
    p.fx = pk.resampling.fx;
    p.fy = pk.resampling.fy;
  }
  return l;
}

}  // namespace lensopt
