// Differentiable image formation (joint/imaging.h): the optics sampled with Jets, the rendering
// of a crop in double, and its adjoint.
//
// Optics. The variables x are seeded as Jets of width N >= param.size() (one of kJetWidths), so
// one traced system carries dP_h/dx, dR_h/dx, dy_ref,h/dx and dybar_h/dx. They are stored as
// values plus derivative rows (for a PSF only the bins inside its support box); no Jet outlives
// prepare().
//
// Patch kernels (per full-image size, cached until the next prepare()). K_q[c] is linear in the
// field PSFs with fixed weights: K_q[c] = L_q (sum_h a_qh P_h[c]) / T (render/psf_resample.h),
// a_qh fixed by the value of y_ref (piecewise constant in x: no derivative), L_q fixed by the
// geometry, and the radius r_q (the largest channel's, so every channel's kernel, and the grey
// mean, share one size) fixed per prepare(). The adjoint therefore goes through L_q^T to the
// field PSFs, and the Jets' derivative parts are contracted there:
//   dL/dP_h[c] = sum_q a_qh L_q^T-adjoint(dL/dK_q[c]),  dL/dx_j += sum dL/dP_h[c] dP_h[c]/dx_j.
//
// Rendering a crop (full-image coordinates; the same steps as the Renderer, in double):
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
#include <chrono>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <type_traits>

#include "core/fft.h"
#include "lensopt/analysis/field_maps.h"
#include "lensopt/core/error.h"
#include "lensopt/core/interpolate.h"
#include "lensopt/render/psf_resample.h"
#include "lensopt/render/render.h"

namespace lensopt {

void DifferentiableImagingOptions::validate() const {
  sampling.validate();
  psf.validate();
  if (res_factor != 1 && res_factor != 2)
    throw Error(fmt::format("resolution factor {} must be 1 or 2", res_factor));
  if (threads < 0 || threads > 1024)
    throw Error(fmt::format("threads = {} must be in [0, 1024]", threads));
}

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Jet widths compiled (one derivative per variable; the smallest that holds param.size()).
constexpr int kJetWidths[] = {8, 12, 16, 24, 32};

using Optics = ImagingOptics;

// The value and derivative parts of a double (no derivatives) or a Jet.
inline double value_part(double v) {
  return v;
}
template <int N>
double value_part(const ceres::Jet<double, N>& v) {
  return v.a;
}
inline void derivative_part(double, int, double*) {}
template <int N>
void derivative_part(const ceres::Jet<double, N>& v, int n, double* out) {
  for (int j = 0; j < n; ++j) out[j] = v.v[j];
}
inline double seed_variable(double x, int, double*) {
  return x;
}
template <int N>
ceres::Jet<double, N> seed_variable(double x, int j, ceres::Jet<double, N>*) {
  return ceres::Jet<double, N>(x, j);
}

// J = double samples the values only (o.derivatives = 0), a Jet also the derivatives.
template <typename J>
Optics sample_optics(const LensParameterization& param, GlassMode mode,
                     const std::vector<int>& fixed_glasses,
                     const DifferentiableImagingOptions& options, const std::vector<double>& x,
                     ImagingTimings& timings) {
  constexpr bool kJets = !std::is_same_v<J, double>;
  const int n = kJets ? param.size() : 0;  // derivatives stored per value
  Specs specs = param.structure().specs;
  specs.mode = SpecMode::kPaper;  // the paper's sampling in every spec mode
  auto start = Clock::now();
  std::vector<J> xj(x.size());
  for (std::size_t j = 0; j < x.size(); ++j)
    xj[j] = seed_variable(x[j], static_cast<int>(j), static_cast<J*>(nullptr));
  const TraceLens<J> lens = param.to_trace_lens(xj.data(), mode, fixed_glasses);
  const TraceSystem<J> sys = prepare_system(lens, specs, options.sampling);
  const std::vector<J> y_ref = reference_heights(sys);
  const std::vector<J> ri = relative_illuminations(sys);
  timings.trace_s = seconds_since(start);

  start = Clock::now();
  const int trace_threads =
      options.sampling.threads > 0 ? options.sampling.threads : options.threads;
  const PsfSet<J> psfs = compute_psfs(sys, specs.wavelength_channels, options.psf, trace_threads);
  Optics o;
  o.variables = n;  // 0: values only
  o.fields_deg = sys.fields_deg;
  const int fields = static_cast<int>(sys.fields_deg.size());
  auto store = [n](const J& v, std::vector<double>& values, std::vector<double>& derivatives) {
    values.push_back(value_part(v));
    derivatives.resize(derivatives.size() + n);
    derivative_part(v, n, derivatives.data() + derivatives.size() - n);
  };
  for (int h = 0; h < fields; ++h) {
    store(y_ref[h], o.reference_y_mm, o.d_reference);
    store(psfs.fields[h].centroid_y_mm, o.centroid_y_mm, o.d_centroid);
    store(ri[h], o.illumination, o.d_illumination);
  }
  o.psf.resize(fields);
  o.d_psf.resize(fields);
  o.support.resize(fields);
  for (int h = 0; h < fields; ++h) o.support[h] = psfs.fields[h].support;
  const int g = options.psf.grid_size;
  const std::size_t cells = static_cast<std::size_t>(options.psf.grid_size) * options.psf.grid_size;
#pragma omp parallel for collapse(2) \
    num_threads(options.threads > 0 ? options.threads : omp_get_max_threads())
  for (int h = 0; h < fields; ++h) {
    for (int c = 0; c < kColourChannels; ++c) {
      const std::vector<J>& grid = psfs.fields[h].psf[c];
      const std::array<int, 4>& box = o.support[h][c];
      std::vector<double>& values = o.psf[h][c];
      std::vector<double>& derivatives = o.d_psf[h][c];
      values.assign(cells, 0.0);
      derivatives.resize(static_cast<std::size_t>(box[1] - box[0]) * (box[3] - box[2]) * n);
      double* d = derivatives.data();
      for (int r = box[0]; r < box[1]; ++r) {
        for (int i = box[2]; i < box[3]; ++i, d += n) {
          const J& v = grid[static_cast<std::size_t>(r) * g + i];
          values[static_cast<std::size_t>(r) * g + i] = value_part(v);
          derivative_part(v, n, d);
        }
      }
    }
  }
  for (int h = 0; h < fields; ++h) {
    const FieldPsf<J>& f = psfs.fields[h];
    o.ray_failures += f.failed_rays;
    if (f.traced_rays[0] + f.traced_rays[1] + f.traced_rays[2] == 0) {
      throw Error(fmt::format("cannot render: no ray of field {:.2f} deg reaches the image",
                              sys.fields_deg[h]));
    }
  }
  timings.psf_s = seconds_since(start);
  return o;
}

template <std::size_t I = 0>
Optics sample_optics_any(int width, const LensParameterization& param, GlassMode mode,
                         const std::vector<int>& fixed_glasses,
                         const DifferentiableImagingOptions& options, const std::vector<double>& x,
                         ImagingTimings& timings) {
  constexpr std::size_t kCount = sizeof(kJetWidths) / sizeof(kJetWidths[0]);
  if constexpr (I < kCount) {
    if (width <= kJetWidths[I])
      return sample_optics<ceres::Jet<double, kJetWidths[I]>>(param, mode, fixed_glasses, options,
                                                              x, timings);
    return sample_optics_any<I + 1>(width, param, mode, fixed_glasses, options, x, timings);
  } else {
    throw Error(fmt::format("joint imaging supports up to {} lens variables, the lens has {}",
                            kJetWidths[kCount - 1], width));
  }
}

// One patch's kernels at a common radius: per colour channel the mixed field PSF and its
// kernel, and the grey mean.
struct PatchKernels {
  int radius = 0;
  PsfResampling resampling;
  std::array<std::vector<double>, kColourChannels> mixed;   // sum_h a_qh P_h[c]
  std::array<std::vector<double>, kColourChannels> kernel;  // (2r+1)^2
  std::vector<double> grey;
};

// Everything of one full-image size: layout, windows, kernels.
struct Geometry {
  int width = 0, height = 0;
  PsfGrid layout;
  std::vector<std::vector<double>> window_x, window_y;  // [patch][pixel]
  std::vector<int> lo_x, hi_x, lo_y, hi_y;              // window extents
  std::vector<PatchKernels> patches;
  int max_radius = 0;
};

int thread_count(int threads) {
  return threads > 0 ? threads : omp_get_max_threads();
}

std::shared_ptr<Geometry> make_geometry(const Optics& o, const DifferentiableImagingOptions& opt,
                                        double sensor_diagonal_mm, int width, int height) {
  auto g = std::make_shared<Geometry>();
  g->width = width;
  g->height = height;
  g->layout =
      make_psf_grid_layout(o.reference_y_mm, sensor_diagonal_mm, width, height, opt.res_factor);
  g->window_x = overlap_windows(g->layout.bounds_x, width, 0);
  g->window_y = overlap_windows(g->layout.bounds_y, height, 0);
  overlap_window_extents(g->window_x, g->lo_x, g->hi_x);
  overlap_window_extents(g->window_y, g->lo_y, g->hi_y);
  constexpr int n = PsfGrid::kPatches;
  const int fields = static_cast<int>(o.psf.size());
  const std::size_t cells = static_cast<std::size_t>(opt.psf.grid_size) * opt.psf.grid_size;
  const double pitch_um = g->layout.geometry.pitch_mm * 1000.0;
  g->patches.resize(n * n);
#pragma omp parallel for schedule(dynamic, 1) num_threads(thread_count(opt.threads))
  for (int q = 0; q < n * n; ++q) {
    PatchKernels& pk = g->patches[q];
    const std::vector<double>& a = g->layout.field_weights[q];
    const double azimuth = g->layout.azimuth_rad[q];
    int radius = 0;
    for (int c = 0; c < kColourChannels; ++c) {
      pk.mixed[c].assign(cells, 0.0);
      for (int h = 0; h < fields; ++h) {
        if (a[h] == 0.0) continue;
        const std::vector<double>& psf = o.psf[h][c];
        for (std::size_t i = 0; i < cells; ++i) pk.mixed[c][i] += a[h] * psf[i];
      }
      radius = std::max(radius, psf_kernel_radius(pk.mixed[c], opt.psf, azimuth, pitch_um));
    }
    pk.radius = radius;
    pk.resampling = PsfResampling::make(opt.psf, azimuth, pitch_um, radius);
    const int size = 2 * radius + 1;
    pk.grey.assign(static_cast<std::size_t>(size) * size, 0.0);
    for (int c = 0; c < kColourChannels; ++c) {
      if (!resample_psf(pk.resampling, pk.mixed[c].data(), pk.kernel[c])) {
        pk.kernel[c].assign(static_cast<std::size_t>(size) * size, 0.0);  // unit kernel
        pk.kernel[c][static_cast<std::size_t>(radius) * size + radius] = 1.0;
      }
      for (std::size_t i = 0; i < pk.grey.size(); ++i)
        pk.grey[i] += pk.kernel[c][i] / kColourChannels;
    }
  }
  for (const PatchKernels& pk : g->patches) g->max_radius = std::max(g->max_radius, pk.radius);
  check_image_holds_psf(width, height, g->max_radius, pitch_um);
  return g;
}

// One convolution of the blur: patch q, channel c, over [x0, x1) x [y0, y1) (full image).
struct BlurTask {
  int q = 0, c = 0;
  int x0 = 0, x1 = 0, y0 = 0, y1 = 0;
  int radius = 0, nx = 0, ny = 0;
};

// What a crop needs: the blurred region, the warp's sample positions, the blur tasks.
struct CropPlan {
  CropWindow crop;
  int rx0 = 0, ry0 = 0, rw = 0, rh = 0;  // region of B (full-image coordinates)
  bool warp = false;
  std::vector<double> u, v;  // per crop pixel: sample position - 1/2 (NaN: black)
  std::vector<BlurTask> tasks;
  int colours = 0;
};

}  // namespace

struct DifferentiableImaging::State {
  const LensParameterization& param;
  GlassMode mode;
  std::vector<int> fixed_glasses;
  DifferentiableImagingOptions options;
  double sensor_diagonal_mm = 0;
  bool prepared = false;
  std::uint64_t generation = 0;  // counts prepare() calls (keys the forward cache)
  Optics optics;
  mutable ImagingTimings timings;
  mutable std::mutex mutex;
  mutable std::map<std::pair<int, int>, std::shared_ptr<Geometry>> geometries;

  State(const LensParameterization& p, GlassMode m, std::vector<int> fixed,
        DifferentiableImagingOptions o)
      : param(p), mode(m), fixed_glasses(std::move(fixed)), options(std::move(o)) {}

  std::shared_ptr<Geometry> geometry(int width, int height) const {
    if (!prepared) throw Error("DifferentiableImaging: call prepare(x) before render/backward");
    std::lock_guard<std::mutex> lock(mutex);
    auto it = geometries.find({width, height});
    if (it != geometries.end()) return it->second;
    const auto start = Clock::now();
    auto g = make_geometry(optics, options, sensor_diagonal_mm, width, height);
    timings.kernels_s = seconds_since(start);
    geometries[{width, height}] = g;
    return g;
  }

  // The blurred regions B of the last few crops render() made, so backward() of the same
  // scene, crop and prepare() needs only the scene's spectra (not the kernels' spectra, their
  // products and the inverse transforms). Keyed by a hash of every scene pixel the blur reads.
  struct ForwardEntry {
    std::uint64_t generation = 0, scene_hash = 0;
    int width = 0, height = 0, channels = 0;
    CropWindow crop;
    std::shared_ptr<const std::vector<double>> blurred;
  };
  static constexpr std::size_t kForwardEntries = 8;  // a batch of crops, ~1.6 MB each at 256^2
  mutable std::mutex forward_mutex;
  mutable std::vector<ForwardEntry> forward_cache;

  CropPlan plan(const FloatImage& scene, const CropWindow& crop, const Geometry& g) const;
  // B of the plan's region (channels planar, [c][pixel]; the colour channels blurred, further
  // ones copied) into `blurred` if given, and each task's scene spectrum into `spectra` if given.
  void blur_region(const FloatImage& scene, const CropPlan& p, const Geometry& g,
                   std::vector<double>* blurred,
                   std::vector<std::vector<std::complex<double>>>* spectra) const;
  // FNV-1a of the scene pixels the blur of plan `p` reads (its region plus the largest kernel
  // radius, clamped to the image: reflected indices fall inside).
  std::uint64_t scene_hash(const FloatImage& scene, const CropPlan& p, const Geometry& g) const;
};

namespace {

void check_inputs(const FloatImage& scene, const CropWindow& crop) {
  if (scene.empty()) throw Error("joint imaging: empty scene image");
  if (crop.width <= 0 || crop.height <= 0 || crop.x0 < 0 || crop.y0 < 0 ||
      crop.x0 + crop.width > scene.width || crop.y0 + crop.height > scene.height) {
    throw Error(fmt::format("crop {}x{} at ({}, {}) is not inside the {}x{} scene", crop.width,
                            crop.height, crop.x0, crop.y0, scene.width, scene.height));
  }
}

}  // namespace

CropPlan DifferentiableImaging::State::plan(const FloatImage& scene, const CropWindow& crop,
                                            const Geometry& g) const {
  CropPlan p;
  p.crop = crop;
  p.colours = colour_channel_count(scene.channels);
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
    const double axis_scale = ybar.size() > 1 ? (yref[1] - yref[0]) / (ybar[1] - ybar[0]) : 1.0;
    const std::size_t count = static_cast<std::size_t>(crop.width) * crop.height;
    p.u.assign(count, std::numeric_limits<double>::quiet_NaN());
    p.v.assign(count, std::numeric_limits<double>::quiet_NaN());
    x_lo = width;
    x_hi = 0;
    y_lo = height;
    y_hi = 0;
    for (int j = 0; j < crop.height; ++j) {
      for (int i = 0; i < crop.width; ++i) {
        const double dx = crop.x0 + i + 0.5 - geo.axis_x, dy = crop.y0 + j + 0.5 - geo.axis_y;
        const double r_out = geo.pitch_mm * std::sqrt(dx * dx + dy * dy);
        const double scale =
            r_out > 1e-12 ? interpolate_linear(ybar, yref, r_out, true) / r_out : axis_scale;
        const double sx = geo.axis_x + dx * scale, sy = geo.axis_y + dy * scale;
        if (!(sx >= 0.0 && sx <= width && sy >= 0.0 && sy <= height)) continue;
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

namespace {

// The 4 x 4 bicubic taps of crop pixel k's sample: weights (and their derivatives) and the
// taps' indices in the region (clamped to the image).
struct WarpTaps {
  double wx[4], wy[4], dwx[4], dwy[4];
  std::size_t index[4][4];  // [row m][column t]
};

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

}  // namespace

std::uint64_t DifferentiableImaging::State::scene_hash(const FloatImage& scene, const CropPlan& p,
                                                       const Geometry& g) const {
  const int x0 = std::max(0, p.rx0 - g.max_radius),
            x1 = std::min(scene.width, p.rx0 + p.rw + g.max_radius);
  const int y0 = std::max(0, p.ry0 - g.max_radius),
            y1 = std::min(scene.height, p.ry0 + p.rh + g.max_radius);
  std::uint64_t h = 1469598103934665603ull;
  for (int j = y0; j < y1; ++j) {
    const float* row = scene.pixels.data() + scene.index(x0, j, 0);
    const std::size_t count = static_cast<std::size_t>(x1 - x0) * scene.channels;
    for (std::size_t i = 0; i < count; ++i) {
      std::uint32_t bits;
      std::memcpy(&bits, row + i, sizeof bits);
      h = (h ^ bits) * 1099511628211ull;
    }
  }
  return h;
}

void DifferentiableImaging::State::blur_region(
    const FloatImage& scene, const CropPlan& p, const Geometry& g, std::vector<double>* blurred,
    std::vector<std::vector<std::complex<double>>>* spectra) const {
  const std::size_t plane = static_cast<std::size_t>(p.rw) * p.rh;
  const int channels = scene.channels;
  if (blurred) {
    blurred->assign(plane * channels, 0.0);
    // Channels that are not blurred (alpha): copied.
    for (int c = p.colours; c < channels; ++c)
      for (int j = 0; j < p.rh; ++j)
        for (int i = 0; i < p.rw; ++i)
          (*blurred)[plane * c + static_cast<std::size_t>(j) * p.rw + i] =
              scene.at(p.rx0 + i, p.ry0 + j, c);
  }
  const int tasks = static_cast<int>(p.tasks.size());
  if (spectra) spectra->assign(tasks, {});
  const int nthreads = thread_count(options.threads);
  // Each task's windowed output in its own buffer, added in task order afterwards: the sum does
  // not depend on which thread ran which task (runs are reproducible to the last bit).
  std::vector<std::vector<double>> outputs(blurred ? tasks : 0);
#pragma omp parallel num_threads(nthreads)
  {
#pragma omp for schedule(dynamic, 1)
    for (int ti = 0; ti < tasks; ++ti) {
      const BlurTask& t = p.tasks[ti];
      const int nx = t.nx, ny = t.ny, r = t.radius;
      const FftPlans plans = fft_plans(ny, nx);
      const std::size_t spectrum_size = static_cast<std::size_t>(ny) * (nx / 2 + 1);
      RealBuffer real(static_cast<std::size_t>(ny) * nx);
      ComplexBuffer spectrum(spectrum_size), kspec(spectrum_size);
      const int cols = t.x1 - t.x0 + 2 * r, rows = t.y1 - t.y0 + 2 * r;
      // The scene block [x0 - r, x1 + r) x [y0 - r, y1 + r), reflected at the borders.
      std::fill(real.data, real.data + static_cast<std::size_t>(ny) * nx, 0.0);
      for (int j = 0; j < rows; ++j) {
        const int sy = reflect_index(t.y0 - r + j, scene.height);
        double* row = real.data + static_cast<std::size_t>(j) * nx;
        for (int i = 0; i < cols; ++i)
          row[i] = scene.at(reflect_index(t.x0 - r + i, scene.width), sy, t.c);
      }
      fftw_execute_dft_r2c(plans.forward, real.data, spectrum.data);
      if (spectra) {
        auto& s = (*spectra)[ti];
        s.resize(spectrum_size);
        for (std::size_t i = 0; i < spectrum_size; ++i)
          s[i] = std::complex<double>(spectrum.data[i][0], spectrum.data[i][1]);
      }
      if (!blurred) continue;
      place_kernel(task_kernel(g, p, t).data(), r, ny, nx, real.data);
      fftw_execute_dft_r2c(plans.forward, real.data, kspec.data);
      const double scale = 1.0 / (static_cast<double>(nx) * ny);
      for (std::size_t i = 0; i < spectrum_size; ++i) {
        const std::complex<double> v =
            std::complex<double>(spectrum.data[i][0], spectrum.data[i][1]) *
            std::complex<double>(kspec.data[i][0], kspec.data[i][1]) * scale;
        spectrum.data[i][0] = v.real();
        spectrum.data[i][1] = v.imag();
      }
      fftw_execute_dft_c2r(plans.backward, spectrum.data, real.data);
      const int px = t.q % PsfGrid::kPatches, py = t.q / PsfGrid::kPatches;
      const std::vector<double>& wx = g.window_x[px];
      const std::vector<double>& wy = g.window_y[py];
      std::vector<double>& out = outputs[ti];
      out.resize(static_cast<std::size_t>(t.x1 - t.x0) * (t.y1 - t.y0));
      for (int j = t.y0; j < t.y1; ++j) {
        const double* row = real.data + static_cast<std::size_t>(j - t.y0 + r) * nx + r;
        double* dst = out.data() + static_cast<std::size_t>(j - t.y0) * (t.x1 - t.x0);
        const double w = wy[j];
        for (int i = t.x0; i < t.x1; ++i) dst[i - t.x0] = w * wx[i] * row[i - t.x0];
      }
    }
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
  const Specs& specs = param.structure().specs;
  validate_wavelength_channels(specs.wavelength_channels,
                               static_cast<int>(specs.wavelengths_nm.size()));
  state_->sensor_diagonal_mm = specs.sensor_diagonal_mm;
}

DifferentiableImaging::~DifferentiableImaging() {
  delete state_;
}

const ImagingTimings& DifferentiableImaging::timings() const {
  return state_->timings;
}

void DifferentiableImaging::prepare(const std::vector<double>& x, bool derivatives) {
  State& s = *state_;
  if (static_cast<int>(x.size()) != s.param.size()) {
    throw Error(fmt::format("joint imaging: {} variables given, the lens has {}", x.size(),
                            s.param.size()));
  }
  Optics optics = derivatives ? sample_optics_any(s.param.size(), s.param, s.mode, s.fixed_glasses,
                                                  s.options, x, s.timings)
                              : sample_optics<double>(s.param, s.mode, s.fixed_glasses, s.options,
                                                      x, s.timings);
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
}

FloatImage DifferentiableImaging::render(const FloatImage& scene, const CropWindow& crop) const {
  const std::vector<double> values = render_values(scene, crop);
  FloatImage out(crop.width, crop.height, scene.channels);
  for (std::size_t i = 0; i < values.size(); ++i) out.pixels[i] = static_cast<float>(values[i]);
  return out;
}

std::vector<double> DifferentiableImaging::render_values(const FloatImage& scene,
                                                         const CropWindow& crop) const {
  const auto start = Clock::now();
  check_inputs(scene, crop);
  const State& s = *state_;
  const std::shared_ptr<Geometry> g = s.geometry(scene.width, scene.height);
  const CropPlan p = s.plan(scene, crop, *g);
  std::vector<double> b;
  s.blur_region(scene, p, *g, &b, nullptr);
  {
    State::ForwardEntry e;
    e.generation = s.generation;
    e.scene_hash = s.scene_hash(scene, p, *g);
    e.width = scene.width;
    e.height = scene.height;
    e.channels = scene.channels;
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
  const int channels = scene.channels;
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
  s.timings.render_s = seconds_since(start);
  return out;
}

const ImagingOptics& DifferentiableImaging::optics() const {
  if (!state_->prepared) throw Error("DifferentiableImaging: call prepare(x) before optics()");
  return state_->optics;
}

void DifferentiableImaging::backward(const FloatImage& scene, const CropWindow& crop,
                                     const FloatImage& grad_image,
                                     std::vector<double>& grad_x) const {
  backward(scene, crop, grad_image, grad_x, nullptr);
}

void DifferentiableImaging::backward(const FloatImage& scene, const CropWindow& crop,
                                     const FloatImage& grad_image, std::vector<double>& grad_x,
                                     std::vector<double>* grad_scene) const {
  const auto start = Clock::now();
  check_inputs(scene, crop);
  const State& s = *state_;
  const int n = s.param.size();
  if (grad_x.empty()) grad_x.assign(n, 0.0);
  if (static_cast<int>(grad_x.size()) != n) {
    throw Error(fmt::format("joint imaging: grad_x has {} entries, the lens has {} variables",
                            grad_x.size(), n));
  }
  if (grad_image.width != crop.width || grad_image.height != crop.height ||
      grad_image.channels != scene.channels) {
    throw Error(fmt::format("joint imaging: the gradient image is {}x{}x{}, the crop {}x{}x{}",
                            grad_image.width, grad_image.height, grad_image.channels, crop.width,
                            crop.height, scene.channels));
  }
  if (s.prepared && s.optics.variables != n) {
    throw Error("joint imaging: backward() needs prepare(x) with derivatives");
  }
  const std::shared_ptr<Geometry> g = s.geometry(scene.width, scene.height);
  const CropPlan p = s.plan(scene, crop, *g);
  // B from render() of the same scene and crop if it is cached, else computed here.
  std::shared_ptr<const std::vector<double>> cached;
  {
    const std::uint64_t hash = s.scene_hash(scene, p, *g);
    std::lock_guard<std::mutex> lock(s.forward_mutex);
    for (const State::ForwardEntry& e : s.forward_cache) {
      if (e.generation == s.generation && e.scene_hash == hash && e.width == scene.width &&
          e.height == scene.height && e.channels == scene.channels && e.crop.x0 == crop.x0 &&
          e.crop.y0 == crop.y0 && e.crop.width == crop.width && e.crop.height == crop.height)
        cached = e.blurred;
    }
  }
  std::vector<double> computed;
  std::vector<std::vector<std::complex<double>>> spectra;
  s.blur_region(scene, p, *g, cached ? nullptr : &computed, &spectra);
  const std::vector<double>& b = cached ? *cached : computed;
  const Optics& o = s.optics;
  const int fields = static_cast<int>(o.reference_y_mm.size());
  const std::size_t plane = static_cast<std::size_t>(p.rw) * p.rh;
  const int channels = scene.channels;
  const SensorGeometry& geo = g->layout.geometry;
  const int nthreads = thread_count(s.options.threads);

  // Relative illumination per region pixel, and B' = R B.
  std::vector<double> ri(plane, 1.0);
  if (s.options.relative_illumination) {
    for (int j = 0; j < p.rh; ++j)
      for (int i = 0; i < p.rw; ++i)
        ri[static_cast<std::size_t>(j) * p.rw + i] = interpolate_linear(
            o.reference_y_mm, o.illumination, geo.radius_mm(p.rx0 + i, p.ry0 + j), false);
  }
  std::vector<double> bp = b;
  for (int c = 0; c < p.colours; ++c)
    for (std::size_t k = 0; k < plane; ++k) bp[plane * c + k] *= ri[k];

  // Gradients of the per-field nodes.
  std::vector<double> g_reference(fields, 0.0), g_centroid(fields, 0.0),
      g_illumination(fields, 0.0);

  // Adjoint of the warp: dL/dB' and dL/d(sample position) -> dL/drho -> ybar, y_ref.
  std::vector<double> gbp(plane * channels, 0.0);
  if (!p.warp) {
    for (int j = 0; j < crop.height; ++j)
      for (int i = 0; i < crop.width; ++i)
        for (int c = 0; c < channels; ++c)
          gbp[plane * c + static_cast<std::size_t>(crop.y0 + j - p.ry0) * p.rw +
              (crop.x0 + i - p.rx0)] = grad_image.at(i, j, c);
  } else {
    const std::vector<double>& ybar = o.centroid_y_mm;
    const std::vector<double>& yref = o.reference_y_mm;
    for (int j = 0; j < crop.height; ++j) {
      for (int i = 0; i < crop.width; ++i) {
        const std::size_t k = static_cast<std::size_t>(j) * crop.width + i;
        if (std::isnan(p.u[k])) continue;
        const WarpTaps w = warp_taps(p, *g, k, true);
        double du = 0, dv = 0;
        for (int c = 0; c < channels; ++c) {
          const double gv = grad_image.at(i, j, c);
          if (gv == 0.0) continue;
          double* gc = gbp.data() + plane * c;
          const double* bc = bp.data() + plane * c;
          for (int m = 0; m < 4; ++m) {
            for (int t = 0; t < 4; ++t) {
              const double val = bc[w.index[m][t]];
              gc[w.index[m][t]] += w.wy[m] * w.wx[t] * gv;
              du += gv * w.wy[m] * w.dwx[t] * val;
              dv += gv * w.dwy[m] * w.wx[t] * val;
            }
          }
        }
        // u = a_x + dx rho(r') / r' - 1/2 (pixels), rho in mm.
        const double dx = crop.x0 + i + 0.5 - geo.axis_x, dy = crop.y0 + j + 0.5 - geo.axis_y;
        const double r_out = geo.pitch_mm * std::sqrt(dx * dx + dy * dy);
        if (!(r_out > 1e-12)) continue;  // the axis maps to itself
        const double g_rho = (du * dx + dv * dy) / r_out;
        const LinearPiece piece = linear_piece(ybar, yref, r_out, true);
        g_centroid[piece.k] += g_rho * piece.d_x0;
        g_reference[piece.k] += g_rho * piece.d_y0;
        if (fields > 1) {
          g_centroid[piece.k + 1] += g_rho * piece.d_x1;
          g_reference[piece.k + 1] += g_rho * piece.d_y1;
        }
      }
    }
  }

  // Adjoint of the relative illumination: dL/dB = R dL/dB', dL/dR = sum_c dL/dB' B.
  std::vector<double>& gb = gbp;  // in place: dL/dB of the colour channels
  if (s.options.relative_illumination) {
    for (int j = 0; j < p.rh; ++j) {
      for (int i = 0; i < p.rw; ++i) {
        const std::size_t k = static_cast<std::size_t>(j) * p.rw + i;
        double g_r = 0;
        for (int c = 0; c < p.colours; ++c) g_r += gbp[plane * c + k] * b[plane * c + k];
        for (int c = 0; c < p.colours; ++c) gb[plane * c + k] *= ri[k];
        if (g_r == 0.0) continue;
        const LinearPiece piece = linear_piece(o.reference_y_mm, o.illumination,
                                               geo.radius_mm(p.rx0 + i, p.ry0 + j), false);
        g_illumination[piece.k] += g_r * piece.d_y0;
        g_reference[piece.k] += g_r * piece.d_x0;
        if (fields > 1) {
          g_illumination[piece.k + 1] += g_r * piece.d_y1;
          g_reference[piece.k + 1] += g_r * piece.d_x1;
        }
      }
    }
  }

  // Adjoint of the overlap-add convolution: dL/dK_q[c] by correlation, then to the mixed PSF.
  const int tasks = static_cast<int>(p.tasks.size());
  const std::size_t cells =
      static_cast<std::size_t>(s.options.psf.grid_size) * s.options.psf.grid_size;
  std::vector<std::vector<double>> g_mixed(tasks * kColourChannels);
  // dL/dS of each task's reflected scene block [x0 - r, x1 + r) x [y0 - r, y1 + r) (grad_scene).
  std::vector<std::vector<double>> g_blocks(grad_scene ? tasks : 0);
#pragma omp parallel num_threads(nthreads)
  {
    std::vector<double> g_kernel;
#pragma omp for schedule(dynamic, 1)
    for (int ti = 0; ti < tasks; ++ti) {
      const BlurTask& t = p.tasks[ti];
      const int nx = t.nx, ny = t.ny, r = t.radius, size = 2 * r + 1;
      const FftPlans plans = fft_plans(ny, nx);
      const std::size_t spectrum_size = static_cast<std::size_t>(ny) * (nx / 2 + 1);
      RealBuffer real(static_cast<std::size_t>(ny) * nx);
      ComplexBuffer spectrum(spectrum_size);
      std::fill(real.data, real.data + static_cast<std::size_t>(ny) * nx, 0.0);
      const int px = t.q % PsfGrid::kPatches, py = t.q / PsfGrid::kPatches;
      const std::vector<double>& wx = g->window_x[px];
      const std::vector<double>& wy = g->window_y[py];
      const double* gc = gb.data() + plane * t.c;
      for (int j = t.y0; j < t.y1; ++j) {
        double* row = real.data + static_cast<std::size_t>(j - t.y0 + r) * nx + r;
        const double* src = gc + static_cast<std::size_t>(j - p.ry0) * p.rw + (t.x0 - p.rx0);
        for (int i = t.x0; i < t.x1; ++i) row[i - t.x0] = wy[j] * wx[i] * src[i - t.x0];
      }
      fftw_execute_dft_r2c(plans.forward, real.data, spectrum.data);
      if (grad_scene) {
        // The blur block is K * S_b (valid part, no wrap-around); its adjoint is the correlation
        // dL/dS_b(m) = sum_p G_b(p) K(p - m): the inverse FFT of FFT(G_b) conj(FFT(K)).
        RealBuffer work(static_cast<std::size_t>(ny) * nx);
        ComplexBuffer kspec(spectrum_size), product(spectrum_size);
        place_kernel(task_kernel(*g, p, t).data(), r, ny, nx, work.data);
        fftw_execute_dft_r2c(plans.forward, work.data, kspec.data);
        const double scale = 1.0 / (static_cast<double>(nx) * ny);
        for (std::size_t i = 0; i < spectrum_size; ++i) {
          const std::complex<double> v =
              std::complex<double>(spectrum.data[i][0], spectrum.data[i][1]) *
              std::conj(std::complex<double>(kspec.data[i][0], kspec.data[i][1])) * scale;
          product.data[i][0] = v.real();
          product.data[i][1] = v.imag();
        }
        fftw_execute_dft_c2r(plans.backward, product.data, work.data);
        const int cols = t.x1 - t.x0 + 2 * r, rows = t.y1 - t.y0 + 2 * r;
        std::vector<double>& block = g_blocks[ti];
        block.resize(static_cast<std::size_t>(rows) * cols);
        for (int j = 0; j < rows; ++j)
          for (int i = 0; i < cols; ++i)
            block[static_cast<std::size_t>(j) * cols + i] =
                work.data[static_cast<std::size_t>(j) * nx + i];
      }
      const std::vector<std::complex<double>>& scene_spectrum = spectra[ti];
      const double scale = 1.0 / (static_cast<double>(nx) * ny);
      for (std::size_t i = 0; i < spectrum_size; ++i) {
        const std::complex<double> v =
            std::complex<double>(spectrum.data[i][0], spectrum.data[i][1]) *
            std::conj(scene_spectrum[i]) * scale;
        spectrum.data[i][0] = v.real();
        spectrum.data[i][1] = v.imag();
      }
      fftw_execute_dft_c2r(plans.backward, spectrum.data, real.data);
      // C(d) = sum_j G_b(j) S_b(j - d) sits at index d (mod the FFT size).
      g_kernel.assign(static_cast<std::size_t>(size) * size, 0.0);
      for (int dy = -r; dy <= r; ++dy) {
        const double* row = real.data + static_cast<std::size_t>((dy + ny) % ny) * nx;
        for (int dx = -r; dx <= r; ++dx)
          g_kernel[static_cast<std::size_t>(dy + r) * size + (dx + r)] = row[(dx + nx) % nx];
      }
      const PatchKernels& pk = g->patches[t.q];
      if (p.colours == kColourChannels) {
        std::vector<double>& gm = g_mixed[ti * kColourChannels + t.c];
        gm.assign(cells, 0.0);
        resample_psf_adjoint(pk.resampling, pk.mixed[t.c].data(), pk.kernel[t.c], g_kernel,
                             gm.data());
      } else {  // the grey kernel is the channels' mean
        for (double& v : g_kernel) v /= kColourChannels;
        for (int c = 0; c < kColourChannels; ++c) {
          std::vector<double>& gm = g_mixed[ti * kColourChannels + c];
          gm.assign(cells, 0.0);
          resample_psf_adjoint(pk.resampling, pk.mixed[c].data(), pk.kernel[c], g_kernel,
                               gm.data());
        }
      }
    }
  }
  if (grad_scene) {
    std::vector<double>& gs = *grad_scene;
    if (gs.empty()) gs.assign(scene.pixels.size(), 0.0);
    if (gs.size() != scene.pixels.size())
      throw Error("joint imaging: grad_scene does not have the scene's size");
    // In task order (reproducible): each block folded back through the border reflection.
    for (int ti = 0; ti < tasks; ++ti) {
      const BlurTask& t = p.tasks[ti];
      const int r = t.radius, cols = t.x1 - t.x0 + 2 * r, rows = t.y1 - t.y0 + 2 * r;
      const std::vector<double>& block = g_blocks[ti];
      for (int j = 0; j < rows; ++j) {
        const int sy = reflect_index(t.y0 - r + j, scene.height);
        for (int i = 0; i < cols; ++i)
          gs[scene.index(reflect_index(t.x0 - r + i, scene.width), sy, t.c)] +=
              block[static_cast<std::size_t>(j) * cols + i];
      }
    }
    // Channels that are not blurred (alpha) were copied.
    for (int c = p.colours; c < channels; ++c)
      for (int j = 0; j < p.rh; ++j)
        for (int i = 0; i < p.rw; ++i)
          gs[scene.index(p.rx0 + i, p.ry0 + j, c)] +=
              gb[plane * c + static_cast<std::size_t>(j) * p.rw + i];
  }

  // dL/dP_h[c] = sum_q a_qh dL/dmixed_q[c].
  std::vector<std::array<std::vector<double>, kColourChannels>> g_psf(fields);
  for (int ti = 0; ti < tasks; ++ti) {
    const std::vector<double>& a = g->layout.field_weights[p.tasks[ti].q];
    for (int c = 0; c < kColourChannels; ++c) {
      const std::vector<double>& gm = g_mixed[ti * kColourChannels + c];
      if (gm.empty()) continue;
      for (int h = 0; h < fields; ++h) {
        if (a[h] == 0.0) continue;
        std::vector<double>& gp = g_psf[h][c];
        if (gp.empty()) gp.assign(cells, 0.0);
        for (std::size_t i = 0; i < cells; ++i) gp[i] += a[h] * gm[i];
      }
    }
  }
  // Contract with the Jets' derivative parts.
  std::vector<double> gx(n, 0.0);
  for (int h = 0; h < fields; ++h) {
    for (int c = 0; c < kColourChannels; ++c) {
      const std::vector<double>& gp = g_psf[h][c];
      if (gp.empty()) continue;
      const std::array<int, 4>& box = o.support[h][c];
      const double* d = o.d_psf[h][c].data();
      for (int r = box[0]; r < box[1]; ++r) {
        for (int i = box[2]; i < box[3]; ++i, d += n) {
          const double v = gp[static_cast<std::size_t>(r) * s.options.psf.grid_size + i];
          if (v == 0.0) continue;
          for (int j = 0; j < n; ++j) gx[j] += v * d[j];
        }
      }
    }
    for (int j = 0; j < n; ++j) {
      const std::size_t k = static_cast<std::size_t>(h) * n + j;
      gx[j] += g_reference[h] * o.d_reference[k] + g_centroid[h] * o.d_centroid[k] +
               g_illumination[h] * o.d_illumination[k];
    }
  }
  for (int j = 0; j < n; ++j) grad_x[j] += gx[j];
  s.timings.adjoint_s = seconds_since(start);
}

}  // namespace lensopt
