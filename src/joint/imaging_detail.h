// Internals of the differentiable image formation (joint/imaging.h), shared by its files:
//   optics_sampling.cpp  the optics of prepare(x) with Jets (PSFs, RI, heights, derivative rows);
//   patch_kernels.cpp    the patch kernels K_q = L_q(sum_h a_qh P_h) / T of one image size;
//   imaging.cpp          the forward rendering of a crop (the blur by render/overlap_add.h, the
//                        RI, the warp by render/distortion_warp.h) and the public class;
//   imaging_backward.cpp the adjoint of each step.
// The maths of each step is stated at the top of imaging.cpp; not part of the public API.
#pragma once

#include <atomic>
#include <chrono>
#include <complex>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "lensopt/joint/imaging.h"
#include "lensopt/render/psf_resample.h"
#include "lensopt/render/render.h"

namespace lensopt {
namespace imaging_detail {

using Clock = std::chrono::steady_clock;

inline double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

using Optics = ImagingOptics;

// ImagingTimings written from concurrent const calls (render() and backward() may overlap): one
// atomic per entry, read as a snapshot.
struct AtomicTimings {
  std::atomic<double> trace_s{0}, psf_s{0}, kernels_s{0}, render_s{0}, adjoint_s{0};
  ImagingTimings snapshot() const {
    return {trace_s.load(), psf_s.load(), kernels_s.load(), render_s.load(), adjoint_s.load()};
  }
};

// The optics of variables x: with derivatives (Jets of the narrowest width that holds them) or
// values only (doubles). `timings` receives trace_s and psf_s. optics_sampling.cpp.
Optics sample_optics(const LensParameterization& param, GlassMode mode,
                     const std::vector<int>& fixed_glasses,
                     const DifferentiableImagingOptions& options, const std::vector<double>& x,
                     bool derivatives, ImagingTimings& timings);

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

// The layout, windows and patch kernels of a width x height full image (patch_kernels.cpp).
std::shared_ptr<Geometry> make_geometry(const Optics& o, const DifferentiableImagingOptions& opt,
                                        double sensor_diagonal_mm, int width, int height);

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

// The 4 x 4 bicubic taps of crop pixel k's sample: weights (and their derivatives) and the
// taps' indices in the region (clamped to the image).
struct WarpTaps {
  double wx[4], wy[4], dwx[4], dwy[4];
  std::size_t index[4][4];  // [row m][column t]
};
WarpTaps warp_taps(const CropPlan& p, const Geometry& g, std::size_t k, bool derivatives);

// The kernel of blur task t: its channel's, or the grey mean for grey images.
const std::vector<double>& task_kernel(const Geometry& g, const CropPlan& p, const BlurTask& t);

// Throws Error unless the crop lies inside the (non-empty) scene.
void check_inputs(const SceneWindow& scene, const CropWindow& crop);

// The whole image as a window of itself.
inline SceneWindow whole(const FloatImage& scene) {
  return SceneWindow{scene, 0, 0, scene.width, scene.height};
}

// The scene pixels the blur of plan `p` reads: its region plus the largest kernel radius,
// clamped to the image (reflected indices fall inside).
CropWindow read_window(const CropPlan& p, const Geometry& g);

// Throws Error unless the window holds read_window(p, g).
void check_window(const SceneWindow& scene, const CropPlan& p, const Geometry& g);

}  // namespace imaging_detail

using imaging_detail::AtomicTimings;
using imaging_detail::CropPlan;
using imaging_detail::Geometry;
using imaging_detail::Optics;

struct DifferentiableImaging::State {
  const LensParameterization& param;
  GlassMode mode;
  std::vector<int> fixed_glasses;
  DifferentiableImagingOptions options;
  double sensor_diagonal_mm = 0;
  bool prepared = false;
  std::uint64_t generation = 0;  // counts prepare() calls (keys the forward cache)
  Optics optics;
  mutable AtomicTimings timings;  // written by concurrent render()/backward() calls
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
    const auto start = imaging_detail::Clock::now();
    auto g = imaging_detail::make_geometry(optics, options, sensor_diagonal_mm, width, height);
    timings.kernels_s.store(imaging_detail::seconds_since(start));
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

  // The plan of a crop of a scene with `channels` channels on geometry g: made once per
  // prepare(), crop and colour count (a few kept: render() and backward() of a batch of crops,
  // and scene_window(), share them).
  std::shared_ptr<const CropPlan> plan(int channels, const CropWindow& crop,
                                       const Geometry& g) const;
  CropPlan make_plan(int channels, const CropWindow& crop, const Geometry& g) const;
  struct PlanEntry {
    int width = 0, height = 0, colours = 0;
    CropWindow crop;
    std::shared_ptr<const CropPlan> plan;
  };
  static constexpr std::size_t kPlanEntries = 16;
  mutable std::mutex plan_mutex;
  mutable std::vector<PlanEntry> plan_cache;  // cleared by prepare()
  // B of the plan's region (channels planar, [c][pixel]; the colour channels blurred, further
  // ones copied) into `blurred` if given, and each task's scene spectrum into `spectra` if given.
  void blur_region(const SceneWindow& scene, const CropPlan& p, const Geometry& g,
                   std::vector<double>* blurred,
                   std::vector<std::vector<std::complex<double>>>* spectra) const;
  // FNV-1a of the scene pixels the blur of plan `p` reads (read_window).
  std::uint64_t scene_hash(const SceneWindow& scene, const CropPlan& p, const Geometry& g) const;
};

}  // namespace lensopt
