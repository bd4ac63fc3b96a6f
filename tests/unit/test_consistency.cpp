// The consistency suite: every quantity that two paths compute agrees, on a varied corpus of
// lenses that are not only the paper's (the shipped lenses, real .zmx files of other projects,
// optiland's lenses, and generated variants: finite objects, object- and image-height fields,
// unequal wavelength and field weights, vignetting factors). The paths:
//   * analyze_lens (`lensopt analyze`), measure_fields (analysis/field_optics.h) and the render
//     and export imaging model (build_imaging_model): spot, centroid, distortion, relative
//     illumination, ray failures agree exactly;
//   * each geometric PSF's first moment against the wavelength-weighted centroid of its
//     channel's rays, traced independently here (start_rays + trace_bundle);
//   * the plot data's centroids against analyze;
//   * measure_fields on Jets against doubles (values), and its Jet derivatives against central
//     finite differences of the double path.
// Python's field_data and spots against `lensopt analyze --json` are in tests/python.
#include <ceres/jet.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/field_optics.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/render/diffraction_psf.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace test_consistency {

namespace fs = std::filesystem;
using namespace lensopt;

namespace {

struct Case {
  std::string name;
  Lens lens;
};

std::vector<fs::path> files_in(const fs::path& dir, const std::string& ext) {
  std::vector<fs::path> out;
  if (!fs::is_directory(dir)) return out;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ext) out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

// The corpus: every lens file the project ships or keeps as test data that reads, plus variants.
std::vector<Case> corpus() {
  const fs::path src = lensopt::test::source_dir();
  std::vector<fs::path> files;
  for (const auto& p : files_in(src / "lenses", ".toml")) files.push_back(p);
  for (const auto& p : files_in(src / "lenses" / "zmx", ".zmx")) files.push_back(p);
  for (const auto& p : files_in(src / "tests" / "data" / "zmx-real", ".zmx")) files.push_back(p);
  for (const auto& p : files_in(src / "tests" / "data" / "independent", ".toml"))
    files.push_back(p);
  std::vector<Case> out;
  for (const fs::path& p : files) {
    try {
      out.push_back({p.filename().string(), read_lens(p)});
    } catch (const Error& e) {
      MESSAGE("not in the corpus (refused with a message): " << std::string(e.what()));
    }
  }
  // Variants of a 100 mm achromat as written and of a 50 mm Cooke triplet.
  const Lens achromat = read_lens(src / "lenses" / "zmx" / "achromat_ac254_100.zmx");
  const Lens cooke = read_lens(src / "lenses" / "zmx" / "cooke_triplet_50.zmx");
  {
    Lens l = achromat;
    l.specs.object_distance_mm = 300.0;
    out.push_back({"achromat at 300 mm", l});
  }
  {
    Lens l = achromat;
    l.specs.object_distance_mm = 400.0;
    l.specs.field_type = FieldType::kObjectHeight;
    l.specs.fields = {{0.0, 1.0, {}}, {8.0, 2.0, {}}, {16.0, 0.5, {}}};
    out.push_back({"achromat, object heights at 400 mm", l});
  }
  {
    Lens l = cooke;
    l.specs.field_type = FieldType::kParaxialImageHeight;
    l.specs.fields = {{0.0, 1.0, {}}, {10.0, 1.0, {}}, {18.0, 1.0, {}}};
    out.push_back({"cooke, paraxial image heights", l});
  }
  {
    Lens l = cooke;
    l.specs.field_type = FieldType::kRealImageHeight;
    l.specs.fields = {{0.0, 1.0, {}}, {10.0, 1.0, {}}, {18.0, 1.0, {}}};
    out.push_back({"cooke, real image heights", l});
  }
  {
    Lens l = cooke;
    l.specs.wavelength_weights.assign(l.specs.wavelengths_nm.size(), 1.0);
    for (std::size_t w = 0; w < l.specs.wavelength_weights.size(); ++w)
      l.specs.wavelength_weights[w] = 0.5 + 0.75 * static_cast<double>(w);
    for (std::size_t h = 0; h < l.specs.fields.size(); ++h)
      l.specs.fields[h].weight = 1.0 + static_cast<double>(h);
    out.push_back({"cooke, unequal wavelength and field weights", l});
  }
  {
    Lens l = cooke;
    // Every wavelength in the green channel: a channel fed by several weighted wavelengths.
    l.specs.wavelength_channels.assign(l.specs.wavelengths_nm.size(), 1);
    l.specs.wavelength_weights.assign(l.specs.wavelengths_nm.size(), 1.0);
    l.specs.wavelength_weights[0] = 3.0;
    out.push_back({"cooke, one channel of weighted wavelengths", l});
  }
  {
    Lens l = cooke;
    for (std::size_t h = 1; h < l.specs.fields.size(); ++h) {
      l.specs.fields[h].vignetting.vcy = 0.2;
      l.specs.fields[h].vignetting.vdy = -0.1;
    }
    out.push_back({"cooke, symmetric vignetting factors", l});
  }
  {
    Lens l = cooke;
    l.specs.fields.back().vignetting.vdx = 0.05;
    l.specs.fields.back().vignetting.vcx = 0.1;
    out.push_back({"cooke, VDX (full pupils)", l});
  }
  return out;
}

TraceOptions coarse() {
  TraceOptions t;
  t.rings = 8;
  t.fields = 7;
  return t;
}

// The omega-weighted centroid (x, y) of the rays of the given wavelengths of field h, traced
// here with the kernel directly.
void channel_centroid(const TraceSystem<double>& sys, int h, const std::vector<int>& members,
                      double& cx, double& cy, double& energy) {
  const std::vector<double> omega =
      normalized_spot_weights(sys.wavelength_weights, sys.wavelength_count);
  RayBundle<double> rays;
  double sx = 0, sy = 0;
  energy = 0;
  for (int w : members) {
    start_rays(sys, h, w, rays);
    trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                 static_cast<RayRecord<double>*>(nullptr));
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (rays.status[i] != kRayOk) continue;
      sx += omega[w] * (sys.full_pupil ? rays.x[i] : 0.0);
      sy += omega[w] * rays.y[i];
      energy += omega[w];
    }
  }
  cx = energy > 0 ? sx / energy : 0.0;
  cy = energy > 0 ? sy / energy : 0.0;
}

// The largest error of one ray's kernel first moment against the ray's position (um), over sub-bin
// offsets: the sampled Gaussian (sigma = half a bin) normalized on its nearest bins has a mean
// that deviates from the ray's position periodically in the offset. A PSF's first moment is the
// mean of its rays' kernel moments, so it lies within this of the rays' mean position.
double kernel_bias_um(const PsfOptions& po) {
  double worst = 0;
  const int g = po.grid_size, centre = po.centre();
  for (int step = 0; step <= 100; ++step) {
    const double u = -0.5 + step / 100.0;
    std::vector<double> grid(static_cast<std::size_t>(g) * g, 0.0);
    detail::kde_deposit(u, 0.0, po, grid);
    double s = 0, su = 0;
    for (int r = 0; r < g; ++r)
      for (int i = 0; i < g; ++i) {
        s += grid[static_cast<std::size_t>(r) * g + i];
        su += grid[static_cast<std::size_t>(r) * g + i] * (i - centre);
      }
    worst = std::max(worst, std::abs(su / s - u) * po.bin_um);
  }
  return worst;
}

}  // namespace

TEST_CASE("consistency: analyze, field optics, the imaging model and PSFs agree on the corpus") {
  const std::vector<Case> cases = corpus();
  int checked = 0, psf_checked = 0;
  for (const Case& c : cases) {
    CAPTURE(c.name);
    AnalyzeOptions options;
    options.trace = coarse();
    AnalysisReport report;
    try {
      report = analyze_lens(c.lens, options);
    } catch (const Error& e) {
      MESSAGE(c.name << ": analyze refuses it: " << std::string(e.what()));
      continue;
    }
    const TraceSystem<double> sys = prepare_lens_system(c.lens, options.trace);
    const FieldOptics<double> measured = measure_fields(sys);
    REQUIRE(measured.size() == report.fields.size());
    for (std::size_t h = 0; h < measured.size(); ++h) {
      const FieldReport& f = report.fields[h];
      CAPTURE(h);
      CHECK(f.field_deg == measured.fields_deg[h]);
      CHECK(f.traced_rays == measured.spots.traced_rays[h]);
      CHECK(f.failed_rays == measured.spots.failed_rays[h]);
      CHECK(f.centroid_y_mm == measured.spots.centroid_y_mm[h]);
      CHECK(f.reference_y_mm == measured.reference_y_mm[h]);
      CHECK(f.distortion_percent == 100.0 * measured.distortion[h]);
      CHECK(f.relative_illumination.has_value() ==
            static_cast<bool>(measured.relative_illumination_known[h]));
      if (f.relative_illumination) {
        CHECK(*f.relative_illumination == measured.relative_illumination[h]);
        // A relative illumination is a ratio of light: never negative, never a number that is
        // not finite.
        CHECK(std::isfinite(*f.relative_illumination));
        CHECK(*f.relative_illumination >= 0.0);
      }
      if (f.rms_spot_um) CHECK(*f.rms_spot_um == measured.spots.rms_spot_mm[h] * 1000.0);
    }
    ++checked;

    ImagingModel model;
    try {
      model = build_imaging_model(c.lens, options.trace);
    } catch (const Error& e) {
      MESSAGE(c.name << ": the imaging model refuses it: " << std::string(e.what()));
      continue;
    }
    REQUIRE(model.fields_deg.size() == report.fields.size());
    CHECK(model.ray_failures == report.ray_failures);
    const std::vector<double> spec_nm(sys.lens.wavelengths_nm.begin(),
                                      sys.lens.wavelengths_nm.begin() + sys.wavelength_count);
    const auto members = channel_wavelengths(c.lens.specs.wavelength_channels, spec_nm);
    const PsfOptions& po = model.psfs.options;
    const double bias_um = kernel_bias_um(po);
    MESSAGE("kernel first-moment bias bound: " << bias_um << " um");
    for (std::size_t h = 0; h < model.fields_deg.size(); ++h) {
      CAPTURE(h);
      const FieldReport& f = report.fields[h];
      CHECK(model.centroid_y_mm[h] == f.centroid_y_mm);
      CHECK(model.reference_y_mm[h] == f.reference_y_mm);
      CHECK(model.distortion[h] * 100.0 == f.distortion_percent);
      CHECK(model.relative_illumination[h] == f.relative_illumination.value_or(0.0));
      // The PSF grid is centred on the field's (weighted) centroid, the distortion's.
      const FieldPsf<double>& psf = model.psfs.fields[h];
      CHECK(psf.centroid_y_mm == f.centroid_y_mm);
      for (int k = 0; k < kColourChannels; ++k) {
        CAPTURE(k);
        // Only where the whole spot is inside the window is the PSF's moment the rays' mean.
        if (!(psf.energy_share[k] > 0.999999)) continue;
        double cx = 0, cy = 0, energy = 0;
        channel_centroid(sys, static_cast<int>(h), members[k], cx, cy, energy);
        const int g = po.grid_size, centre = po.centre();
        double s = 0, su = 0, sv = 0;
        for (int r = 0; r < g; ++r)
          for (int i = 0; i < g; ++i) {
            const double p = psf.psf[k][static_cast<std::size_t>(r) * g + i];
            s += p;
            su += p * (i - centre) * po.bin_um;
            sv += p * (centre - r) * po.bin_um;
          }
        // Each ray's kernel moment is its position within bias_um (kernel_bias_um), so the PSF's
        // moment is the channel's weighted ray centroid within it; a PSF centred on another
        // centroid (the unweighted one, another channel's) or weighting its rays otherwise is
        // off by more wherever the weights or the colours differ.
        CHECK(std::abs(s - 1.0) < 1e-12);
        CHECK(std::abs(su / s - 1000.0 * cx) <= bias_um + 1e-9);
        CHECK(std::abs(sv / s - 1000.0 * (cy - psf.centroid_y_mm)) <= bias_um + 1e-9);
        ++psf_checked;
      }
    }
  }
  MESSAGE("lenses checked: " << checked
                             << ", PSF channels against traced centroids: " << psf_checked);
  CHECK(checked >= 20);
  CHECK(psf_checked >= 100);
}

TEST_CASE("consistency: field optics on Jets equal the doubles, and their derivatives are exact") {
  using J = ceres::Jet<double, 1>;
  const fs::path src = lensopt::test::source_dir();
  std::vector<Case> cases;
  for (const auto& c : corpus())
    if (c.name == "cooke_triplet_50.zmx" || c.name == "achromat, object heights at 400 mm" ||
        c.name == "cooke, unequal wavelength and field weights" ||
        c.name == "cooke, VDX (full pupils)" || c.name == "tessar.toml")
      cases.push_back(c);
  REQUIRE(cases.size() == 5);
  for (const Case& c : cases) {
    CAPTURE(c.name);
    const TraceOptions trace = coarse();
    const TraceLens<double> lens_d = make_trace_lens(c.lens);
    const SystemSetup setup = lens_setup(c.lens, trace);
    // The variable: the curvature of the first surface.
    PrescriptionVariable v;
    v.kind = PrescriptionVariable::Kind::kCurvature;
    v.surface = 0;
    const TraceLens<J> lens_j =
        convert_trace_lens<J>(lens_d, {v}, 0, 1, [](double value, int j) { return J(value, j); });
    const FieldOptics<double> d = measure_fields(prepare_system(lens_d, setup, trace));
    const FieldOptics<J> j = measure_fields(prepare_system(lens_j, setup, trace));
    const double c0 = lens_d.curvature_per_mm[0];
    const double step = 1e-6 * std::max(std::abs(c0), 1e-3);
    TraceLens<double> plus = lens_d, minus = lens_d;
    plus.curvature_per_mm[0] = c0 + step;
    minus.curvature_per_mm[0] = c0 - step;
    const FieldOptics<double> fp = measure_fields(prepare_system(plus, setup, trace));
    const FieldOptics<double> fm = measure_fields(prepare_system(minus, setup, trace));
    auto same = [](double a, double b) {
      return std::abs(a - b) <= 1e-12 * std::max(1.0, std::abs(b));
    };
    auto derivative_ok = [&](const J& value, double p, double m, double scale) {
      const double fd = (p - m) / (2.0 * step);
      // Central differences err by O(step^2) f''' and by rounding (1e-16 |f| / step).
      return std::abs(value.v[0] - fd) <= 1e-6 * std::max({std::abs(fd), scale, 1e-9});
    };
    for (std::size_t h = 0; h < d.size(); ++h) {
      CAPTURE(h);
      CHECK(j.spots.traced_rays[h] == d.spots.traced_rays[h]);
      if (fp.spots.traced_rays[h] != d.spots.traced_rays[h] ||
          fm.spots.traced_rays[h] != d.spots.traced_rays[h])
        continue;  // a ray crosses a clear aperture within the step: no derivative to compare
      CHECK(same(j.spots.centroid_y_mm[h].a, d.spots.centroid_y_mm[h]));
      CHECK(same(j.spots.rms_spot_mm[h].a, d.spots.rms_spot_mm[h]));
      CHECK(same(j.distortion[h].a, d.distortion[h]));
      CHECK(same(j.relative_illumination[h].a, d.relative_illumination[h]));
      CHECK(same(j.reference_y_mm[h].a, d.reference_y_mm[h]));
      const double y_scale = std::abs(d.reference_y_mm.back()) + 1.0;
      CHECK(derivative_ok(j.spots.centroid_y_mm[h], fp.spots.centroid_y_mm[h],
                          fm.spots.centroid_y_mm[h], y_scale));
      CHECK(derivative_ok(j.spots.rms_spot_mm[h], fp.spots.rms_spot_mm[h], fm.spots.rms_spot_mm[h],
                          std::abs(d.spots.rms_spot_mm[h]) + 1e-3));
      CHECK(derivative_ok(j.distortion[h], fp.distortion[h], fm.distortion[h], 1e-3));
      CHECK(
          derivative_ok(j.reference_y_mm[h], fp.reference_y_mm[h], fm.reference_y_mm[h], y_scale));
      if (d.relative_illumination_known[h] && fp.relative_illumination_known[h] &&
          fm.relative_illumination_known[h])
        CHECK(derivative_ok(j.relative_illumination[h], fp.relative_illumination[h],
                            fm.relative_illumination[h], 1.0));
    }
  }
}

TEST_CASE("consistency: a render prepares the traced system once") {
  const fs::path src = lensopt::test::source_dir();
  for (const char* name : {"cooke.toml", "zmx/cooke_triplet_50.zmx"}) {
    CAPTURE(name);
    const Lens lens = read_lens(src / "lenses" / name);
    TraceOptions trace = coarse();
    const long before = prepared_system_count.load();
    ImagingModel model = build_imaging_model(lens, trace);
    // The diffraction PSFs (render --psf diffraction) reuse the model's system.
    WaveOptions wave;
    wave.pupil_samples = 16;
    apply_psf_kind(model, lens, PsfKind::kDiffraction, wave);
    RenderOptions options;
    const Renderer renderer(std::move(model), options);
    FloatImage image(320, 240, 3, 0.5f);
    const RenderResult result = renderer.render(image);
    CHECK(result.image.width == image.width);
    CHECK(prepared_system_count.load() - before == 1);
  }
}

TEST_CASE("consistency: relative illumination needs an on-axis field to normalize to") {
  // A lens whose fields are all off axis: R_h = A_h / A_0 was taken against the first field,
  // so the 5 deg field read 1 (a plausible, false number).
  Lens lens = read_lens(lensopt::test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx");
  lens.specs.fields = {{5.0, 1.0, {}}, {10.0, 1.0, {}}, {20.0, 1.0, {}}};
  AnalyzeOptions options;
  options.trace = coarse();
  const AnalysisReport report = analyze_lens(lens, options);
  REQUIRE(report.fields.size() == 3);
  for (const FieldReport& f : report.fields) {
    CHECK_FALSE(f.relative_illumination.has_value());
    CHECK(f.relative_illumination_unknown.find("no on-axis field") != std::string::npos);
  }
  // With the axis added, the same fields are known and below 1 off axis.
  lens.specs.fields.insert(lens.specs.fields.begin(), {0.0, 1.0, {}});
  const AnalysisReport with_axis = analyze_lens(lens, options);
  REQUIRE(with_axis.fields.size() == 4);
  CHECK(*with_axis.fields[0].relative_illumination == 1.0);
  CHECK(*with_axis.fields[1].relative_illumination < 1.0);
}

}  // namespace test_consistency
