// Diffraction PSFs on the geometric PSF grid (render/diffraction_psf.h).
#include "lensopt/render/diffraction_psf.h"

#include <fmt/format.h>

#include <cmath>

#include "lensopt/core/error.h"

namespace lensopt {

PsfKind parse_psf_kind(const std::string& name) {
  if (name == "geometric") return PsfKind::kGeometric;
  if (name == "diffraction") return PsfKind::kDiffraction;
  if (name == "auto") return PsfKind::kAuto;
  throw Error(fmt::format("PSF kind '{}' must be geometric, diffraction or auto", name));
}

std::string psf_kind_name(PsfKind kind) {
  switch (kind) {
    case PsfKind::kGeometric:
      return "geometric";
    case PsfKind::kDiffraction:
      return "diffraction";
    case PsfKind::kAuto:
      return "auto";
  }
  return "?";
}

DiffractionPsfs diffraction_psfs(const TraceSystem<double>& sys, const std::vector<int>& channels,
                                 const std::vector<double>& weights,
                                 const PsfSet<double>& geometric, const WaveOptions& wave_in) {
  const PsfOptions& popt = geometric.options;
  const int g = popt.grid_size;
  const int field_count = static_cast<int>(sys.fields_deg.size());
  if (static_cast<int>(geometric.fields.size()) != field_count)
    throw Error("diffraction PSFs: the geometric PSFs are of another system");
  WaveOptions wave = wave_in;
  wave.keep_psf = true;
  wave.geometric = false;
  wave.wavelength_weights = weights;
  const WaveReport report = analyze_wave(sys, wave, {});
  const std::vector<double> spec_nm(sys.lens.wavelengths_nm.begin(),
                                    sys.lens.wavelengths_nm.begin() + sys.wavelength_count);
  const auto members = channel_wavelengths(channels, spec_nm);

  DiffractionPsfs out;
  out.psfs.options = popt;
  out.psfs.fields_deg = geometric.fields_deg;
  out.psfs.fields.resize(field_count);
  out.warnings = report.warnings;
  out.pupil_samples = report.pupil_samples;
  out.fft_n = report.fft_n;
  for (int h = 0; h < field_count; ++h) {
    const WaveField& wf = report.fields[h];
    const FieldPsf<double>& geo = geometric.fields[h];
    FieldPsf<double>& f = out.psfs.fields[h];
    f.centroid_y_mm = geo.centroid_y_mm;
    f.traced_rays = geo.traced_rays;
    f.failed_rays = geo.failed_rays;
    out.strehl.push_back(wf.strehl);
    // The grid centre (0, ybar_h) relative to C_h, um.
    const double cx_um = -1e3 * wf.reference_x_mm;
    const double cy_um = 1e3 * (geo.centroid_y_mm - wf.reference_y_mm);
    std::vector<std::vector<double>> cells(wf.mono.size());
    for (int k = 0; k < kColourChannels; ++k) {
      std::vector<double>& grid = f.psf[k];
      grid.assign(static_cast<std::size_t>(g) * g, 0.0);
      double omega_sum = 0;
      for (const int w : members[k]) {
        const MonoWave& mono = wf.mono[w];
        if (cells[w].empty()) cells[w] = psf_cell_energies(mono, g, popt.bin_um, cx_um, cy_um);
        const double omega = report.weights[w];
        for (std::size_t i = 0; i < grid.size(); ++i) grid[i] += omega * cells[w][i];
        omega_sum += omega;
      }
      double total = 0;
      for (double& v : grid) {
        v = omega_sum > 0 ? v / omega_sum : 0.0;
        total += v;
      }
      f.energy_share[k] = total;
      if (total > 0)
        for (double& v : grid) v /= total;
      f.support[k] = total > 0 ? std::array<int, 4>{0, g, 0, g} : std::array<int, 4>{0, 0, 0, 0};
    }
  }
  return out;
}

double psf_rms_radius_um(const std::vector<double>& grid, const PsfOptions& options) {
  const int g = options.grid_size;
  const int c = options.centre();
  double s = 0, su = 0, sv = 0, s2 = 0;
  for (int r = 0; r < g; ++r)
    for (int i = 0; i < g; ++i) {
      const double p = grid[static_cast<std::size_t>(r) * g + i];
      if (p == 0.0) continue;
      const double u = (i - c) * options.bin_um, v = (c - r) * options.bin_um;
      s += p;
      su += p * u;
      sv += p * v;
      s2 += p * (u * u + v * v);
    }
  if (!(s > 0)) return 0.0;
  const double var = s2 / s - (su * su + sv * sv) / (s * s);
  return var > 0 ? std::sqrt(var) : 0.0;
}

DiffractionPsfs model_diffraction_psfs(const ImagingModel& model, const Lens& lens,
                                       const WaveOptions& wave) {
  // The model's own traced system (build_imaging_model prepares it once), else one of the same
  // lens and sampling.
  const TraceSystem<double> own =
      model.system
          ? TraceSystem<double>{}
          : prepare_system(make_trace_lens(lens), lens_setup(lens, model.trace), model.trace);
  const TraceSystem<double>& sys = model.system ? *model.system : own;
  WaveOptions w = wave;
  if (w.threads == 0) w.threads = model.trace.threads;
  return diffraction_psfs(sys, lens.specs.wavelength_channels,
                          lens_wavelength_weights(lens, sys.wavelength_count), model.psfs, w);
}

PsfChoice apply_psf_kind(ImagingModel& model, const Lens& lens, PsfKind kind,
                         const WaveOptions& wave) {
  PsfChoice choice;
  choice.kind = kind;
  const int field_count = static_cast<int>(model.psfs.fields.size());
  choice.channels = field_count * kColourChannels;
  model.psf_kind = psf_kind_name(kind);
  model.psf_diffraction.assign(field_count, {false, false, false});
  model.psf_pupil_samples = model.psf_padding = model.psf_fft_n = 0;
  if (kind == PsfKind::kGeometric) return choice;
  DiffractionPsfs d = model_diffraction_psfs(model, lens, wave);
  choice.warnings = d.warnings;
  model.psf_pupil_samples = d.pupil_samples;
  model.psf_padding = wave.padding;
  model.psf_fft_n = d.fft_n;
  for (int h = 0; h < field_count; ++h) {
    FieldPsf<double>& geo = model.psfs.fields[h];
    FieldPsf<double>& dif = d.psfs.fields[h];
    for (int k = 0; k < kColourChannels; ++k) {
      const bool use_diffraction =
          kind == PsfKind::kDiffraction || psf_rms_radius_um(dif.psf[k], d.psfs.options) >
                                               psf_rms_radius_um(geo.psf[k], model.psfs.options);
      if (!use_diffraction) continue;
      geo.psf[k] = std::move(dif.psf[k]);
      geo.energy_share[k] = dif.energy_share[k];
      geo.support[k] = dif.support[k];
      model.psf_diffraction[h][k] = true;
      ++choice.diffraction_channels;
    }
  }
  return choice;
}

}  // namespace lensopt
