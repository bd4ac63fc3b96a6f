// Diffraction PSFs for rendering (render/diffraction_psf.h): the bins of a PSF integrate its
// energy (a grid covering the FFT window holds all of it), each channel sums to 1 with the part
// inside the grid reported, the pixel kernels built from them conserve energy, the geometric
// choice leaves the model untouched, auto picks the larger blur, and the render metrics' settings
// record which PSFs were used.
#include <doctest/doctest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "lensopt/analysis/wave.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/render/chart.h"
#include "lensopt/render/dataset.h"
#include "lensopt/render/diffraction_psf.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace test_render_diffraction {

using namespace lensopt;

namespace {

// f = 100 mm f/10 plano-convex singlet, three wavelengths, 0.5 deg: near the diffraction limit
// (Strehl ~0.75 at 587.6 nm on axis, checked), Airy radius 1.22 lambda N ~ 7 um, under two 4 um
// bins.
Lens fast_singlet() {
  const char* text = R"(
[lens]
name = "f10-singlet"
[specs]
f_number = 10.0
half_field_deg = 0.5
sensor_diagonal_mm = 1.7453292519943295
wavelengths_nm = [486.13, 587.56, 656.27]
channels = ["B", "G", "R"]
dispersion = "abbe"
[[surfaces]]
radius_mm = inf
thickness_mm = 1.0
stop = true
[[surfaces]]
radius_mm = 51.68
thickness_mm = 4.0
material = { nd = 1.5168, vd = 64.17 }
[[surfaces]]
radius_mm = inf
thickness_mm = 97.36
)";
  Lens lens = parse_lens_toml(text, "f10-singlet");
  lens.specs.wavelength_weights = {1.0, 2.0, 1.0};  // the polychromatic sums weigh them
  return lens;
}

TraceOptions small_trace() {
  TraceOptions t;
  t.fields = 3;
  t.rings = 8;
  return t;
}

}  // namespace

TEST_CASE("render diffraction: PSF bins integrate the energy; channels sum to 1; kernels too") {
  const Lens lens = fast_singlet();
  const ImagingModel model = build_imaging_model(lens, small_trace());
  WaveOptions wave;
  wave.pupil_samples = 48;
  const DiffractionPsfs d = model_diffraction_psfs(model, lens, wave);
  REQUIRE(d.psfs.fields.size() == model.psfs.fields.size());
  const PsfOptions& popt = d.psfs.options;
  for (std::size_t h = 0; h < d.psfs.fields.size(); ++h) {
    CAPTURE(h);
    const FieldPsf<double>& f = d.psfs.fields[h];
    CHECK(f.centroid_y_mm == model.psfs.fields[h].centroid_y_mm);
    for (int k = 0; k < kColourChannels; ++k) {
      double sum = 0, min = 1;
      for (double v : f.psf[k]) {
        sum += v;
        min = std::min(min, v);
      }
      CHECK(sum == doctest::Approx(1.0).epsilon(1e-12));
      CHECK(min >= 0.0);
      // The Airy pattern's rings beyond the 260 um grid hold well under 3 % (for lambda N ~ 6 um).
      CHECK(f.energy_share[k] > 0.97);
      CHECK(f.energy_share[k] <= 1.0 + 1e-12);
      // Its blur is the diffraction limit's, below the geometric bins' KDE: centroid within a
      // bin of the grid centre.
      double su = 0, sv = 0;
      const int g = popt.grid_size, c = popt.centre();
      for (int r = 0; r < g; ++r)
        for (int i = 0; i < g; ++i) {
          su += f.psf[k][static_cast<std::size_t>(r) * g + i] * (i - c);
          sv += f.psf[k][static_cast<std::size_t>(r) * g + i] * (c - r);
        }
      CHECK(std::abs(su) < 1.0);
      CHECK(std::abs(sv) < 1.0);
    }
  }

  // The bins of one monochromatic PSF over a grid covering its whole FFT window hold all of its
  // energy (the resampling conserves energy); the green PSF on axis.
  WaveOptions keep = wave;
  keep.keep_psf = true;
  const TraceSystem<double> sys =
      prepare_system(make_trace_lens(lens), lens_setup(lens, model.trace), model.trace);
  const WaveReport r = analyze_wave(sys, keep, {}, {0});
  const MonoWave& mono = r.fields[0].mono[1];
  REQUIRE(mono.ok);
  CHECK(mono.strehl > 0.6);  // the premise: the Airy core dominates
  const double window_um =
      mono.fft_n * std::max(std::abs(mono.psf_dx_um), std::abs(mono.psf_dy_um));
  for (const double spacing : {popt.bin_um, 0.37 * std::abs(mono.psf_dy_um)}) {
    CAPTURE(spacing);
    const int pixels = static_cast<int>(std::ceil(window_um / spacing)) + 4;
    double total = 0;
    for (double v :
         psf_cell_energies(mono, pixels, spacing, mono.psf_shift_x_um, mono.psf_shift_y_um))
      total += v;
    CHECK(total == doctest::Approx(1.0).epsilon(1e-9));
  }

  // Pixel kernels from the diffraction PSFs (the Renderer's): each non-negative, summing to 1.
  ImagingModel diffraction_model = model;
  const PsfChoice choice = apply_psf_kind(diffraction_model, lens, PsfKind::kDiffraction, wave);
  CHECK(choice.diffraction_channels == choice.channels);
  const PsfGrid grid = make_psf_grid(diffraction_model, 96, 64, 1);
  for (const auto& kernels : grid.kernels)
    for (const PixelKernel& kernel : kernels) {
      double sum = 0, min = 1;
      for (float v : kernel.values) {
        sum += v;
        min = std::min<double>(min, v);
      }
      CHECK(sum == doctest::Approx(1.0).epsilon(1e-5));
      CHECK(min >= 0.0);
    }
}

TEST_CASE("render diffraction: geometric leaves the model as it is; auto takes the larger blur") {
  const Lens lens = fast_singlet();
  const ImagingModel model = build_imaging_model(lens, small_trace());
  WaveOptions wave;
  wave.pupil_samples = 32;
  ImagingModel same = model;
  const PsfChoice geometric = apply_psf_kind(same, lens, PsfKind::kGeometric, wave);
  CHECK(geometric.diffraction_channels == 0);
  for (std::size_t h = 0; h < model.psfs.fields.size(); ++h)
    for (int k = 0; k < kColourChannels; ++k)
      CHECK(same.psfs.fields[h].psf[k] == model.psfs.fields[h].psf[k]);

  // Auto: every (field, channel) gets the PSF of the larger RMS radius.
  const DiffractionPsfs d = model_diffraction_psfs(model, lens, wave);
  ImagingModel chosen = model;
  const PsfChoice choice = apply_psf_kind(chosen, lens, PsfKind::kAuto, wave);
  int expected = 0;
  for (std::size_t h = 0; h < model.psfs.fields.size(); ++h)
    for (int k = 0; k < kColourChannels; ++k) {
      const double rg = psf_rms_radius_um(model.psfs.fields[h].psf[k], model.psfs.options);
      const double rd = psf_rms_radius_um(d.psfs.fields[h].psf[k], d.psfs.options);
      const bool diffraction = rd > rg;
      expected += diffraction;
      CHECK(chosen.psfs.fields[h].psf[k] ==
            (diffraction ? d.psfs.fields[h].psf[k] : model.psfs.fields[h].psf[k]));
    }
  CHECK(choice.diffraction_channels == expected);
  // This f/10 singlet is near the diffraction limit on axis: the Airy pattern is the larger blur
  // there in green.
  CHECK(psf_rms_radius_um(d.psfs.fields[0].psf[1], d.psfs.options) >
        psf_rms_radius_um(model.psfs.fields[0].psf[1], model.psfs.options));
  // A strongly aberrated lens (the Cooke at full aperture) keeps geometric PSFs at full field.
  const Lens cooke = read_lens(test::source_dir() / "lenses/cooke.toml");
  ImagingModel cooke_model = build_imaging_model(cooke, small_trace());
  const ImagingModel cooke_geometric = cooke_model;
  apply_psf_kind(cooke_model, cooke, PsfKind::kAuto, wave);
  CHECK(cooke_model.psfs.fields.back().psf[1] == cooke_geometric.psfs.fields.back().psf[1]);
  CHECK_THROWS_AS(parse_psf_kind("wave"), Error);
}

TEST_CASE("render diffraction: the metrics' settings record the PSF kind and auto's choice") {
  namespace fs = std::filesystem;
  const Lens lens = fast_singlet();
  const ImagingModel model = build_imaging_model(lens, small_trace());
  CHECK(model.psf_kind == "geometric");  // as built: the ray-density PSFs
  WaveOptions wave;
  wave.pupil_samples = 32;
  const fs::path dir =
      fs::temp_directory_path() / ("lensopt-test-render-psf-kind-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  ChartOptions chart;
  chart.width = 96;
  chart.height = 64;
  chart.text = false;
  write_image(dir / "chart.png", make_test_chart(chart).image);
  RenderOptions ro;
  ro.threads = 1;
  // Renders the chart with `kind` into OUT/<kind> (or `out`) and returns the metrics' settings.
  auto settings_of = [&](PsfKind kind, const std::string& out, PsfChoice& choice, ImagingModel& m,
                         std::vector<std::string>* notes = nullptr) {
    m = model;
    choice = apply_psf_kind(m, lens, kind, wave);
    const Renderer renderer(m, ro);
    DatasetOptions d;
    d.inputs = {dir / "chart.png"};
    d.output_dir = dir / out;
    d.jobs = 1;
    const DatasetSummary s = render_dataset(renderer, d);
    CHECK(s.failed == 0);
    if (notes) *notes = s.notes;
    return nlohmann::json::parse(read_file(dir / out / "render_metrics.json"))["settings"];
  };
  PsfChoice choice;
  ImagingModel m;
  const nlohmann::json geometric = settings_of(PsfKind::kGeometric, "geometric", choice, m);
  CHECK(geometric["psf"] == nlohmann::json{{"kind", "geometric"}});
  CHECK(geometric["lens"] == "f10-singlet");

  const nlohmann::json diffraction = settings_of(PsfKind::kDiffraction, "diffraction", choice, m);
  CHECK(diffraction["psf"]["kind"] == "diffraction");
  CHECK(diffraction["psf"]["pupil_samples"] == 32);
  CHECK(diffraction["psf"]["padding"] == wave.padding);
  CHECK(diffraction["psf"]["fft_n"].get<int>() >= 2 * 32);
  CHECK(!diffraction["psf"].contains("chosen"));

  const nlohmann::json automatic = settings_of(PsfKind::kAuto, "auto", choice, m);
  const nlohmann::json& psf = automatic["psf"];
  CHECK(psf["kind"] == "auto");
  CHECK(psf["diffraction_channels"] == choice.diffraction_channels);
  CHECK(psf["channels"] == choice.channels);
  REQUIRE(psf["chosen"].size() == m.psfs.fields.size());
  int diffraction_channels = 0;
  for (std::size_t h = 0; h < m.psfs.fields.size(); ++h) {
    const nlohmann::json& field = psf["chosen"][h];
    CHECK(field["field_deg"].get<double>() == m.fields_deg[h]);
    const char* names[kColourChannels] = {"R", "G", "B"};
    for (int k = 0; k < kColourChannels; ++k) {
      // The choice recorded is the PSF the renderer holds.
      const bool used = m.psfs.fields[h].psf[k] != model.psfs.fields[h].psf[k];
      CHECK(m.psf_diffraction[h][k] == used);
      CHECK(field[names[k]] == (used ? "diffraction" : "geometric"));
      diffraction_channels += used;
    }
  }
  CHECK(diffraction_channels == choice.diffraction_channels);
  // Near the diffraction limit on axis (the test above): green is diffraction there.
  CHECK(psf["chosen"][0]["G"] == "diffraction");

  // Rendering the geometric folder again with auto: the settings differ, the image is kept.
  std::vector<std::string> notes;
  settings_of(PsfKind::kAuto, "geometric", choice, m, &notes);
  bool noted = false;
  for (const std::string& n : notes) noted |= n.find("other settings") != std::string::npos;
  CHECK(noted);
  fs::remove_all(dir);
}

}  // namespace test_render_diffraction
