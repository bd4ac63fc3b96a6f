// Diffraction PSF, MTF and Strehl ratio (analysis/wave.h), and the pupil grid (wavefront.h).
#include "lensopt/analysis/wave.h"

#include <fftw3.h>
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <utility>

#include "core/fft.h"
#include "lensopt/core/error.h"
#include "lensopt/core/threads.h"

namespace lensopt {
namespace {

using Complex = std::complex<double>;

// Cubic (4-point Lagrange) interpolation of samples a(k) at s = k0 + t, t in [0, 1):
//   a(s) ~ -t(t-1)(t-2)/6 a(k0-1) + (t+1)(t-1)(t-2)/2 a(k0) - (t+1)t(t-2)/2 a(k0+1)
//          + (t+1)t(t-1)/6 a(k0+2),
// exact at the samples, error O(h^4) between them (linear interpolation: O(h^2), which at a
// coarse pupil grid misplaced an aberrated MTF between OTF samples by up to ~0.03).
template <typename At>
Complex cubic_at(At&& at, double s) {
  const double f = std::floor(s);
  const double t = s - f;
  const long k0 = static_cast<long>(f);
  const double w_m = -t * (t - 1.0) * (t - 2.0) / 6.0;
  const double w_0 = (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0;
  const double w_1 = -(t + 1.0) * t * (t - 2.0) / 2.0;
  const double w_2 = (t + 1.0) * t * (t - 1.0) / 6.0;
  return w_m * at(k0 - 1) + w_0 * at(k0) + w_1 * at(k0 + 1) + w_2 * at(k0 + 2);
}

// The r2c spectrum C (m rows x (m/2+1) columns) at a fractional shift along y (column 0) or
// along x (row 0, Hermitian symmetry for negative x shifts), interpolated by cubic_at. The OTF
// of an n-cell pupil vanishes from a shift of n on (m >= 2n), so a sample past m/2 is 0.
Complex spectrum_along_y(const fftw_complex* c, int m, double s) {
  auto at = [&](long k) {
    if (k > m / 2 || -k > m / 2) return Complex(0, 0);
    const long row = ((k % m) + m) % m;
    const fftw_complex& v = c[static_cast<std::size_t>(row) * (m / 2 + 1)];
    return Complex(v[0], v[1]);
  };
  return cubic_at(at, s);
}

Complex spectrum_along_x(const fftw_complex* c, int m, double s) {
  auto at = [&](long k) {
    const long a = k >= 0 ? k : -k;
    if (a > m / 2) return Complex(0, 0);
    const Complex v(c[a][0], c[a][1]);
    return k >= 0 ? v : std::conj(v);
  };
  return cubic_at(at, s);
}

struct Scratch {
  int m = 0;
  std::unique_ptr<ComplexBuffer> field;
  std::unique_ptr<RealBuffer> intensity;
  std::unique_ptr<ComplexBuffer> spectrum;
  RayBundle<double> rays;
  RayRecord<double> record;

  void ensure(int size) {
    if (m == size) return;
    m = size;
    field = std::make_unique<ComplexBuffer>(static_cast<std::size_t>(m) * m);
    intensity = std::make_unique<RealBuffer>(static_cast<std::size_t>(m) * m);
    spectrum = std::make_unique<ComplexBuffer>(static_cast<std::size_t>(m) * (m / 2 + 1));
  }
};

// One field and wavelength: wavefront, PSF, Strehl, OTFs at the frequencies.
MonoWave mono_wave(const TraceSystem<double>& sys, int h, int w, const PupilGrid& grid,
                   const std::vector<int>& cell_index, const ReferenceSphere<double>& sphere,
                   const WaveOptions& options, const std::vector<double>& freqs, int m,
                   Scratch& scratch) {
  MonoWave out;
  const Wavefront<double> wf = compute_wavefront(sys, h, w, grid, sphere, options.focus_shift_mm,
                                                 scratch.rays, scratch.record);
  const int n = grid.n;
  const double lambda_mm = wf.wavelength_nm * 1e-6;
  out.wavelength_nm = wf.wavelength_nm;
  out.rms_waves = wf.rms_waves;
  out.pv_waves = wf.pv_waves;
  out.du_x = wf.du_x;
  out.du_y = wf.du_y;
  out.fft_n = m;
  out.vignetted_fraction = wf.total_weight > 0 ? 1.0 - wf.valid_weight / wf.total_weight : 1.0;
  out.ok = wf.chief_ok && wf.valid_weight > 0 && wf.du_x != 0 && wf.du_y != 0;
  if (options.zernike_terms > 0 && wf.chief_ok) {
    int arrived = 0;
    for (std::uint8_t k : wf.ok) arrived += k;
    if (arrived >= options.zernike_terms) {
      const ZernikeFit fit = fit_zernike(wf, grid, options.zernike_terms, options.zernike_ordering);
      out.zernike_waves = fit.coefficients_waves;
      out.zernike_residual_rms_waves = fit.residual_rms_waves;
    }
  }
  out.otf_t.assign(freqs.size(), Complex(0, 0));
  out.otf_s = out.otf_t;
  out.geo_t = out.otf_t;
  out.geo_s = out.otf_t;
  if (!out.ok) return out;
  const double cell = 2.0 / n;
  // Sample (ky, kx) of the FFT lies at (x0 + kx dx, y0 + ky dy) (wave.h): dy = -lambda / (m du_y
  // cell), positive for a positive lens (du_y < 0).
  out.psf_dx_um = -1e3 * lambda_mm / (m * wf.du_x * cell);
  out.psf_dy_um = -1e3 * lambda_mm / (m * wf.du_y * cell);
  out.cutoff_t_cyc_mm = 2.0 * std::abs(wf.du_y) / lambda_mm;
  out.cutoff_s_cyc_mm = 2.0 * std::abs(wf.du_x) / lambda_mm;

  // Pupil function with the tilt removed (the shift is put back into the OTF's phase).
  scratch.ensure(m);
  fftw_complex* field = scratch.field->data;
  std::fill(reinterpret_cast<double*>(field), reinterpret_cast<double*>(field) + 2 * m * m, 0.0);
  double amplitude_sum = 0;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    if (!wf.ok[i]) continue;
    const double phase = 2.0 * kPi *
                         (wf.opd_waves[i] - wf.tilt_x_waves * grid.samples.x[i] -
                          wf.tilt_y_waves * grid.samples.y[i]);
    // Amplitude 1 for a cell whose centre is inside the pupil: area-fraction weights would
    // soften the edge and bias the autocorrelation (MTF) upwards by ~ (sum a - sum a^2) / sum a^2.
    const double px = grid.samples.x[i], py = grid.samples.y[i];
    if (px * px + py * py > 1.0) continue;
    const double a = 1.0;
    fftw_complex& v = field[static_cast<std::size_t>(grid.row[i]) * m + grid.column[i]];
    v[0] = a * std::cos(phase);
    v[1] = a * std::sin(phase);
    amplitude_sum += a;
    // Sampling check: the wavefront step to the right and upper neighbours.
    for (const auto& [dr, dc] : {std::pair{0, 1}, std::pair{1, 0}}) {
      const int r2 = grid.row[i] + dr, c2 = grid.column[i] + dc;
      if (r2 >= n || c2 >= n) continue;
      const int j = cell_index[static_cast<std::size_t>(r2) * n + c2];
      if (j < 0 || !wf.ok[j]) continue;
      out.max_step_waves =
          std::max(out.max_step_waves, std::abs(wf.opd_waves[j] - wf.opd_waves[i]));
    }
  }
  fftw_execute_dft(complex_fft_plan(m), field, field);
  double* intensity = scratch.intensity->data;
  const double norm = 1.0 / (amplitude_sum * amplitude_sum);
  double peak = 0;
  for (std::size_t k = 0; k < static_cast<std::size_t>(m) * m; ++k) {
    intensity[k] = (field[k][0] * field[k][0] + field[k][1] * field[k][1]) * norm;
    peak = std::max(peak, intensity[k]);
  }
  out.strehl = peak;
  if (options.keep_psf) {
    // Centred: output row r holds ky = r - m/2 (wrapped), column c holds kx = c - m/2.
    out.psf.assign(static_cast<std::size_t>(m) * m, 0.f);
    for (int r = 0; r < m; ++r) {
      const int ky = (r - m / 2 + m) % m;
      for (int c = 0; c < m; ++c) {
        const int kx = (c - m / 2 + m) % m;
        out.psf[static_cast<std::size_t>(r) * m + c] =
            static_cast<float>(intensity[static_cast<std::size_t>(ky) * m + kx]);
      }
    }
  }
  fftw_execute_dft_r2c(fft_plans(m, m).forward, intensity, scratch.spectrum->data);
  const fftw_complex* spectrum = scratch.spectrum->data;
  const double c0 = spectrum[0][0];
  // The tilt's image shift (mm; wave.h): x0 = -tilt_x lambda / du_x, y0 = -tilt_y lambda / du_y.
  const double x0 = -wf.tilt_x_waves * lambda_mm / wf.du_x;
  const double y0 = -wf.tilt_y_waves * lambda_mm / wf.du_y;
  out.psf_shift_x_um = 1e3 * x0;
  out.psf_shift_y_um = 1e3 * y0;
  for (std::size_t f = 0; f < freqs.size(); ++f) {
    // OTF(nu) = sum_k I_k exp(-i 2 pi nu (y0 + k dy)) = C(nu m dy) exp(-i 2 pi nu y0), C the
    // spectrum of the samples; I is real, so C(s) = conj(C(-s)), read at -s = nu lambda / (du
    // cell).
    const double nu = freqs[f];
    const double s_y = nu * lambda_mm / (wf.du_y * cell);
    const double s_x = nu * lambda_mm / (wf.du_x * cell);
    const Complex shift_t = std::polar(1.0, 2.0 * kPi * nu * y0);  // conj(exp(-i 2 pi nu y0))
    const Complex shift_s = std::polar(1.0, 2.0 * kPi * nu * x0);
    out.otf_t[f] = std::abs(s_y) >= n
                       ? Complex(0, 0)
                       : std::conj(spectrum_along_y(spectrum, m, s_y) / c0 * shift_t);
    out.otf_s[f] = std::abs(s_x) >= n
                       ? Complex(0, 0)
                       : std::conj(spectrum_along_x(spectrum, m, s_x) / c0 * shift_s);
  }
  if (options.geometric) {
    double sum = 0;
    for (std::size_t i = 0; i < grid.size(); ++i) {
      if (!wf.ok[i]) continue;
      const double a = grid.weight[i];
      sum += a;
      for (std::size_t f = 0; f < freqs.size(); ++f) {
        out.geo_t[f] += std::polar(a, -2.0 * kPi * freqs[f] * wf.image_y_mm[i]);
        out.geo_s[f] += std::polar(a, -2.0 * kPi * freqs[f] * wf.image_x_mm[i]);
      }
    }
    for (std::size_t f = 0; f < freqs.size(); ++f) {
      out.geo_t[f] /= sum;
      out.geo_s[f] /= sum;
    }
  }
  return out;
}

}  // namespace

PupilGrid make_pupil_grid(int n) {
  if (n < 2 || n > 4096) throw Error(fmt::format("pupil grid n = {} must be in [2, 4096]", n));
  PupilGrid grid;
  grid.n = n;
  const double cell = 2.0 / n;
  const int sub = 16;  // subsamples per cell side for the area fraction
  for (int iy = 0; iy < n; ++iy) {
    for (int ix = 0; ix < n; ++ix) {
      const double x0 = -1.0 + ix * cell, y0 = -1.0 + iy * cell;
      // Nearest and farthest corners: fully outside or fully inside need no subsampling.
      const double nx = std::max({x0, 0.0, -(x0 + cell)}), ny = std::max({y0, 0.0, -(y0 + cell)});
      if (nx * nx + ny * ny >= 1.0) continue;
      const double fx = std::max(std::abs(x0), std::abs(x0 + cell));
      const double fy = std::max(std::abs(y0), std::abs(y0 + cell));
      double weight = 1.0;
      if (fx * fx + fy * fy > 1.0) {
        int inside = 0;
        for (int a = 0; a < sub; ++a)
          for (int b = 0; b < sub; ++b) {
            const double x = x0 + (a + 0.5) * cell / sub, y = y0 + (b + 0.5) * cell / sub;
            inside += x * x + y * y <= 1.0;
          }
        weight = static_cast<double>(inside) / (sub * sub);
      }
      if (weight <= 0.0) continue;
      grid.column.push_back(ix);
      grid.row.push_back(iy);
      grid.weight.push_back(weight);
      grid.samples.x.push_back(x0 + 0.5 * cell);
      grid.samples.y.push_back(y0 + 0.5 * cell);
    }
  }
  return grid;
}

PupilGrid make_half_pupil_grid(int n) {
  const PupilGrid full = make_pupil_grid(n);
  PupilGrid half;
  half.n = n;
  half.mirrored = true;
  for (std::size_t i = 0; i < full.size(); ++i) {
    const double x = full.samples.x[i];
    if (x < -1e-12) continue;
    half.column.push_back(full.column[i]);
    half.row.push_back(full.row[i]);
    half.weight.push_back(x > 1e-12 ? 2.0 * full.weight[i] : full.weight[i]);
    half.samples.x.push_back(x);
    half.samples.y.push_back(full.samples.y[i]);
  }
  return half;
}

PupilGrid make_pupil_quadrature(int rings, int half_azimuths, bool mirrored) {
  if (rings < 1 || rings > 512 || half_azimuths < 1 || half_azimuths > 2048)
    throw Error(
        fmt::format("pupil quadrature of {} rings x {} azimuths per half: rings must be "
                    "in [1, 512], azimuths in [1, 2048]",
                    rings, half_azimuths));
  // Gauss-Legendre nodes t_i of [-1, 1] by Newton's method on P_R (three-term recurrence
  // (k + 1) P_{k+1} = (2k + 1) t P_k - k P_{k-1}; P_R'(t) = R (t P_R - P_{R-1}) / (t^2 - 1)),
  // weights 2 / ((1 - t^2) P_R'(t)^2); mapped to u = (1 + t) / 2 in [0, 1] with weight w / 2.
  std::vector<double> u(rings), w(rings);
  for (int i = 0; i < rings; ++i) {
    double t = std::cos(kPi * (i + 0.75) / (rings + 0.5));  // the i-th root, approximately
    double derivative = 1.0;
    for (int iteration = 0; iteration < 100; ++iteration) {
      double p0 = 1.0, p1 = t;
      for (int k = 1; k < rings; ++k) {
        const double p2 = ((2.0 * k + 1.0) * t * p1 - k * p0) / (k + 1.0);
        p0 = p1;
        p1 = p2;
      }
      derivative = rings * (t * p1 - p0) / (t * t - 1.0);
      const double step = p1 / derivative;
      t -= step;
      if (std::abs(step) < 1e-15) break;
    }
    u[i] = 0.5 * (1.0 + t);
    w[i] = 1.0 / ((1.0 - t * t) * derivative * derivative);  // (2 / (...)) / 2
  }
  PupilGrid grid;
  grid.n = 0;
  grid.mirrored = mirrored;
  const int azimuths = 2 * half_azimuths;
  for (int i = rings - 1; i >= 0; --i) {  // inner ring first
    const double r = std::sqrt(u[i]);
    for (int j = 0; j < (mirrored ? half_azimuths : azimuths); ++j) {
      const double theta = (j + 0.5) * kPi / half_azimuths;
      grid.column.push_back(j);
      grid.row.push_back(rings - 1 - i);
      grid.weight.push_back((mirrored ? 2.0 : 1.0) * kPi * w[i] / azimuths);
      grid.samples.x.push_back(r * std::sin(theta));
      grid.samples.y.push_back(r * std::cos(theta));
    }
  }
  return grid;
}

void WaveOptions::validate(int wavelength_count) const {
  if (pupil_samples < 8 || pupil_samples > 1024)
    throw Error(fmt::format("pupil samples = {} must be in [8, 1024]", pupil_samples));
  if (padding < 2 || padding > 16)
    throw Error(fmt::format("padding = {} must be in [2, 16]", padding));
  if (!wavelength_weights.empty()) {
    if (static_cast<int>(wavelength_weights.size()) != wavelength_count)
      throw Error(fmt::format("{} wavelength weights for {} wavelengths", wavelength_weights.size(),
                              wavelength_count));
    double sum = 0;
    for (double v : wavelength_weights) {
      if (!(v >= 0.0) || !std::isfinite(v))
        throw Error(fmt::format("wavelength weight {} must be finite and >= 0", v));
      sum += v;
    }
    if (!(sum > 0)) throw Error("the wavelength weights sum to 0");
  }
  if (!std::isfinite(focus_shift_mm)) throw Error("the focus shift must be finite");
  if (threads < 0) throw Error(fmt::format("threads = {} must be >= 0", threads));
  if (zernike_terms < 0 || zernike_terms > kMaxZernikeTerms)
    throw Error(
        fmt::format("Zernike terms = {} must be in [0, {}]", zernike_terms, kMaxZernikeTerms));
  if (zernike_terms > 0) zernike_term(zernike_ordering, zernike_terms);  // Fringe: at most 37
}

std::vector<double> lens_wavelength_weights(const Lens& lens, int wavelength_count) {
  if (static_cast<int>(lens.specs.wavelength_weights.size()) != wavelength_count) return {};
  return lens.specs.wavelength_weights;
}

double diffraction_limited_mtf(double v) {
  if (v <= 0.0) return 1.0;
  if (v >= 1.0) return 0.0;
  const double phi = std::acos(v);
  return 2.0 / kPi * (phi - std::cos(phi) * std::sin(phi));
}

WaveReport analyze_wave(const TraceSystem<double>& sys, const WaveOptions& options,
                        const std::vector<double>& freqs,
                        const std::vector<int>& field_indices_in) {
  const int wl_count = sys.wavelength_count;
  options.validate(wl_count);
  for (double f : freqs)
    if (!(f >= 0.0) || !std::isfinite(f))
      throw Error(fmt::format("frequency {} cycles/mm must be finite and >= 0", f));
  std::vector<int> fields = field_indices_in;
  if (fields.empty())
    for (int h = 0; h < static_cast<int>(sys.fields_deg.size()); ++h) fields.push_back(h);
  for (int h : fields)
    if (h < 0 || h >= static_cast<int>(sys.fields_deg.size()))
      throw Error(fmt::format("field index {} out of range", h));

  const PupilGrid grid = make_pupil_grid(options.pupil_samples);
  const int n = grid.n;
  std::vector<int> cell_index(static_cast<std::size_t>(n) * n, -1);
  for (std::size_t i = 0; i < grid.size(); ++i)
    cell_index[static_cast<std::size_t>(grid.row[i]) * n + grid.column[i]] = static_cast<int>(i);
  const int m = fft_size(options.padding * n);

  WaveReport report;
  report.pupil_samples = n;
  report.fft_n = m;
  report.padding = options.padding;
  report.focus_shift_mm = options.focus_shift_mm;
  report.zernike_terms = options.zernike_terms;
  report.zernike_ordering = options.zernike_ordering;
  report.frequencies_cyc_mm = freqs;
  report.weights = options.wavelength_weights;
  if (report.weights.empty()) report.weights.assign(wl_count, 1.0);
  double weight_sum = 0;
  for (double v : report.weights) weight_sum += v;
  double lambda_min = 1e9;
  for (int w = 0; w < wl_count; ++w) {
    report.wavelengths_nm.push_back(sys.lens.wavelengths_nm[w]);
    lambda_min = std::min(lambda_min, sys.lens.wavelengths_nm[w]);
  }
  if (sys.object_at_infinity()) {
    // |EFL|: a diverging lens has the same cutoff on its virtual image.
    report.cutoff_cyc_mm = sys.epd_mm / std::abs(sys.efl_mm) / (lambda_min * 1e-6);
  } else {
    report.image_na = finite_object_image_na(sys);  // the working F-number 1 / (2 NA')
    report.cutoff_cyc_mm = 2.0 * report.image_na / (lambda_min * 1e-6);
  }
  report.reference_wavelength_nm = sys.lens.wavelengths_nm.back();
  report.fields.resize(fields.size());

  // Every (field, wavelength) pair is one task.
  const int tasks = static_cast<int>(fields.size()) * wl_count;
  std::vector<ReferenceSphere<double>> spheres(fields.size());
  for (std::size_t f = 0; f < fields.size(); ++f) {
    spheres[f] = reference_sphere(sys, fields[f], options.focus_shift_mm);
    report.fields[f].field_deg = sys.fields_deg[fields[f]];
    report.fields[f].reference_x_mm = spheres[f].centre_x_mm;
    report.fields[f].reference_y_mm = spheres[f].centre_y_mm;
    report.fields[f].mono.resize(wl_count);
  }
  const int nthreads = thread_count(options.threads);
  complex_fft_plan(m);
  fft_plans(m, m);
#pragma omp parallel num_threads(nthreads)
  {
    Scratch scratch;
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < tasks; ++t) {
      const int f = t / wl_count, w = t % wl_count;
      MonoWave mono =
          mono_wave(sys, fields[f], w, grid, cell_index, spheres[f], options, freqs, m, scratch);
      mono.weight = report.weights[w];
      report.fields[f].mono[w] = std::move(mono);
    }
  }

  double max_step = 0;
  for (WaveField& field : report.fields) {
    double rms2 = 0, strehl = 0;
    std::vector<Complex> t(freqs.size()), s(freqs.size()), gt(freqs.size()), gs(freqs.size());
    for (const MonoWave& mono : field.mono) {
      const double omega = mono.weight / weight_sum;
      rms2 += omega * mono.rms_waves * mono.rms_waves;
      strehl += omega * mono.strehl;
      max_step = std::max(max_step, mono.max_step_waves);
      for (std::size_t k = 0; k < freqs.size(); ++k) {
        t[k] += omega * mono.otf_t[k];
        s[k] += omega * mono.otf_s[k];
        gt[k] += omega * mono.geo_t[k];
        gs[k] += omega * mono.geo_s[k];
      }
    }
    field.rms_waves = std::sqrt(rms2);
    field.strehl = strehl;
    for (std::size_t k = 0; k < freqs.size(); ++k) {
      field.mtf_t.push_back(std::abs(t[k]));
      field.mtf_s.push_back(std::abs(s[k]));
      if (options.geometric) {
        field.geo_mtf_t.push_back(std::abs(gt[k]));
        field.geo_mtf_s.push_back(std::abs(gs[k]));
      }
    }
    report.mean_rms_waves += field.rms_waves / report.fields.size();
    report.mean_strehl += field.strehl / report.fields.size();
  }
  if (max_step > 0.5) {
    report.warnings.push_back(fmt::format(
        "the wavefront changes by up to {:.2f} waves between neighbouring pupil samples (> 0.5): "
        "the diffraction PSF and MTF are undersampled; raise the pupil sampling (now {})",
        max_step, n));
  }
  return report;
}

namespace {

// The integral of the hat function max(0, 1 - |t|) from -inf to u.
double hat_integral(double u) {
  if (u <= -1.0) return 0.0;
  if (u <= 0.0) return 0.5 * (u + 1.0) * (u + 1.0);
  if (u <= 1.0) return 1.0 - 0.5 * (1.0 - u) * (1.0 - u);
  return 1.0;
}

// The overlaps of the interval [a, b] (sample-index units) with the hats of samples 0 .. m-1:
// (first sample, overlaps).
std::pair<int, std::vector<double>> hat_overlaps(double a, double b, int m) {
  if (a > b) std::swap(a, b);
  const int j0 = std::max(0, static_cast<int>(std::floor(a)) - 1);
  const int j1 = std::min(m - 1, static_cast<int>(std::ceil(b)) + 1);
  std::vector<double> w;
  for (int j = j0; j <= j1; ++j) w.push_back(hat_integral(b - j) - hat_integral(a - j));
  return {j0, w};
}

}  // namespace

std::vector<double> psf_cell_energies(const MonoWave& mono, int pixels, double spacing_um,
                                      double centre_x_um, double centre_y_um) {
  std::vector<double> out(static_cast<std::size_t>(pixels) * pixels, 0.0);
  if (!mono.ok || mono.psf.empty()) return out;
  const int m = mono.fft_n;
  double energy = 0;  // the interpolant's integral, in sample units
  for (float v : mono.psf) energy += v;
  if (!(energy > 0)) return out;
  // Sample-index coordinate of a position (um): f = (p - shift) / d + m / 2.
  auto fy = [&](double y_um) { return (y_um - mono.psf_shift_y_um) / mono.psf_dy_um + m / 2; };
  auto fx = [&](double x_um) { return (x_um - mono.psf_shift_x_um) / mono.psf_dx_um + m / 2; };
  std::vector<std::pair<int, std::vector<double>>> cols(pixels);
  for (int c = 0; c < pixels; ++c) {
    const double x_um = centre_x_um + (c - 0.5 * (pixels - 1)) * spacing_um;
    cols[c] = hat_overlaps(fx(x_um - 0.5 * spacing_um), fx(x_um + 0.5 * spacing_um), m);
  }
  std::vector<double> row_sum(m);
  for (int r = 0; r < pixels; ++r) {
    const double y_um = centre_y_um + (0.5 * (pixels - 1) - r) * spacing_um;  // row 0 is +y
    const auto [j0, wy] = hat_overlaps(fy(y_um - 0.5 * spacing_um), fy(y_um + 0.5 * spacing_um), m);
    // The row's weighted sum of sample rows, then each cell's columns.
    std::fill(row_sum.begin(), row_sum.end(), 0.0);
    bool any = false;
    for (std::size_t a = 0; a < wy.size(); ++a) {
      if (wy[a] <= 0.0) continue;
      any = true;
      const float* line = &mono.psf[static_cast<std::size_t>(j0 + a) * m];
      for (int k = 0; k < m; ++k) row_sum[k] += wy[a] * line[k];
    }
    if (!any) continue;
    for (int c = 0; c < pixels; ++c) {
      const auto& [k0, wx] = cols[c];
      double sum = 0;
      for (std::size_t b = 0; b < wx.size(); ++b) sum += wx[b] * row_sum[k0 + b];
      out[static_cast<std::size_t>(r) * pixels + c] = sum / energy;
    }
  }
  return out;
}

std::vector<float> polychromatic_psf(const WaveField& field, int pixels, double spacing_um) {
  std::vector<double> sum(static_cast<std::size_t>(pixels) * pixels, 0.0);
  for (const MonoWave& mono : field.mono) {
    const std::vector<double> cells = psf_cell_energies(mono, pixels, spacing_um, 0.0, 0.0);
    for (std::size_t i = 0; i < sum.size(); ++i) sum[i] += mono.weight * cells[i];
  }
  double peak = 0;
  for (double v : sum) peak = std::max(peak, v);
  std::vector<float> out(sum.size(), 0.f);
  if (peak > 0)
    for (std::size_t i = 0; i < sum.size(); ++i) out[i] = static_cast<float>(sum[i] / peak);
  return out;
}

ThroughFocus through_focus_mtf(const TraceSystem<double>& sys, const WaveOptions& options_in,
                               double frequency_cyc_mm, const std::vector<double>& shifts_mm,
                               const std::vector<int>& field_indices) {
  ThroughFocus out;
  out.frequency_cyc_mm = frequency_cyc_mm;
  out.focus_shift_mm = shifts_mm;
  WaveOptions options = options_in;
  options.geometric = false;
  options.keep_psf = false;
  for (double dz : shifts_mm) {
    options.focus_shift_mm = dz + options_in.focus_shift_mm;
    const WaveReport r = analyze_wave(sys, options, {frequency_cyc_mm}, field_indices);
    if (out.field_deg.empty()) {
      for (const WaveField& f : r.fields) out.field_deg.push_back(f.field_deg);
      out.mtf_t.resize(r.fields.size());
      out.mtf_s.resize(r.fields.size());
    }
    for (std::size_t f = 0; f < r.fields.size(); ++f) {
      out.mtf_t[f].push_back(r.fields[f].mtf_t[0]);
      out.mtf_s[f].push_back(r.fields[f].mtf_s[0]);
    }
  }
  return out;
}

}  // namespace lensopt

namespace lensopt {

std::string format_wave_text(const WaveReport& r) {
  std::string out;
  auto line = [&](const std::string& s) { out += s + "\n"; };
  auto join = [](const std::vector<double>& v, const char* f) {
    std::string s;
    for (double x : v) s += (s.empty() ? "" : ", ") + fmt::format(fmt::runtime(f), x);
    return s;
  };
  line("");
  line(fmt::format(
      "  wave optics (OPD to the exit-pupil reference sphere about the {:g} nm chief ray's image "
      "point; piston and tilt removed)",
      r.reference_wavelength_nm));
  const std::string cutoff =
      r.image_na > 0 ? fmt::format("2 NA'/lambda_min = {:.1f} cycles/mm (paraxial NA' {:.4f})",
                                   r.cutoff_cyc_mm, r.image_na)
                     : fmt::format("1/(lambda_min N) = {:.1f} cycles/mm", r.cutoff_cyc_mm);
  line(
      fmt::format("  sampling: {} x {} pupil grid, FFT {} x {} (padding {}), wavelengths {} nm "
                  "(weights {}), cutoff {}",
                  r.pupil_samples, r.pupil_samples, r.fft_n, r.fft_n, r.padding,
                  join(r.wavelengths_nm, "{:.1f}"), join(r.weights, "{:g}"), cutoff));
  if (!r.fields.empty() && !r.fields[0].mono.empty()) {
    std::string spacing;
    for (const MonoWave& m : r.fields[0].mono)
      spacing += (spacing.empty() ? "" : ", ") + fmt::format("{:.3f}", std::abs(m.psf_dy_um));
    line(fmt::format("  PSF sample spacing on axis (um, per wavelength): {}", spacing));
  }
  if (r.focus_shift_mm != 0) line(fmt::format("  focus shift {:.4f} mm", r.focus_shift_mm));
  std::string header = "  field (deg)  RMS WFE (waves)  Strehl";
  for (double f : r.frequencies_cyc_mm) header += fmt::format("  MTF{:g} T/S   ", f);
  for (double f : r.frequencies_cyc_mm) header += fmt::format("  geo{:g} T/S   ", f);
  line(header);
  for (const WaveField& f : r.fields) {
    std::string s =
        fmt::format("  {:11.3f}  {:15.4f}  {:6.4f}", f.field_deg, f.rms_waves, f.strehl);
    for (std::size_t k = 0; k < f.mtf_t.size(); ++k)
      s += fmt::format("  {:5.3f}/{:5.3f}", f.mtf_t[k], f.mtf_s[k]);
    for (std::size_t k = 0; k < f.geo_mtf_t.size(); ++k)
      s += fmt::format("  {:5.3f}/{:5.3f}", f.geo_mtf_t[k], f.geo_mtf_s[k]);
    line(s);
  }
  line(fmt::format("  mean RMS wavefront {:.4f} waves, mean Strehl {:.4f}", r.mean_rms_waves,
                   r.mean_strehl));
  if (r.zernike_terms > 0) {
    line(fmt::format(
        "  Zernike {} coefficients (waves; Z1..Z{}, the raw OPD: piston and tilt included; "
        "least squares over the rays that arrived)",
        zernike_ordering_name(r.zernike_ordering), r.zernike_terms));
    for (const WaveField& f : r.fields)
      for (const MonoWave& m : f.mono) {
        if (m.zernike_waves.empty()) {
          line(fmt::format("    field {:.3f} deg, {:.1f} nm: no fit (too few rays arrived)",
                           f.field_deg, m.wavelength_nm));
          continue;
        }
        line(fmt::format("    field {:.3f} deg, {:.1f} nm (fit residual RMS {:.2e} waves):",
                         f.field_deg, m.wavelength_nm, m.zernike_residual_rms_waves));
        std::string row;
        for (std::size_t j = 0; j < m.zernike_waves.size(); ++j) {
          row += fmt::format("  Z{:<3d}{:+.5f}", j + 1, m.zernike_waves[j]);
          if ((j + 1) % 6 == 0 || j + 1 == m.zernike_waves.size()) {
            line("    " + row);
            row.clear();
          }
        }
      }
  }
  for (const std::string& w : r.warnings) line("  warning: " + w);
  return out;
}

std::string format_wave_json(const WaveReport& r) {
  using nlohmann::json;
  auto num = [](double v) { return std::isfinite(v) ? json(v) : json(nullptr); };
  auto arr = [&](const std::vector<double>& v) {
    json a = json::array();
    for (double x : v) a.push_back(num(x));
    return a;
  };
  json j;
  j["pupil_samples"] = r.pupil_samples;
  j["fft_n"] = r.fft_n;
  j["padding"] = r.padding;
  j["focus_shift_mm"] = num(r.focus_shift_mm);
  j["wavelengths_nm"] = arr(r.wavelengths_nm);
  j["weights"] = arr(r.weights);
  j["cutoff_cyc_mm"] = num(r.cutoff_cyc_mm);
  if (r.image_na > 0) j["image_na"] = num(r.image_na);
  j["frequencies_cyc_mm"] = arr(r.frequencies_cyc_mm);
  j["mean_rms_wavefront_waves"] = num(r.mean_rms_waves);
  j["mean_strehl"] = num(r.mean_strehl);
  if (r.zernike_terms > 0) {
    j["zernike_terms"] = r.zernike_terms;
    j["zernike_ordering"] = zernike_ordering_name(r.zernike_ordering);
  }
  json fields = json::array();
  for (const WaveField& f : r.fields) {
    json o;
    o["field_deg"] = num(f.field_deg);
    o["rms_wavefront_waves"] = num(f.rms_waves);
    o["strehl"] = num(f.strehl);
    o["mtf_tangential"] = arr(f.mtf_t);
    o["mtf_sagittal"] = arr(f.mtf_s);
    o["geometric_mtf_tangential"] = arr(f.geo_mtf_t);
    o["geometric_mtf_sagittal"] = arr(f.geo_mtf_s);
    json mono = json::array();
    for (const MonoWave& m : f.mono) {
      json q;
      q["wavelength_nm"] = num(m.wavelength_nm);
      q["rms_waves"] = num(m.rms_waves);
      q["pv_waves"] = num(m.pv_waves);
      q["strehl"] = num(m.strehl);
      q["psf_dx_um"] = num(std::abs(m.psf_dx_um));
      q["psf_dy_um"] = num(std::abs(m.psf_dy_um));
      q["vignetted_fraction"] = num(m.vignetted_fraction);
      if (r.zernike_terms > 0) {
        q["zernike_waves"] = arr(m.zernike_waves);
        q["zernike_residual_rms_waves"] =
            m.zernike_waves.empty() ? json(nullptr) : num(m.zernike_residual_rms_waves);
      }
      mono.push_back(q);
    }
    o["per_wavelength"] = mono;
    fields.push_back(o);
  }
  j["fields"] = fields;
  j["warnings"] = r.warnings;
  return j.dump();
}

}  // namespace lensopt
