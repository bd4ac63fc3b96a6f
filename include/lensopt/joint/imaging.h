// Differentiable image formation for the joint optimization (paper "Joint Optimization").
//
// The rendered crop R depends on the lens variables x only through the sampled optics:
//   x -> (field PSFs P_h, relative illumination R_h, heights y_ref,h, ybar_h)  [Jets, tracer]
//     -> patch kernels K_q = L_q(sum_h a_qh P_h) / T                 [linear, fixed weights]
//     -> R = warp_(ybar, y_ref)( RI_(y_ref, R) . sum_q w_q (K_q * S) )  [doubles only]
// (S the sharp scene, * convolution, w_q the overlap-add windows, L_q the rotation and bilinear
// resampling to the pixel grid, render/psf_resample.h; render/render.h states each step). The
// distortion D_h = (ybar_h - y_ref,h) / y_ref,last enters the warp as its nodes (ybar_h, y_ref,h).
// The field weights a_qh (nearest field), kernel radii and every integer choice are fixed per
// prepare(). No Jet ever sits on a pixel or a kernel. The backward pass takes G = dL/dR and
// returns
//   dL/dx_j = sum_h,c <dL/dP_h[c], dP_h[c]/dx_j> + sum_h dL/dR_h dR_h/dx_j
//             + sum_h (dL/dy_ref,h dy_ref,h/dx_j + dL/dybar_h dybar_h/dx_j),
// where dL/dP_h[c] = sum_q a_qh L_q^T-adjoint(dL/dK_q[c]) (with the normalization by T),
// dL/dK_q[c] is the correlation of (w_q . dL/d(blurred)) with S over the kernel's support (the
// convolution is linear in K_q), dL/d(blurred) comes from G through the adjoint of the warp (the
// transpose of the bicubic sampling) and the RI multiplication, dL/dR_h and dL/dy_ref,h from the
// RI interpolation, dL/dybar_h and dL/dy_ref,h from the bicubic derivative at the warp's source
// positions, and the derivative parts of the Jets give dP_h/dx_j, dR_h/dx_j, dy_ref,h/dx_j,
// dybar_h/dx_j. src/joint/imaging.cpp states the adjoint of each step.
#pragma once

#include <array>
#include <vector>

#include "lensopt/optimize/variables.h"
#include "lensopt/render/image.h"
#include "lensopt/render/psf.h"
#include "lensopt/trace/system.h"

namespace lensopt {

// A crop of the full scene image (pixels). The full image's size fixes the sensor geometry
// (render/render.h: its diagonal spans the sensor diagonal), so a crop sees the PSFs of where it
// lies on the sensor.
struct CropWindow {
  int x0 = 0;
  int y0 = 0;
  int width = 0;
  int height = 0;
};

// The PSF options of the joint optimization: the renderer's, with the KDE's support widened
// from 2 to 3 bins either side of a ray's nearest bin. With 2, the taps a ray deposits into
// switch when it crosses the middle between bins, moving exp(-2.5^2 / (2 (1/2)^2)) = 3.7e-6 of
// its energy between bins 5 apart: a jump in the PSF (and the loss) that finite differences see
// (relative gradient errors of up to 1e-2 at h = 1e-6). With 3 the jump is exp(-24.5) = 2e-11.
inline PsfOptions joint_psf_options() {
  PsfOptions o;
  o.support_bins = 3;
  return o;
}

// The ray sampling of the joint optimization: 8 pupil rings (64 rays per field and wavelength
// on the half pupil, 128 with the mirror) and the paper's 21 fields, ray aiming on. A PSF then
// has 640 rays per colour channel (5 wavelengths each) instead of 10240 at 32 rings; its Jet
// trace costs 1/16. tools/bench-joint-imaging.sh measures it.
inline TraceOptions joint_trace_options() {
  TraceOptions o;
  o.rings = 8;
  return o;
}

// A window of a full scene image: `pixels` holds the pixels [x0, x0 + pixels.width) x
// [y0, y0 + pixels.height) of a width x height scene (whose size fixes the sensor geometry and
// where the blur reflects). render() and backward() of a crop read only the pixels of
// DifferentiableImaging::scene_window(), so a window that holds them renders the crop exactly as
// the whole scene does, without the rest of the scene converted or copied (lensopt.torch passes
// each crop's window of its B x C x H x W tensors).
struct SceneWindow {
  const FloatImage& pixels;
  int x0 = 0, y0 = 0;
  int width = 0, height = 0;
};

struct DifferentiableImagingOptions {
  TraceOptions sampling = joint_trace_options();  // PSF ray sampling (fields: the PSF fields)
  PsfOptions psf = joint_psf_options();           // PSF grid and kernel
  int res_factor = 1;                             // 1 or 2, as RenderOptions
  bool relative_illumination = true;              // apply (and differentiate) the RI map
  bool distortion = true;                         // apply (and differentiate) the distortion warp
  int threads = 0;  // threads of render/backward and, unless sampling.threads says, of the
                    // tracing; 0: all cores

  void validate() const;  // throws Error naming the bad value
};

// Wall time of the last prepare() / render() / backward() calls, seconds.
struct ImagingTimings {
  double trace_s = 0;    // ray tracing with Jets (incl. RI and distortion)
  double psf_s = 0;      // KDE PSFs with Jets (tracing their rays included)
  double kernels_s = 0;  // patch kernels of the last new image size (made by the first render
                         // or backward of that size after prepare(); included in its time)
  double render_s = 0;   // forward rendering
  double adjoint_s = 0;  // backward pass
};

// The optics of one prepare(x): per field h the values and, after a prepare with derivatives,
// their derivative rows (n = `variables` per entry, d/dx_j at [h * n + j]).
struct ImagingOptics {
  int variables = 0;  // n; 0 after a prepare without derivatives
  std::vector<double> fields_deg;
  std::vector<double> reference_y_mm, centroid_y_mm, illumination;    // [h]
  std::vector<double> d_reference, d_centroid, d_illumination;        // [h * variables + j]
  std::vector<std::array<std::vector<double>, kColourChannels>> psf;  // [h][c] G x G
  // [h][c]: the derivatives of the bins inside the PSF's support box (FieldPsf::support), row by
  // row, [(r - r0) (c1 - c0) + (i - c0)] * n + j; every bin outside is 0 with derivative 0.
  std::vector<std::array<std::vector<double>, kColourChannels>> d_psf;
  std::vector<std::array<std::array<int, 4>, kColourChannels>> support;  // [h][c]
  int ray_failures = 0;
};

// The patch layout of a width x height full image under the last prepare(): what render() blurs,
// dims and warps with, for implementations of the image operations elsewhere (lensopt.torch runs
// them in torch on the input's device). Patch q = py * PsfGrid::kPatches + px.
struct ImagingPatchLayout {
  int radius = 0;                     // kernel radius r_q (px), shared by the channels
  double azimuth_rad = 0;             // direction of the PSF's +y (render/render.h)
  std::vector<double> field_weights;  // a_qh
  // L_q (render/psf_resample.h, PsfResampling at radius r_q): per PSF bin the kernel index of its
  // top-left tap (-1: out of reach) and the bilinear fractions.
  std::vector<int> corner;
  std::vector<double> fx, fy;
};

struct ImagingLayout {
  int width = 0, height = 0;
  double pitch_mm = 0, axis_x = 0, axis_y = 0;          // SensorGeometry
  std::vector<std::vector<double>> window_x, window_y;  // [patch column / row][pixel]
  std::vector<int> lo_x, hi_x, lo_y, hi_y;              // where each window is non-zero
  std::vector<ImagingPatchLayout> patches;              // [q]
  int max_radius = 0;
};

class DifferentiableImaging {
 public:
  // `param` must outlive this object. `fixed_glasses` is used with GlassMode::kFixed.
  DifferentiableImaging(const LensParameterization& param, GlassMode mode,
                        std::vector<int> fixed_glasses, DifferentiableImagingOptions options);
  ~DifferentiableImaging();
  DifferentiableImaging(const DifferentiableImaging&) = delete;
  DifferentiableImaging& operator=(const DifferentiableImaging&) = delete;

  // Samples the optics of variables x (size param.size()) with derivatives w.r.t. every
  // variable. Must be called before render()/backward(); again whenever x changes. With
  // derivatives = false it samples the values only (in double, several times faster: for
  // evaluation), and backward() throws until the next prepare with derivatives.
  void prepare(const std::vector<double>& x, bool derivatives = true);

  // The crop of the rendered full image (blur, then RI and distortion as enabled). For the same
  // lens, sampling and PsfOptions it equals Renderer::render of the full scene, restricted to the
  // crop, to float rounding (the default PsfOptions here differ: joint_psf_options()).
  FloatImage render(const FloatImage& scene, const CropWindow& crop) const;
  // The same crop in double (interleaved channels, FloatImage's layout): what render() rounds
  // to float. For finite-difference checks, where float's 6e-8 per pixel is too coarse.
  std::vector<double> render_values(const FloatImage& scene, const CropWindow& crop) const;

  // Adds dL/dx to grad_x (resized to param.size() if empty) for dL/d(rendered crop) = grad_image
  // (same shape as render's output).
  void backward(const FloatImage& scene, const CropWindow& crop, const FloatImage& grad_image,
                std::vector<double>& grad_x) const;
  // The same, and, when grad_scene is given, adds dL/d(scene) to it (resized to the scene's
  // pixel count if empty; interleaved as FloatImage). The rendering is linear in the scene,
  // R = A(x) S, so this is A^T G: the adjoint of the warp and the RI as above, then per blur task
  // the correlation of (w_q . dL/dB) with K_q, folded back through the border reflection.
  void backward(const FloatImage& scene, const CropWindow& crop, const FloatImage& grad_image,
                std::vector<double>& grad_x, std::vector<double>* grad_scene) const;

  // The pixels of a width x height scene with `channels` channels that render() and backward()
  // of `crop` read: its blurred region plus the largest kernel radius, clamped to the scene (the
  // reflection at the borders folds back inside). Throws Error as render() does.
  CropWindow scene_window(int width, int height, int channels, const CropWindow& crop) const;
  // render_values() and backward() of a window of the scene (it must hold scene_window()). With
  // grad_x null, backward() computes dL/dwindow only (no lens gradient: the optics need no
  // derivatives, and neither the blurred image nor the scene's spectra are made); grad_window,
  // if given, is resized to the window's pixel count if empty and receives dL/d(window).
  std::vector<double> render_values(const SceneWindow& scene, const CropWindow& crop) const;
  void backward(const SceneWindow& scene, const CropWindow& crop, const FloatImage& grad_image,
                std::vector<double>* grad_x, std::vector<double>* grad_window) const;

  // The optics of the last prepare() (throws Error before the first).
  const ImagingOptics& optics() const;

  // The layout render() uses for a width x height full image (throws Error before prepare(), or
  // if the image is smaller than a PSF).
  ImagingLayout layout(int width, int height) const;

  // Of the last calls. render() and backward() may run from several threads at once (the patch
  // kernels of an image size are made once, under a lock); prepare() may not overlap them.
  ImagingTimings timings() const;  // a snapshot

 private:
  struct State;
  State* state_;
};

}  // namespace lensopt
