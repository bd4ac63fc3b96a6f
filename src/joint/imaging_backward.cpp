// The adjoint of the differentiable image formation (joint/imaging.h): for G = dL/d(crop), the
// transposes of the warp, the relative illumination and the overlap-add blur (their forward
// steps in imaging.cpp, which states the maths), through the patch kernels' resampling
// (render/psf_resample.h) to the field PSFs, contracted with the Jets' derivative rows
// (optics_sampling.cpp).
#include <fftw3.h>
#include <fmt/format.h>
#include <omp.h>

#include <cmath>
#include <complex>

#include "core/fft.h"
#include "imaging_detail.h"
#include "lensopt/core/error.h"
#include "lensopt/core/interpolate.h"
#include "lensopt/core/threads.h"

namespace lensopt {

using namespace imaging_detail;

namespace {

// What the adjoint's steps share: the forward's plan and region, and the gradients of the
// per-field nodes (y_ref,h, ybar_h, R_h) they add to.
struct Adjoint {
  const DifferentiableImagingOptions& opt;
  const Optics& o;
  const Geometry& g;
  const CropPlan& p;
  const SceneWindow& scene;
  const CropWindow& crop;
  bool lens = true;       // the lens gradient wanted (else dL/dscene only)
  std::size_t plane = 0;  // pixels of the region
  int channels = 0, fields = 0;
  std::vector<double> ri;  // R per region pixel (1 without relative illumination)
  std::vector<double> g_reference, g_centroid, g_illumination;
};

// R per region pixel, the factor of B' = R B.
void illumination_factors(Adjoint& a) {
  const CropPlan& p = a.p;
  const SensorGeometry& geo = a.g.layout.geometry;
  a.ri.assign(a.plane, 1.0);
  if (!a.opt.relative_illumination) return;
  for (int j = 0; j < p.rh; ++j)
    for (int i = 0; i < p.rw; ++i)
      a.ri[static_cast<std::size_t>(j) * p.rw + i] = interpolate_linear(
          a.o.reference_y_mm, a.o.illumination, geo.radius_mm(p.rx0 + i, p.ry0 + j), false);
}

// The warp's adjoint: dL/dB' (returned, planar like B) and dL/dybar, dL/dy_ref through the
// sample positions.
std::vector<double> warp_adjoint(Adjoint& a, const FloatImage& grad_image,
                                 const std::vector<double>& bp) {
  const CropPlan& p = a.p;
  const CropWindow& crop = a.crop;
  const Optics& o = a.o;
  const Geometry& g = a.g;
  const SensorGeometry& geo = g.layout.geometry;
  const std::size_t plane = a.plane;
  const int channels = a.channels, fields = a.fields;
  std::vector<double>& g_centroid = a.g_centroid;
  std::vector<double>& g_reference = a.g_reference;
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
        const WarpTaps w = warp_taps(p, g, k, a.lens);
        double du = 0, dv = 0;
        for (int c = 0; c < channels; ++c) {
          const double gv = grad_image.at(i, j, c);
          if (gv == 0.0) continue;
          double* gc = gbp.data() + plane * c;
          if (!a.lens) {
            for (int m = 0; m < 4; ++m)
              for (int t = 0; t < 4; ++t) gc[w.index[m][t]] += w.wy[m] * w.wx[t] * gv;
            continue;
          }
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
        if (!a.lens) continue;
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
  return gbp;
}

// The relative illumination's adjoint, in place: dL/dB' -> dL/dB = R dL/dB' on the colour
// channels; dL/dR = sum_c dL/dB' B to R_h and y_ref,h.
void illumination_adjoint(Adjoint& a, const std::vector<double>& b, std::vector<double>& gbp) {
  const CropPlan& p = a.p;
  const Optics& o = a.o;
  const SensorGeometry& geo = a.g.layout.geometry;
  const std::size_t plane = a.plane;
  const int fields = a.fields;
  const std::vector<double>& ri = a.ri;
  std::vector<double>& g_illumination = a.g_illumination;
  std::vector<double>& g_reference = a.g_reference;
  std::vector<double>& gb = gbp;  // in place: dL/dB of the colour channels
  if (a.opt.relative_illumination) {
    for (int j = 0; j < p.rh; ++j) {
      for (int i = 0; i < p.rw; ++i) {
        const std::size_t k = static_cast<std::size_t>(j) * p.rw + i;
        double g_r = 0;
        if (a.lens)
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
}

// The overlap-add blur's adjoint: per task dL/dK_q[c] by correlation, through L_q^T to the mixed
// PSFs (returned, [task * 3 + c], empty where nothing) and, if g_blocks, dL/dS of each task's
// reflected scene block.
std::vector<std::vector<double>> blur_adjoint(
    Adjoint& a, const std::vector<double>& gb,
    const std::vector<std::vector<std::complex<double>>>& spectra,
    std::vector<std::vector<double>>* g_blocks) {
  const CropPlan& p = a.p;
  const Geometry& g = a.g;
  const std::size_t plane = a.plane;
  const int nthreads = thread_count(a.opt.threads);
  const int tasks = static_cast<int>(p.tasks.size());
  const std::size_t cells = static_cast<std::size_t>(a.opt.psf.grid_size) * a.opt.psf.grid_size;
  std::vector<std::vector<double>> g_mixed(tasks * kColourChannels);
  // dL/dS of each task's reflected scene block [x0 - r, x1 + r) x [y0 - r, y1 + r) (grad_scene).
  if (g_blocks) g_blocks->assign(tasks, {});
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
      const std::vector<double>& wx = g.window_x[px];
      const std::vector<double>& wy = g.window_y[py];
      const double* gc = gb.data() + plane * t.c;
      for (int j = t.y0; j < t.y1; ++j) {
        double* row = real.data + static_cast<std::size_t>(j - t.y0 + r) * nx + r;
        const double* src = gc + static_cast<std::size_t>(j - p.ry0) * p.rw + (t.x0 - p.rx0);
        for (int i = t.x0; i < t.x1; ++i) row[i - t.x0] = wy[j] * wx[i] * src[i - t.x0];
      }
      fftw_execute_dft_r2c(plans.forward, real.data, spectrum.data);
      if (g_blocks) {
        // The blur block is K * S_b (valid part, no wrap-around); its adjoint is the correlation
        // dL/dS_b(m) = sum_p G_b(p) K(p - m): the inverse FFT of FFT(G_b) conj(FFT(K)).
        RealBuffer work(static_cast<std::size_t>(ny) * nx);
        ComplexBuffer kspec(spectrum_size), product(spectrum_size);
        place_kernel(task_kernel(g, p, t).data(), r, ny, nx, work.data);
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
        std::vector<double>& block = (*g_blocks)[ti];
        block.resize(static_cast<std::size_t>(rows) * cols);
        for (int j = 0; j < rows; ++j)
          for (int i = 0; i < cols; ++i)
            block[static_cast<std::size_t>(j) * cols + i] =
                work.data[static_cast<std::size_t>(j) * nx + i];
      }
      if (!a.lens) continue;
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
      const PatchKernels& pk = g.patches[t.q];
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
  return g_mixed;
}

// dL/dS: each block folded back through the border reflection (in task order: reproducible),
// and the copied channels (alpha).
void fold_scene_gradient(const Adjoint& a, const std::vector<std::vector<double>>& g_blocks,
                         const std::vector<double>& gb, std::vector<double>* grad_scene) {
  const CropPlan& p = a.p;
  const SceneWindow& scene = a.scene;
  const FloatImage& window = scene.pixels;
  const std::size_t plane = a.plane;
  const int channels = a.channels;
  const int tasks = static_cast<int>(p.tasks.size());
  if (grad_scene) {
    std::vector<double>& gs = *grad_scene;
    if (gs.empty()) gs.assign(window.pixels.size(), 0.0);
    if (gs.size() != window.pixels.size())
      throw Error("joint imaging: grad_scene does not have the scene's size");
    // In task order (reproducible): each block folded back through the border reflection.
    for (int ti = 0; ti < tasks; ++ti) {
      const BlurTask& t = p.tasks[ti];
      const int r = t.radius, cols = t.x1 - t.x0 + 2 * r, rows = t.y1 - t.y0 + 2 * r;
      const std::vector<double>& block = g_blocks[ti];
      for (int j = 0; j < rows; ++j) {
        const int sy = reflect_index(t.y0 - r + j, scene.height) - scene.y0;
        for (int i = 0; i < cols; ++i)
          gs[window.index(reflect_index(t.x0 - r + i, scene.width) - scene.x0, sy, t.c)] +=
              block[static_cast<std::size_t>(j) * cols + i];
      }
    }
    // Channels that are not blurred (alpha) were copied.
    for (int c = p.colours; c < channels; ++c)
      for (int j = 0; j < p.rh; ++j)
        for (int i = 0; i < p.rw; ++i)
          gs[window.index(p.rx0 - scene.x0 + i, p.ry0 - scene.y0 + j, c)] +=
              gb[plane * c + static_cast<std::size_t>(j) * p.rw + i];
  }
}

// dL/dx: dL/dP_h[c] = sum_q a_qh dL/dmixed_q[c], contracted with the PSFs' derivative rows, plus
// the per-field nodes' gradients times their derivative rows.
std::vector<double> lens_gradient(const Adjoint& a, const std::vector<std::vector<double>>& g_mixed,
                                  int n) {
  const CropPlan& p = a.p;
  const Optics& o = a.o;
  const Geometry& g = a.g;
  const int fields = a.fields;
  const int tasks = static_cast<int>(p.tasks.size());
  const std::size_t cells = static_cast<std::size_t>(a.opt.psf.grid_size) * a.opt.psf.grid_size;
  const std::vector<double>& g_reference = a.g_reference;
  const std::vector<double>& g_centroid = a.g_centroid;
  const std::vector<double>& g_illumination = a.g_illumination;
  // dL/dP_h[c] = sum_q a_qh dL/dmixed_q[c].
  std::vector<std::array<std::vector<double>, kColourChannels>> g_psf(fields);
  for (int ti = 0; ti < tasks; ++ti) {
    const std::vector<double>& a = g.layout.field_weights[p.tasks[ti].q];
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
          const double v = gp[static_cast<std::size_t>(r) * a.opt.psf.grid_size + i];
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
  return gx;
}

}  // namespace

void DifferentiableImaging::backward(const FloatImage& scene, const CropWindow& crop,
                                     const FloatImage& grad_image,
                                     std::vector<double>& grad_x) const {
  backward(scene, crop, grad_image, grad_x, nullptr);
}

void DifferentiableImaging::backward(const FloatImage& scene, const CropWindow& crop,
                                     const FloatImage& grad_image, std::vector<double>& grad_x,
                                     std::vector<double>* grad_scene) const {
  backward(whole(scene), crop, grad_image, &grad_x, grad_scene);
}

void DifferentiableImaging::backward(const SceneWindow& scene, const CropWindow& crop,
                                     const FloatImage& grad_image, std::vector<double>* grad_x,
                                     std::vector<double>* grad_scene) const {
  const auto start = Clock::now();
  check_inputs(scene, crop);
  const State& s = *state_;
  const int n = s.param.size();
  const int channels = scene.pixels.channels;
  const bool lens = grad_x != nullptr;
  if (lens && grad_x->empty()) grad_x->assign(n, 0.0);
  if (lens && static_cast<int>(grad_x->size()) != n) {
    throw Error(fmt::format("joint imaging: grad_x has {} entries, the lens has {} variables",
                            grad_x->size(), n));
  }
  if (grad_image.width != crop.width || grad_image.height != crop.height ||
      grad_image.channels != channels) {
    throw Error(fmt::format("joint imaging: the gradient image is {}x{}x{}, the crop {}x{}x{}",
                            grad_image.width, grad_image.height, grad_image.channels, crop.width,
                            crop.height, channels));
  }
  if (lens && s.prepared && s.optics.variables != n) {
    throw Error("joint imaging: backward() needs prepare(x) with derivatives");
  }
  const std::shared_ptr<Geometry> g = s.geometry(scene.width, scene.height);
  const std::shared_ptr<const CropPlan> plan = s.plan(channels, crop, *g);
  const CropPlan& p = *plan;
  check_window(scene, p, *g);
  // B from render() of the same scene and crop if it is cached, else computed here (the lens
  // gradient only: dL/dscene = A^T G does not depend on the scene).
  std::shared_ptr<const std::vector<double>> cached;
  if (lens) {
    const std::uint64_t hash = s.scene_hash(scene, p, *g);
    std::lock_guard<std::mutex> lock(s.forward_mutex);
    for (const State::ForwardEntry& e : s.forward_cache) {
      if (e.generation == s.generation && e.scene_hash == hash && e.width == scene.width &&
          e.height == scene.height && e.channels == channels && e.crop.x0 == crop.x0 &&
          e.crop.y0 == crop.y0 && e.crop.width == crop.width && e.crop.height == crop.height)
        cached = e.blurred;
    }
  }
  std::vector<double> computed;
  std::vector<std::vector<std::complex<double>>> spectra;
  if (lens) s.blur_region(scene, p, *g, cached ? nullptr : &computed, &spectra);
  const std::vector<double>& b = cached ? *cached : computed;
  const int fields = static_cast<int>(s.optics.reference_y_mm.size());
  Adjoint a{s.options,
            s.optics,
            *g,
            p,
            scene,
            crop,
            lens,
            static_cast<std::size_t>(p.rw) * p.rh,
            channels,
            fields,
            {},
            std::vector<double>(fields, 0.0),
            std::vector<double>(fields, 0.0),
            std::vector<double>(fields, 0.0)};
  illumination_factors(a);
  std::vector<double> bp;  // B' = R B
  if (lens) {
    bp = b;
    for (int c = 0; c < p.colours; ++c)
      for (std::size_t k = 0; k < a.plane; ++k) bp[a.plane * c + k] *= a.ri[k];
  }
  std::vector<double> gb = warp_adjoint(a, grad_image, bp);  // dL/dB'
  illumination_adjoint(a, b, gb);                            // now dL/dB
  std::vector<std::vector<double>> g_blocks;
  const std::vector<std::vector<double>> g_mixed =
      blur_adjoint(a, gb, spectra, grad_scene ? &g_blocks : nullptr);
  fold_scene_gradient(a, g_blocks, gb, grad_scene);
  if (lens) {
    const std::vector<double> gx = lens_gradient(a, g_mixed, n);
    for (int j = 0; j < n; ++j) (*grad_x)[j] += gx[j];
  }
  s.timings.adjoint_s.store(seconds_since(start));
}

}  // namespace lensopt
