#include "lensopt/analysis/encircled_energy.h"

#include <fftw3.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/fft.h"
#include "core/json_number.h"
#include "lensopt/analysis/field_optics.h"
#include "lensopt/core/error.h"

namespace lensopt {
namespace {

// J1(x) on [0, x_max] from a table of step h, cubic (4-point Lagrange) interpolation: error
// ~ h^4 / 24 max |J1''''| < 1e-8 for h = 0.02.
class BesselJ1Table {
 public:
  explicit BesselJ1Table(double x_max) {
    const int count = static_cast<int>(std::ceil(x_max / kStep)) + 4;
    values_.resize(count);
    for (int i = 1; i < count; ++i) values_[i] = std::cyl_bessel_j(1.0, (i - 1) * kStep);
    values_[0] = -values_[2];  // J1 is odd: J1(-h) = -J1(h)
  }
  double operator()(double x) const {
    const double t = x / kStep + 1.0;  // index into values_ (entry 1 is x = 0)
    int i = static_cast<int>(t);
    i = std::clamp(i, 1, static_cast<int>(values_.size()) - 3);
    const double s = t - i;
    const double a = values_[i - 1], b = values_[i], c = values_[i + 1], d = values_[i + 2];
    // Lagrange through the nodes -1, 0, 1, 2 (in steps) at s in [0, 1).
    return -s * (s - 1.0) * (s - 2.0) / 6.0 * a + (s + 1.0) * (s - 1.0) * (s - 2.0) / 2.0 * b -
           (s + 1.0) * s * (s - 2.0) / 2.0 * c + (s + 1.0) * s * (s - 1.0) / 6.0 * d;
  }

 private:
  static constexpr double kStep = 0.02;
  std::vector<double> values_;
};

}  // namespace

void EncircledEnergyOptions::validate() const {
  if (radii < 2 || radii > 100000)
    throw Error(fmt::format("encircled energy: {} radii must be in 2..100000", radii));
  if (!(max_radius_um >= 0) || !std::isfinite(max_radius_um))
    throw Error(
        fmt::format("encircled energy: the largest radius {} um must be >= 0 (0: "
                    "automatic)",
                    max_radius_um));
}

std::vector<double> psf_encircled_energy(const MonoWave& mono, const std::vector<double>& radii_um,
                                         double centre_x_um, double centre_y_um) {
  std::vector<double> out(radii_um.size(), 0.0);
  if (!mono.ok || mono.psf.empty() || mono.fft_n <= 0) return out;
  const int m = mono.fft_n;
  const double dx = mono.psf_dx_um, dy = mono.psf_dy_um;
  if (!(std::abs(dx) > 0) || !(std::abs(dy) > 0)) return out;
  // The DFT of the samples (row index u <-> y, column index v <-> x).
  ComplexBuffer buffer(static_cast<std::size_t>(m) * m);
  for (std::size_t i = 0; i < mono.psf.size(); ++i) {
    buffer.data[i][0] = mono.psf[i];
    buffer.data[i][1] = 0.0;
  }
  fftw_execute_dft(complex_fft_plan(m), buffer.data, buffer.data);
  const double total = buffer.data[0][0];  // Ihat_0
  if (!(total > 0)) return out;
  // The centre in (continuous) sample indices: u = (y - shift) / dy + m / 2.
  const double u_c = (centre_y_um - mono.psf_shift_y_um) / dy + 0.5 * m;
  const double v_c = (centre_x_um - mono.psf_shift_x_um) / dx + 0.5 * m;
  // Bin Re(Ihat_k exp(i 2 pi (a u_c + b v_c) / m)) on a grid of |nu| (cycles/um).
  const double nu_unit = 1.0 / (m * std::max(std::abs(dx), std::abs(dy)));
  const double step = nu_unit / 64.0;
  const double nu_max = std::hypot(0.5 / std::abs(dx), 0.5 / std::abs(dy));
  const int nodes = static_cast<int>(nu_max / step) + 3;
  std::vector<double> bins(nodes, 0.0);
  for (int r = 0; r < m; ++r) {
    const int a = r < m / 2 ? r : r - m;
    for (int c = 0; c < m; ++c) {
      const int b = c < m / 2 ? c : c - m;
      if (a == 0 && b == 0) continue;
      const double* z = buffer.data[static_cast<std::size_t>(r) * m + c];
      const double phase = 2.0 * kPi * (a * u_c + b * v_c) / m;
      const double re = z[0] * std::cos(phase) - z[1] * std::sin(phase);
      const double nu = std::hypot(a / (m * dy), b / (m * dx));
      const double t = nu / step;
      const int j = static_cast<int>(t);
      const double f = t - j;
      bins[j] += (1.0 - f) * re;
      bins[j + 1] += f * re;
    }
  }
  double r_max = 0;
  for (double r : radii_um) r_max = std::max(r_max, r);
  const BesselJ1Table j1(2.0 * kPi * r_max * (nodes + 1) * step);
  const double norm = 1.0 / (static_cast<double>(m) * m * std::abs(dx * dy) * total);
  for (std::size_t i = 0; i < radii_um.size(); ++i) {
    const double r = radii_um[i];
    double sum = kPi * r * r * total;
    if (r > 0)
      for (int j = 1; j < nodes; ++j) {
        if (bins[j] == 0.0) continue;
        const double nu = j * step;
        sum += bins[j] * r * j1(2.0 * kPi * r * nu) / nu;
      }
    out[i] = sum * norm;
  }
  return out;
}

std::optional<double> radius_at_fraction(const std::vector<double>& radius_um,
                                         const std::vector<double>& curve, double fraction) {
  for (std::size_t i = 0; i < curve.size() && i < radius_um.size(); ++i) {
    if (curve[i] < fraction) continue;
    if (i == 0) return radius_um[0];
    const double t = (fraction - curve[i - 1]) / (curve[i] - curve[i - 1]);
    return radius_um[i - 1] + t * (radius_um[i] - radius_um[i - 1]);
  }
  return std::nullopt;
}

EncircledEnergy encircled_energy(const TraceSystem<double>& sys,
                                 const EncircledEnergyOptions& options) {
  options.validate();
  const int field_count = static_cast<int>(sys.fields_deg.size());
  std::vector<int> fields = options.field_indices;
  if (fields.empty())
    for (int h = 0; h < field_count; ++h) fields.push_back(h);
  for (int h : fields)
    if (h < 0 || h >= field_count)
      throw Error(fmt::format("encircled energy: field {} out of range (the system has {})", h,
                              field_count));
  // The rays of the one trace of every field (measure_fields), kept for the chosen fields with
  // their wavelength's weight.
  std::vector<char> wanted(field_count, 0);
  for (int h : fields) wanted[h] = 1;
  struct Point {
    double x, y, weight;
  };
  std::vector<std::vector<Point>> points(field_count);
  const std::vector<double> omega =
      normalized_spot_weights(sys.wavelength_weights, sys.wavelength_count);
  FieldOpticsOptions field_options;
  field_options.maps = false;
  field_options.threads = options.wave.threads;
  const FieldOptics<double> measured =
      measure_fields(sys, field_options, [&](int h, int w, const RayBundle<double>& rays) {
        if (!wanted[h]) return;  // each field is traced by one thread: points[h] is its own
        for (std::size_t i = 0; i < rays.size(); ++i)
          if (rays.status[i] == kRayOk) points[h].push_back({rays.x[i], rays.y[i], omega[w]});
      });

  EncircledEnergy out;
  WaveReport wave;
  if (options.diffraction) {
    WaveOptions wo = options.wave;
    wo.keep_psf = true;
    wo.geometric = false;
    wave = analyze_wave(sys, wo, {}, fields);
    out.wave_warnings = wave.warnings;
    double lambda_min = 1e9;
    for (int w = 0; w < sys.wavelength_count; ++w)
      lambda_min = std::min(lambda_min, sys.lens.wavelengths_nm[w]);
    const double f_number = 1.0 / (lambda_min * 1e-6 * wave.cutoff_cyc_mm);
    out.airy_radius_um = 1.22 * sys.lens.reference_nm() * 1e-3 * f_number;
    out.diffraction_window_um = 1e300;
    for (const WaveField& f : wave.fields)
      for (const MonoWave& mono : f.mono)
        if (mono.ok)
          out.diffraction_window_um = std::min(
              out.diffraction_window_um,
              0.5 * mono.fft_n * std::min(std::abs(mono.psf_dx_um), std::abs(mono.psf_dy_um)));
    if (!(out.diffraction_window_um < 1e300)) out.diffraction_window_um = 0;
  } else {
    out.airy_radius_um =
        1.22 * sys.lens.reference_nm() * 1e-3 * (sys.efl_mm / sys.epd_mm);  // image-space N
  }
  // The radii: to the largest ray distance of the chosen fields (x 1.05), with the diffraction
  // curve at least 3 Airy radii. The diffraction curve stops at half the PSF window.
  double r_max = options.max_radius_um;
  if (r_max == 0) {
    double extent = 0;
    for (int h : fields)
      for (const Point& p : points[h])
        extent = std::max(extent, std::hypot(p.x - measured.spots.centroid_x_mm[h],
                                             p.y - measured.spots.centroid_y_mm[h]) *
                                      1e3);
    r_max = options.diffraction ? std::max(1.05 * extent, 3.0 * out.airy_radius_um) : 1.05 * extent;
  }
  if (options.diffraction && r_max > out.diffraction_window_um)
    out.warnings.push_back(fmt::format(
        "the diffraction curves stop at {:.1f} um, half the PSF window (beyond it the sampled "
        "PSF repeats); more --pupil-samples widen the window",
        out.diffraction_window_um));
  for (const std::string& w : out.wave_warnings) out.warnings.push_back(w);
  if (!(r_max > 0)) r_max = 1.0;
  for (int i = 0; i < options.radii; ++i) out.radius_um.push_back(r_max * i / (options.radii - 1));

  for (std::size_t j = 0; j < fields.size(); ++j) {
    const int h = fields[j];
    FieldEncircledEnergy f;
    f.field = h;
    f.field_deg = sys.fields_deg[h];
    f.centroid_x_mm = measured.spots.centroid_x_mm[h];
    f.centroid_y_mm = measured.spots.centroid_y_mm[h];
    f.rays = static_cast<int>(points[h].size());
    // Geometric: sorted squared distances, then a sweep over the radii.
    std::vector<std::pair<double, double>> d2;
    double total = 0;
    for (const Point& p : points[h]) {
      const double dx = (p.x - f.centroid_x_mm) * 1e3, dy = (p.y - f.centroid_y_mm) * 1e3;
      d2.push_back({dx * dx + dy * dy, p.weight});
      total += p.weight;
    }
    std::sort(d2.begin(), d2.end());
    f.geometric.assign(out.radius_um.size(), 0.0);
    std::size_t k = 0;
    double inside = 0;
    for (std::size_t i = 0; i < out.radius_um.size(); ++i) {
      const double r2 = out.radius_um[i] * out.radius_um[i];
      while (k < d2.size() && d2[k].first <= r2) inside += d2[k++].second;
      f.geometric[i] = total > 0 ? inside / total : 0.0;
    }
    f.geometric_r50_um = radius_at_fraction(out.radius_um, f.geometric, 0.5);
    f.geometric_r80_um = radius_at_fraction(out.radius_um, f.geometric, 0.8);
    f.geometric_r90_um = radius_at_fraction(out.radius_um, f.geometric, 0.9);
    if (options.diffraction) {
      const WaveField& wf = wave.fields[j];
      const double cx_um = (f.centroid_x_mm - wf.reference_x_mm) * 1e3;
      const double cy_um = (f.centroid_y_mm - wf.reference_y_mm) * 1e3;
      // The radii within half the PSF window.
      std::vector<double> radii;
      for (double r : out.radius_um)
        if (r <= out.diffraction_window_um) radii.push_back(r);
      f.diffraction.assign(radii.size(), 0.0);
      double weight = 0;
      for (const MonoWave& mono : wf.mono) {
        if (!mono.ok) continue;
        const std::vector<double> ee = psf_encircled_energy(mono, radii, cx_um, cy_um);
        for (std::size_t i = 0; i < ee.size(); ++i) f.diffraction[i] += mono.weight * ee[i];
        weight += mono.weight;
      }
      if (weight > 0)
        for (double& v : f.diffraction) v /= weight;
      f.diffraction_r50_um = radius_at_fraction(out.radius_um, f.diffraction, 0.5);
      f.diffraction_r80_um = radius_at_fraction(out.radius_um, f.diffraction, 0.8);
      f.diffraction_r90_um = radius_at_fraction(out.radius_um, f.diffraction, 0.9);
    }
    out.fields.push_back(std::move(f));
  }
  return out;
}

std::string format_encircled_energy_text(const EncircledEnergy& ee,
                                         const std::vector<double>& field_values,
                                         const std::string& field_unit) {
  std::string out;
  auto line = [&](const std::string& t) { out += t + "\n"; };
  auto um = [](const std::optional<double>& v) {
    return v ? fmt::format("{:.3f}", *v) : std::string("n/a");
  };
  const bool diffraction = !ee.fields.empty() && !ee.fields[0].diffraction.empty();
  line(fmt::format(
      "Encircled energy about the polychromatic centroid (radii in um holding 50/80/90 "
      "%; {} radii to {:.2f} um; Airy radius {:.3f} um):",
      ee.radius_um.size(), ee.radius_um.empty() ? 0.0 : ee.radius_um.back(), ee.airy_radius_um));
  line(fmt::format("  {:>11}  angle (deg)  {:>26}{}", "field (" + field_unit + ")",
                   "geometric r50 / r80 / r90",
                   diffraction ? fmt::format("  {:>28}", "diffraction r50 / r80 / r90") : ""));
  for (const FieldEncircledEnergy& f : ee.fields) {
    const double value =
        f.field < static_cast<int>(field_values.size()) ? field_values[f.field] : f.field_deg;
    const std::string geo = fmt::format("{} / {} / {}", um(f.geometric_r50_um),
                                        um(f.geometric_r80_um), um(f.geometric_r90_um));
    const std::string dif = fmt::format("{} / {} / {}", um(f.diffraction_r50_um),
                                        um(f.diffraction_r80_um), um(f.diffraction_r90_um));
    line(fmt::format("  {:11.3f}  {:11.3f}  {:>26}{}", value, f.field_deg, geo,
                     diffraction ? fmt::format("  {:>28}", dif) : ""));
  }
  for (const std::string& w : ee.warnings) line("  warning: " + w);
  return out;
}

std::string format_encircled_energy_json(const EncircledEnergy& ee) {
  using nlohmann::json;
  auto opt = [](const std::optional<double>& v) { return v ? finite_or_null(*v) : json(nullptr); };
  auto arr = [](const std::vector<double>& v) {
    json a = json::array();
    for (double x : v) a.push_back(finite_or_null(x));
    return a;
  };
  json j;
  j["radius_um"] = arr(ee.radius_um);
  j["airy_radius_um"] = finite_or_null(ee.airy_radius_um);
  j["diffraction_window_um"] = finite_or_null(ee.diffraction_window_um);
  j["warnings"] = ee.warnings;
  json fields = json::array();
  for (const FieldEncircledEnergy& f : ee.fields) {
    json o;
    o["field"] = f.field;
    o["field_deg"] = finite_or_null(f.field_deg);
    o["centroid_x_mm"] = finite_or_null(f.centroid_x_mm);
    o["centroid_y_mm"] = finite_or_null(f.centroid_y_mm);
    o["rays"] = f.rays;
    o["geometric"] = arr(f.geometric);
    o["geometric_r50_um"] = opt(f.geometric_r50_um);
    o["geometric_r80_um"] = opt(f.geometric_r80_um);
    o["geometric_r90_um"] = opt(f.geometric_r90_um);
    if (!f.diffraction.empty()) {
      o["diffraction"] = arr(f.diffraction);
      o["diffraction_r50_um"] = opt(f.diffraction_r50_um);
      o["diffraction_r80_um"] = opt(f.diffraction_r80_um);
      o["diffraction_r90_um"] = opt(f.diffraction_r90_um);
    }
    fields.push_back(o);
  }
  j["fields"] = fields;
  return j.dump();
}

}  // namespace lensopt
