// Image simulation: KDE PSFs (normalization, Jet derivatives), the overlap-add windows, the
// blur's conservation of light, consistency of a rendered point's blur with the traced spot,
// relative illumination and distortion, PSNR/SSIM, the baselines' ranking, and bad input.
#include <ceres/jet.h>
#include <doctest/doctest.h>
#include <unistd.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <map>

#include "lensopt/core/error.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/render/chart.h"
#include "lensopt/render/dataset.h"
#include "lensopt/render/metrics.h"
#include "lensopt/render/psf.h"
#include "lensopt/render/render.h"
#include "test_support.h"

using namespace lensopt;
namespace fs = std::filesystem;

namespace {

Lens project_lens(const std::string& name) {
  return read_lens(test::source_dir() / "lenses" / (name + ".toml"));
}

// One imaging model per lens for the whole test binary (full paper sampling).
const ImagingModel& model_of(const std::string& name) {
  static std::map<std::string, ImagingModel> cache;
  auto it = cache.find(name);
  if (it == cache.end()) it = cache.emplace(name, build_imaging_model(project_lens(name))).first;
  return it->second;
}

// A fresh empty folder under the system temp folder, removed by the destructor.
struct TempDir {
  fs::path path;
  TempDir() {
    static std::atomic<int> counter{0};
    path = fs::temp_directory_path() /
           ("lensopt-test-render-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

std::vector<std::string> list_files(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out.push_back(e.path().lexically_relative(dir).generic_string());
  std::sort(out.begin(), out.end());
  return out;
}

double mean_of(const FloatImage& img, int c) {
  double sum = 0;
  for (int j = 0; j < img.height; ++j)
    for (int i = 0; i < img.width; ++i) sum += img.at(i, j, c);
  return sum / (static_cast<double>(img.width) * img.height);
}

FloatImage chart(int w, int h) {
  ChartOptions o;
  o.width = w;
  o.height = h;
  o.text = false;
  return make_test_chart(o).image;
}

// Traced moments of field h, per channel, about the field's grid centre (0, ybar_h): the second
// moment E[x^2 + (y - ybar)^2] (mm^2) and the mean offset E[y] - ybar (mm). Straight from the
// tracer (start_rays + trace_bundle), independent of the PSF code.
struct ChannelMoments {
  std::array<double, 3> second{}, offset{}, rms_mm{};
};
ChannelMoments traced_moments(const Lens& lens, int h) {
  const TraceSystem<double> sys = prepare_system(make_trace_lens(lens), lens.specs, TraceOptions{});
  std::array<double, 3> n{}, sy{}, sx2{}, sy2{};
  double all_y = 0, all_n = 0;
  RayBundle<double> rays;
  for (int w = 0; w < sys.wavelength_count; ++w) {
    start_rays(sys, h, w, rays);
    trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                 static_cast<RayRecord<double>*>(nullptr));
    const int c = lens.specs.wavelength_channels[w];
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (rays.status[i] != kRayOk) continue;
      n[c] += 1;
      sy[c] += rays.y[i];
      sx2[c] += rays.x[i] * rays.x[i];
      sy2[c] += rays.y[i] * rays.y[i];
      all_y += rays.y[i];
      all_n += 1;
    }
  }
  const double ybar = all_y / all_n;
  ChannelMoments m;
  for (int c = 0; c < 3; ++c) {
    const double mean_y = sy[c] / n[c];
    m.offset[c] = mean_y - ybar;
    m.second[c] = sx2[c] / n[c] + sy2[c] / n[c] - 2 * ybar * mean_y + ybar * ybar;
    m.rms_mm[c] = std::sqrt(sx2[c] / n[c] + sy2[c] / n[c] - mean_y * mean_y);
  }
  return m;
}

}  // namespace

TEST_CASE("psf: every field PSF sums to 1 per channel and reports its energy share") {
  for (const std::string name : {"doublet", "cooke", "tessar"}) {
    const ImagingModel& model = model_of(name);
    REQUIRE(model.psfs.fields.size() == 21);
    for (std::size_t h = 0; h < model.psfs.fields.size(); ++h) {
      const FieldPsf<double>& f = model.psfs.fields[h];
      CHECK(f.centroid_y_mm == doctest::Approx(model.centroid_y_mm[h]).epsilon(1e-12));
      for (int c = 0; c < 3; ++c) {
        double sum = 0, min = 1;
        for (double v : f.psf[c]) {
          sum += v;
          min = std::min(min, v);
        }
        INFO(name, " field ", h, " channel ", c);
        CHECK(sum == doctest::Approx(1.0).epsilon(1e-12));
        CHECK(min >= 0.0);
        CHECK(f.traced_rays[c] == 5 * 1024);
        CHECK(f.energy_share[c] > 0.0);
        CHECK(f.energy_share[c] <= 1.0 + 1e-12);
        // The Cooke's and Tessar's spots fit the 260 um grid; the Doublet's outer fields do not.
        if (name != "doublet") CHECK(f.energy_share[c] > 0.999);
      }
    }
  }
  // The Doublet's largest field loses light outside the grid (its RMS spot is 135 um).
  CHECK(model_of("doublet").psfs.fields.back().energy_share[0] < 0.99);
}

TEST_CASE("psf: a single ray inside the grid deposits exactly its energy, centred on it") {
  PsfOptions o;
  std::vector<double> grid(static_cast<std::size_t>(o.grid_size) * o.grid_size, 0.0);
  detail::kde_deposit(3.3, -7.8, o, grid);
  double sum = 0, mu = 0, mv = 0, vu = 0;
  for (int r = 0; r < o.grid_size; ++r)
    for (int i = 0; i < o.grid_size; ++i) {
      const double m = grid[static_cast<std::size_t>(r) * o.grid_size + i];
      sum += m;
      mu += m * (i - o.centre());
      mv += m * (o.centre() - r);
      vu += m * (i - o.centre() - 3.3) * (i - o.centre() - 3.3);
    }
  CHECK(sum == doctest::Approx(1.0).epsilon(1e-14));
  // The sampled Gaussian's mean and variance differ from the ray's position and s^2 only by the
  // ripple of sampling at 2 s (amplitude 2 exp(-pi^2 / 2) (2 pi s^2 / D) = 0.023 bins = 0.09 um).
  CHECK(std::abs(mu - 3.3) < 0.025);
  CHECK(std::abs(mv + 7.8) < 0.025);
  CHECK(vu == doctest::Approx(0.25).epsilon(0.02));
  // On the grid's edge (u = 32.5 bins): only the part inside is kept, the taps at 31 and 32 of
  // the five at 31..35 around the nearest bin 33 (g(d) = exp(-2 d^2), d in bins).
  std::fill(grid.begin(), grid.end(), 0.0);
  detail::kde_deposit(32.5, 0.0, o, grid);
  sum = 0;
  for (double v : grid) sum += v;
  auto g = [](double d) { return std::exp(-2 * d * d); };
  CHECK(sum == doctest::Approx((g(1.5) + g(0.5)) / (2 * g(1.5) + 2 * g(0.5) + g(2.5))).epsilon(1e-12));
}

TEST_CASE("psf: Jet derivatives of one field's PSF match finite differences") {
  const Lens lens = project_lens("tessar");
  const int h = 12;
  const std::vector<PrescriptionVariable> all = all_prescription_variables(lens);
  // The front curvature and the third element's index.
  std::vector<PrescriptionVariable> vars;
  for (const PrescriptionVariable& v : all)
    if (v.name() == "c1" || v.name() == "nd6") vars.push_back(v);
  REQUIRE(vars.size() == 2);
  using J = ceres::Jet<double, 2>;
  const TraceLens<J> lens_j = convert_trace_lens<J>(make_trace_lens(lens), vars, 0, 2,
                                                    [](double v, int j) { return J(v, j); });
  const TraceSystem<J> sys_j = prepare_system(lens_j, lens.specs, TraceOptions{});
  RayBundle<J> rays_j;
  const FieldPsf<J> psf_j =
      field_psf(sys_j, h, lens.specs.wavelength_channels, PsfOptions{}, rays_j);

  auto psf_at = [&](const PrescriptionVariable& v, double value) {
    Lens l = lens;
    set_variable_value(l, v, value);
    const TraceSystem<double> sys = prepare_system(make_trace_lens(l), l.specs, TraceOptions{});
    RayBundle<double> rays;
    return field_psf(sys, h, l.specs.wavelength_channels, PsfOptions{}, rays);
  };
  for (int j = 0; j < 2; ++j) {
    const double x0 = variable_value(lens, vars[j]);
    const double step = vars[j].kind == PrescriptionVariable::Kind::kCurvature ? 2e-6 : 1e-5;
    const FieldPsf<double> plus = psf_at(vars[j], x0 + step), minus = psf_at(vars[j], x0 - step);
    const FieldPsf<double> plus2 = psf_at(vars[j], x0 + step / 2),
                           minus2 = psf_at(vars[j], x0 - step / 2);
    auto fd = [&](double p, double m, double p2, double m2) {
      return (4 * (p2 - m2) / step - (p - m) / (2 * step)) / 3;  // Richardson
    };
    CHECK(psf_j.centroid_y_mm.v[j] ==
          doctest::Approx(fd(plus.centroid_y_mm, minus.centroid_y_mm, plus2.centroid_y_mm,
                             minus2.centroid_y_mm))
              .epsilon(1e-5));
    for (int c = 0; c < 3; ++c) {
      double largest = 0, worst = 0;
      for (const J& v : psf_j.psf[c]) largest = std::max(largest, std::abs(v.v[j]));
      REQUIRE(largest > 0);
      for (std::size_t i = 0; i < psf_j.psf[c].size(); ++i) {
        const double d = fd(plus.psf[c][i], minus.psf[c][i], plus2.psf[c][i], minus2.psf[c][i]);
        worst = std::max(worst, std::abs(psf_j.psf[c][i].v[j] - d) / largest);
      }
      INFO("d psf / d ", vars[j].name(), " channel ", c, ": worst error ", worst,
           " of the largest derivative ", largest);
      CHECK(worst < 1e-4);
      CHECK(psf_j.psf[c][0].a == doctest::Approx(psf_at(vars[j], x0).psf[c][0]).epsilon(1e-12));
    }
  }
}

TEST_CASE("render: the overlap-add windows are a partition of unity") {
  for (int extent : {18, 100, 720, 1281}) {
    std::vector<int> bounds;
    for (int k = 0; k <= PsfGrid::kPatches; ++k)
      bounds.push_back(static_cast<int>(std::lround(static_cast<double>(k) * extent / 9)));
    std::vector<double> raw;
    const auto w = overlap_windows(bounds, extent, 7, &raw);
    double raw_min = 1e9, raw_max = 0;
    for (int i = 0; i < extent + 14; ++i) {
      double sum = 0;
      for (const auto& wk : w) sum += wk[i];
      CHECK(sum == doctest::Approx(1.0).epsilon(1e-14));
      raw_min = std::min(raw_min, raw[i]);
      raw_max = std::max(raw_max, raw[i]);
    }
    // The raw Hann windows at 25 % overlap do not sum to a constant (hence the normalization),
    // but they never vanish.
    CHECK(raw_min > 0.15);
    if (extent >= 100) CHECK(raw_max - raw_min > 0.5);
  }
}

TEST_CASE("render: a uniform image stays uniform under the blur") {
  for (const std::string name : {"doublet", "tessar"}) {
    for (int res : {1, 2}) {
      RenderOptions o;
      o.res_factor = res;
      o.distortion = false;
      o.relative_illumination = false;
      const Renderer renderer(model_of(name), o);
      const FloatImage in(241, 163, 3, 0.6f);
      const FloatImage out = renderer.blur(in);
      double worst = 0;
      for (float v : out.pixels) worst = std::max(worst, std::abs(v - 0.6) / 0.6);
      INFO(name, " at ", res, "x: largest relative change ", worst);
      CHECK(worst < 1e-5);  // everywhere, borders included (reflection padding)
    }
  }
}

TEST_CASE("render: with distortion off the mean is the input's times the mean illumination") {
  auto check = [](const std::string& name, const FloatImage& in, int res) {
    RenderOptions o;
    o.res_factor = res;
    o.distortion = false;
    const Renderer renderer(model_of(name), o);
    const RenderResult r = renderer.render(in);
    FloatImage ri(in.width, in.height, 1, 1.0f);
    renderer.apply_relative_illumination(ri);
    const double mean_ri = mean_of(ri, 0);
    for (int c = 0; c < 3; ++c) {
      const double expected = mean_of(in, c) * mean_ri;
      MESSAGE(name, " ", res, "x ", in.width, "x", in.height, " channel ", c, ": output mean ",
              mean_of(r.image, c), " expected ", expected, " (mean RI ", mean_ri, ")");
      CHECK(std::abs(mean_of(r.image, c) / expected - 1) < 0.01);
    }
    CHECK(mean_ri < 1.0);
  };
  const FloatImage c = chart(320, 180);
  for (const std::string name : {"doublet", "cooke", "tessar"}) check(name, c, 1);
  check("tessar", c, 2);
  LENSOPT_REQUIRE_SHARED(shared);
  const FloatImage sample = read_image(shared / "data/images/sample_image.png").image;
  for (const std::string name : {"doublet", "cooke", "tessar"}) check(name, sample, 1);
}
