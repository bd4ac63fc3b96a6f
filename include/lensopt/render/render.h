// Image simulation (paper "Optical Image Formation Model"): a scene image I_S becomes the
// aberrated image by a spatially varying PSF convolution, then relative illumination, then
// distortion.
//
// Sensor geometry. The image's diagonal spans the sensor diagonal d at the 1x resolution factor:
// pixel pitch p = d / sqrt(W^2 + H^2), optical axis at the image centre. At 2x the image is the
// upper-left quadrant of a virtual 2W x 2H sensor with the same diagonal: p = d / (2 sqrt(W^2 +
// H^2)) and the axis is the image's bottom-right corner. Pixel (i, j) (column, row; row 0 at the
// top) has its centre at (i + 1/2, j + 1/2); its radial image height is r = p |centre - axis|.
// The image is upright: the lens's inversion is undone, which maps the sensor's radial direction
// to the image's radial direction, so a field PSF's +y axis (radially outward) points from the
// axis towards the pixel.
//
// Spatially varying convolution (overlap-add): the image is cut into N x N = 9 x 9 patches with
// bounds b_k = round(k W / N) (and the same in y). Patch k has a 1D Hann window of length
// L_k = (1 + o) P_k, o = 0.25 (25 % overlap), P_k = b_{k+1} - b_k, centred on its centre m_k:
//   w_k(x) = cos^2(pi (x - m_k) / L_k) for |x - m_k| < L_k / 2
// (the first and last patch stay 1 from their centre to the border). The 2D window is
// w_k(x) w_l(y), divided by the windows' sum S(x) S(y) so the windows are a partition of unity
// (the raw Hann windows at 25 % overlap are not: S dips to 0.19 between patches), and
//   blurred = sum over patches q of  w_q (PSF_q * I_S),
// each convolution by FFT (FFTW) over the window's extent plus the PSF's reach. The windows
// weight the convolutions' outputs, so a uniform image stays exactly uniform whatever the patch
// PSFs; weighting the input instead (w_q I_S, Hirsch et al. 2010's form) keeps each point's
// energy exactly but leaves seams between patches whose PSFs differ in centroid (lateral colour,
// rotation) or width: 2 to 9 % in a flat 241 x 163 grey image with the Tessar and the Doublet.
// Away from seams both are the same: a pixel inside a single window is blurred by its patch PSF.
// Borders: the image is extended by symmetric reflection (x_{-1-i} = x_i) by the largest PSF
// radius, so border pixels receive light from the mirrored scene rather than from black.
// Patch PSF: PSF_q = sum_h a_qh PSF_h, a_qh = share of the patch's pixels whose radial height is
// nearest to field h's paraxial reference height y_ref,h; rotated so its +y axis points along the
// patch centre's azimuth (the centre patch, on the axis, keeps +y up); resampled to the pixel
// pitch by distributing each 4 um bin's energy bilinearly over the four nearest pixels (the
// transpose of bilinear interpolation: it keeps the energy and the centroid exactly and adds a
// variance of f (1 - f) p^2 per axis for a bin at fractional pixel offset f, p^2 / 6 on average);
// renormalized to sum 1 per channel.
// Colour: channels R, G, B of the image use the PSFs of wavelength channels 0, 1, 2; a one- or
// two-channel (grey) image uses their mean. Further channels (alpha) are not blurred and not
// dimmed; they are only distorted.
// Relative illumination: each colour channel is multiplied by R(r), R_h linearly interpolated in
// r between the fields' reference heights (Rimmer, at 587.6 nm; analysis/analyze.h), R_last
// beyond the last one (the sensor's corner may lie a little beyond y_ref,last).
// Both maps depend on r only; they are computed once per image size and cached.
// Distortion: a scene point at radial height r is imaged at r' = r + D(r) y_ref,last, D(r) the
// linear interpolation of D_h = (ybar_h - y_ref,h) / y_ref,last, so r'(y_ref,h) = ybar_h exactly.
// The output pixel at r' samples the input at the inverse r = r'^-1(r') (piecewise linear through
// (ybar_h, y_ref,h), extended with the last piece), along the same azimuth, by bicubic
// interpolation (Keys, a = -1/2; taps beyond the border take the edge value); samples that fall
// outside the input image are black (the scene there was not captured).
// Metrics: PSNR and SSIM between I_S and the blurred image, over the colour channels, before
// relative illumination and distortion (as the paper).
#pragma once

#include <array>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "lensopt/lens/lens.h"
#include "lensopt/render/image.h"
#include "lensopt/render/psf.h"
#include "lensopt/trace/system.h"

namespace lensopt {

// How to render (validated by validate()).
// Pupil grid cells across the diameter of the diffraction PSFs a render uses (`render
// --pupil-samples`, Renderer(pupil_samples=...)); analyze's wave optics default to 128.
inline constexpr int kRenderPupilSamples = 64;

struct RenderOptions {
  int res_factor = 1;                 // simulated resolution factor: 1 or 2
  bool distortion = true;             // apply the distortion warp
  bool relative_illumination = true;  // apply the relative-illumination map
  int threads = 0;                    // threads inside one image; 0: all cores

  // Throws Error for out-of-range values.
  void validate() const;
};

// What is sampled once per lens: the field PSFs and the per-field distortion and relative
// illumination (analysis/field_optics.h measure_fields, the same numbers `lensopt analyze`
// prints), from one prepared system and one trace.
struct ImagingModel {
  std::string lens_name;
  double sensor_diagonal_mm = 0;
  std::vector<double> fields_deg;
  std::vector<double> reference_y_mm;         // paraxial chief-ray heights y_ref,h (587.6 nm)
  std::vector<double> centroid_y_mm;          // ybar_h over all wavelengths
  std::vector<double> distortion;             // D_h, a fraction of y_ref,last
  std::vector<double> relative_illumination;  // R_h (0 where unknown)
  // Empty when every R_h is known; else the error that using it raises (a field whose pupil or
  // axis edge ray fails): require_relative_illumination.
  std::string unknown_relative_illumination;
  // What the commands print as warnings (build_imaging_model): the fields whose spot does not fit
  // the geometric PSF window (psf.h: G x D um), whose energy outside it is cut off.
  std::vector<std::string> warnings;
  PsfSet<double> psfs;
  TraceOptions trace;
  // The traced system the model was measured on (prepared once per model; the diffraction PSFs
  // reuse it).
  std::shared_ptr<const TraceSystem<double>> system;
  int ray_failures = 0;
  // Which PSFs `psfs` holds (render/diffraction_psf.h apply_psf_kind, `render --psf`): the kind
  // asked for ("geometric", "diffraction" or "auto"), per field and colour channel (R, G, B)
  // whether the diffraction PSF is the one used (all false: geometric; auto: the larger blur),
  // and the diffraction PSFs' pupil grid cells, padding and FFT size (0 when none was computed).
  std::string psf_kind = "geometric";
  std::vector<std::array<bool, kColourChannels>> psf_diffraction;
  int psf_pupil_samples = 0, psf_padding = 0, psf_fft_n = 0;
};

// Traces the lens at `trace` sampling and computes its PSFs, distortion and relative
// illumination. Throws Error if the lens cannot be traced or a field has no traced ray.
ImagingModel build_imaging_model(const Lens& lens, const TraceOptions& trace = {},
                                 const PsfOptions& psf = {});

// Where the pixels of a W x H image lie on the sensor.
struct SensorGeometry {
  int width = 0;
  int height = 0;
  int res_factor = 1;
  double pitch_mm = 0;
  double axis_x = 0;  // optical axis, pixel coordinates (pixel centres at i + 1/2)
  double axis_y = 0;

  static SensorGeometry make(int width, int height, int res_factor, double sensor_diagonal_mm);
  // Radial image height (mm) of the pixel centre (i + 1/2, j + 1/2).
  double radius_mm(int i, int j) const;
};

// A PSF resampled to the pixel grid: (2 radius + 1)^2 values, row-major, row 0 at the top
// (image rows grow downwards), the centre value at (radius, radius). Sums to 1.
struct PixelKernel {
  int radius = 0;
  std::vector<float> values;
  int size() const { return 2 * radius + 1; }
  float at(int dx, int dy) const {
    return values[static_cast<std::size_t>(dy + radius) * size() + (dx + radius)];
  }
};

// The 9 x 9 patches of an image and their PSFs at the pixel pitch (the "PSF grid").
struct PsfGrid {
  static constexpr int kPatches = 9;
  static constexpr double kOverlap = 0.25;
  SensorGeometry geometry;
  std::vector<int> bounds_x, bounds_y;             // kPatches + 1 each
  std::vector<std::vector<double>> field_weights;  // [patch] a_qh over fields, sums to 1
  std::vector<double> azimuth_rad;                 // [patch] direction of +y, from image +x
                                                   // towards image +y (rows down)
  std::vector<std::array<PixelKernel, kColourChannels>> kernels;  // [patch]
  std::vector<PixelKernel> grey_kernels;  // [patch] mean of the three channels
  int max_radius = 0;                     // largest kernel radius (px)

  int patch_index(int px, int py) const { return py * kPatches + px; }
};

// The PSF grid's layout alone (geometry, bounds, field weights, azimuths; no kernels) for fields
// at paraxial heights `reference_y_mm`. Throws Error if the image is smaller than 2 pixels per
// patch.
PsfGrid make_psf_grid_layout(const std::vector<double>& reference_y_mm, double sensor_diagonal_mm,
                             int width, int height, int res_factor);

// Builds the PSF grid of a W x H image. Throws Error if the image is smaller than a PSF (or than
// 2 pixels per patch).
PsfGrid make_psf_grid(const ImagingModel& model, int width, int height, int res_factor);

// The normalized 1D overlap-add windows of one axis of `extent` pixels with patch bounds
// `bounds`, sampled at pixel centres over [-pad, extent + pad): result[k][x + pad] is patch k's
// weight at pixel x; for every x they sum to 1. `raw_sum` (if not null) receives the sum before
// normalization.
std::vector<std::vector<double>> overlap_windows(const std::vector<int>& bounds, int extent,
                                                 int pad, std::vector<double>* raw_sum = nullptr);

// Where each patch's window (from overlap_windows with pad 0) is non-zero: [lo[k], hi[k]).
// Returns the widest extent.
int overlap_window_extents(const std::vector<std::vector<double>>& windows, std::vector<int>& lo,
                           std::vector<int>& hi);

// Throws Error if a W x H image is smaller than a PSF of `max_radius` pixels.
void check_image_holds_psf(int width, int height, int max_radius, double pitch_um);

// Throws the model's unknown_relative_illumination error, if any: a render that applies the
// relative illumination, or an export that writes it, needs every field's.
void require_relative_illumination(const ImagingModel& model);

// Relative illumination and distortion at a radial height (mm), by the interpolation above
// (relative_illumination_at: the caller has checked require_relative_illumination once).
double relative_illumination_at(const ImagingModel& model, double radius_mm);
double distortion_at(const ImagingModel& model, double radius_mm);  // D(r)
// The inverse distortion: the undistorted height r whose image lies at r'. Throws Error if the
// centroid heights ybar_h do not increase with the field (the map is not invertible).
double undistorted_radius_mm(const ImagingModel& model, double distorted_radius_mm);

class OverlapAddPool;  // src/render/overlap_add.h

// One rendered image.
struct RenderResult {
  FloatImage image;    // blurred, dimmed, distorted (as enabled)
  double psnr_db = 0;  // between the input and the blurred image (+inf if identical)
  double ssim = 0;
  int colour_channels = 0;  // 3, or 1 for grey images
};

// Renders images of one lens. PSF grids are built once per image size and cached (the last few
// sizes); one Renderer may render from several threads at once.
class Renderer {
 public:
  Renderer(ImagingModel model, RenderOptions options);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  const ImagingModel& model() const { return model_; }
  const RenderOptions& options() const { return options_; }

  // The PSF grid of a W x H image (built on first use).
  std::shared_ptr<const PsfGrid> psf_grid(int width, int height) const;

  // The whole pipeline. `threads` > 0 overrides options().threads for this call.
  RenderResult render(const FloatImage& input, int threads = 0) const;
  // The same, taking the input's memory for the output once the metrics have read it: two
  // images of the input's size alive at once instead of three (the same values).
  RenderResult render(FloatImage&& input, int threads = 0) const;

  // The steps, for tests and export.
  FloatImage blur(const FloatImage& input, int threads = 0) const;
  void apply_relative_illumination(FloatImage& image, int threads = 0) const;
  FloatImage apply_distortion(const FloatImage& image, int threads = 0) const;

 private:
  struct GridEntry;
  std::shared_ptr<GridEntry> entry(int width, int height) const;
  // `out` = `input` with its colour channels (R, G, B or grey) blurred.
  void blur_into(const FloatImage& input, FloatImage& out, int nthreads) const;
  // render(); `reuse` (if not null, possibly `input` itself) gives its memory to the output after
  // the metrics.
  RenderResult render_impl(const FloatImage& input, FloatImage* reuse, int threads) const;
  // apply_distortion into `out` (its memory reused when it has the size).
  void warp_into(const FloatImage& image, FloatImage& out, int nthreads) const;
  // Per pixel of a W x H image: the relative-illumination factor; the warp's source offset
  // (x, y interleaved, pixels; NaN where the source is outside the image). Cached per image size
  // while they take at most kMapBudgetBytes; null above (a 4K image's would take 100 MB), and
  // the callers make each row's values as they need them (the same values).
  static constexpr std::size_t kMapBudgetBytes = std::size_t{48} << 20;
  std::shared_ptr<const std::vector<float>> illumination_map(int width, int height) const;
  std::shared_ptr<const std::vector<float>> warp_map(int width, int height) const;
  // Row j's values of those maps, for pixels [0, width) (the function the maps are made with).
  void illumination_row(const SensorGeometry& geo, int j, float* factor) const;
  void warp_row_offsets(const SensorGeometry& geo, int j, float* offsets) const;

  // The most recently used image sizes (a dataset of many sizes does not keep them all).
  template <typename V>
  struct SizeCache {
    static constexpr std::size_t kSizes = 4;
    std::map<std::pair<int, int>, std::pair<std::shared_ptr<V>, long>> items;
    long counter = 0;
    std::shared_ptr<V> find(int width, int height) {
      auto it = items.find({width, height});
      if (it == items.end()) return nullptr;
      it->second.second = ++counter;
      return it->second.first;
    }
    void insert(int width, int height, std::shared_ptr<V> value) {
      if (items.size() >= kSizes) {
        auto oldest = items.begin();
        for (auto i = items.begin(); i != items.end(); ++i)
          if (i->second.second < oldest->second.second) oldest = i;
        items.erase(oldest);
      }
      items[{width, height}] = {std::move(value), ++counter};
    }
  };

  ImagingModel model_;
  RenderOptions options_;
  mutable std::mutex mutex_;  // guards the caches (and is held while an entry is built)
  mutable SizeCache<GridEntry> grids_;
  mutable SizeCache<const std::vector<float>> illumination_maps_;
  mutable SizeCache<const std::vector<float>> warp_maps_;
  // The FFT buffers of the blur, kept between renders (render/overlap_add.h).
  std::unique_ptr<OverlapAddPool> buffer_pool_;
};

// Number of colour channels of an image with `channels` channels (3 for RGB/RGBA, 1 for grey).
int colour_channel_count(int channels);

}  // namespace lensopt
