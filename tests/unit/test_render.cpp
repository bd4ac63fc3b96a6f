// Image simulation: KDE PSFs (normalization, Jet derivatives), the overlap-add windows, the
// blur's conservation of light, consistency of a rendered point's blur with the traced spot,
// relative illumination and distortion, PSNR/SSIM, the baselines' ranking, and bad input.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <ceres/jet.h>
#include <doctest/doctest.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <map>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/render/chart.h"
#include "lensopt/render/dataset.h"
#include "lensopt/render/metrics.h"
#include "lensopt/render/psf.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace test_render {

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
  CHECK(sum ==
        doctest::Approx((g(1.5) + g(0.5)) / (2 * g(1.5) + 2 * g(0.5) + g(2.5))).epsilon(1e-12));
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
    CHECK(psf_j.centroid_y_mm.v[j] == doctest::Approx(fd(plus.centroid_y_mm, minus.centroid_y_mm,
                                                         plus2.centroid_y_mm, minus2.centroid_y_mm))
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

TEST_CASE("render: the image and its metrics do not depend on the thread count") {
  // The overlap-add runs in phases of non-overlapping patches and the metrics sum per row, so
  // 1, 2 and 3 threads give the same bits (a resumed run or a shard equals one run).
  const ImagingModel double_gauss =
      build_imaging_model(read_lens(test::source_dir() / "lenses/zmx/double_gauss_100.zmx"));
  for (const ImagingModel* model : {&model_of("doublet"), &double_gauss}) {
    const std::string name = model == &double_gauss ? "double_gauss_100.zmx" : "doublet";
    const Renderer renderer(*model, RenderOptions{});
    const FloatImage in = chart(333, 187);
    const RenderResult one = renderer.render(in, 1);
    for (int threads : {2, 3}) {
      const RenderResult many = renderer.render(in, threads);
      INFO(name, " with ", threads, " threads");
      CHECK(many.image.pixels == one.image.pixels);
      CHECK(many.psnr_db == one.psnr_db);
      CHECK(many.ssim == one.ssim);
    }
  }
}

TEST_CASE("render: reused buffers and the input's memory give the same bits (issue 33)") {
  // The blur's FFT buffers are pooled between renders and render(FloatImage&&) warps into the
  // input's memory: renders of other sizes in between, and either overload, change no bit. Grey,
  // RGB and RGBA (alpha copied, only warped).
  const Renderer renderer(model_of("doublet"), RenderOptions{});
  for (int channels : {1, 3, 4}) {
    FloatImage in = chart(333, 187);
    if (channels != 3) {
      FloatImage other(in.width, in.height, channels);
      for (int y = 0; y < in.height; ++y)
        for (int x = 0; x < in.width; ++x)
          for (int c = 0; c < channels; ++c)
            other.at(x, y, c) = c < 3 ? in.at(x, y, c) : 0.25f + 0.5f * (x % 2);
      in = other;
    }
    const RenderResult first = renderer.render(in, 2);
    (void)renderer.render(chart(241, 163), 2);  // another size between
    FloatImage copy = in;
    const RenderResult moved = renderer.render(std::move(copy), 2);
    const RenderResult again = renderer.render(in, 2);
    INFO(channels, " channels");
    CHECK(moved.image.pixels == first.image.pixels);
    CHECK(again.image.pixels == first.image.pixels);
    CHECK(moved.psnr_db == first.psnr_db);
    CHECK(moved.ssim == first.ssim);
    // The steps one by one give the same image.
    FloatImage steps = renderer.blur(in, 2);
    renderer.apply_relative_illumination(steps, 2);
    CHECK(renderer.apply_distortion(steps, 2).pixels == first.image.pixels);
  }
}

TEST_CASE("render: with distortion off the mean is the input's times the mean illumination") {
  // Returns the render (its PSNR and SSIM are of the blur alone).
  auto check = [](const std::string& name, const FloatImage& in, int res) {
    RenderOptions o;
    o.res_factor = res;
    o.distortion = false;
    const Renderer renderer(model_of(name), o);
    RenderResult r = renderer.render(in);
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
    return r;
  };
  const FloatImage c = chart(320, 180);
  for (const std::string name : {"doublet", "cooke", "tessar"}) check(name, c, 1);
  check("tessar", c, 2);

  // On the sample photo; the same renders rank the baselines: PSNR and SSIM of the Doublet <
  // Cooke < Tessar (BENCHMARKS.md reports them at 1x and 2x).
  LENSOPT_REQUIRE_SHARED(shared);
  const FloatImage sample = read_image(shared / "data/images/sample_image.png").image;
  std::vector<double> psnr, ssim_values;
  for (const std::string name : {"doublet", "cooke", "tessar"}) {
    const RenderResult r = check(name, sample, 1);
    MESSAGE(name, " at 1x on sample_image.png: PSNR ", r.psnr_db, " dB, SSIM ", r.ssim);
    psnr.push_back(r.psnr_db);
    ssim_values.push_back(r.ssim);
  }
  CHECK(psnr[0] < psnr[1]);
  CHECK(psnr[1] < psnr[2]);
  CHECK(ssim_values[0] < ssim_values[1]);
  CHECK(ssim_values[1] < ssim_values[2]);
}

TEST_CASE("render: a point's blur matches the traced RMS spot at the centre and at 0.7 field") {
  // 1x on a 1921 x 1081 image: pitch 7.26 um; the image centre is a pixel centre.
  const int width = 1921, height = 1081;
  for (const std::string name : {"tessar", "cooke"}) {
    const Lens lens = project_lens(name);
    const ImagingModel& model = model_of(name);
    RenderOptions o;
    o.distortion = false;
    o.relative_illumination = false;
    const Renderer renderer(model, o);
    const std::shared_ptr<const PsfGrid> grid = renderer.psf_grid(width, height);
    const SensorGeometry& geo = grid->geometry;
    const double p_um = geo.pitch_mm * 1000.0;
    const double sigma_um = model.psfs.options.sigma_um();
    struct Probe {
      int field, px, py, x, y;
    };
    std::vector<Probe> probes;
    probes.push_back({0, 4, 4, width / 2, height / 2});
    {  // 0.7 of the field (17.5 deg) at its reference height, towards patch (7, 7)'s centre
      const double cx = 0.5 * (grid->bounds_x[7] + grid->bounds_x[8]) - geo.axis_x;
      const double cy = 0.5 * (grid->bounds_y[7] + grid->bounds_y[8]) - geo.axis_y;
      const double r_px = model.reference_y_mm[14] / geo.pitch_mm / std::hypot(cx, cy);
      probes.push_back({14, 7, 7, static_cast<int>(std::floor(geo.axis_x + cx * r_px)),
                        static_cast<int>(std::floor(geo.axis_y + cy * r_px))});
    }
    FloatImage in(width, height, 3, 0.0f);
    for (const Probe& pr : probes)
      for (int c = 0; c < 3; ++c) in.at(pr.x, pr.y, c) = 1.0f;
    const FloatImage out = renderer.blur(in);
    const auto wx = overlap_windows(grid->bounds_x, width, 0);
    const auto wy = overlap_windows(grid->bounds_y, height, 0);
    std::vector<ChannelMoments> traced;
    for (int h = 0; h < 21; ++h) traced.push_back(traced_moments(lens, h));

    for (const Probe& pr : probes) {
      const int q = grid->patch_index(pr.px, pr.py);
      const int reach = grid->max_radius + 1;
      // Precondition: the blur lies inside the patch's flat window (no other patch's PSF).
      for (int d = -reach; d <= reach; ++d) {
        REQUIRE(wx[pr.px][pr.x + d] == 1.0);
        REQUIRE(wy[pr.py][pr.y + d] == 1.0);
      }
      const double radius_mm = geo.radius_mm(pr.x, pr.y);
      for (int c = 0; c < 3; ++c) {
        // Measured: centroid and variance (pixels^2, both axes) of the blurred point.
        double s = 0, sx = 0, sy = 0, sxx = 0;
        for (int j = pr.y - reach; j <= pr.y + reach; ++j)
          for (int i = pr.x - reach; i <= pr.x + reach; ++i) {
            const double v = out.at(i, j, c);
            s += v;
            sx += v * i;
            sy += v * j;
            sxx += v * (static_cast<double>(i) * i + static_cast<double>(j) * j);
          }
        CHECK(s == doctest::Approx(1.0).epsilon(1e-5));
        const double var_px = sxx / s - (sx / s) * (sx / s) - (sy / s) * (sy / s);
        const double rms_um = std::sqrt(var_px) * p_um;
        // Expected from the tracer: the patch PSF mixes fields with the grid's weights; each
        // field's rays about the grid centre, plus the KDE's s^2 per axis and the bilinear
        // resampling's p^2 / 6 per axis (its mean over bin positions).
        double second_um2 = 0, offset_um = 0;
        for (int h = 0; h < 21; ++h) {
          const double a = grid->field_weights[q][h];
          second_um2 += a * traced[h].second[c] * 1e6;
          offset_um += a * traced[h].offset[c] * 1e3;
        }
        const double expected_um = std::sqrt(second_um2 - offset_um * offset_um +
                                             2 * sigma_um * sigma_um + p_um * p_um / 3);
        // The traced RMS spot of the probe's own field and channel, against the measured blur
        // with the KDE and pixel terms taken out.
        const double field_rms_um = traced[pr.field].rms_mm[c] * 1e3;
        const double measured_spot_um =
            std::sqrt(rms_um * rms_um - 2 * sigma_um * sigma_um - p_um * p_um / 3);
        MESSAGE(name, " field ", pr.field, " (pixel at ", radius_mm, " mm) channel ", c,
                ": blur RMS ", rms_um, " um, expected ", expected_um,
                " um; without KDE and pixel terms ", measured_spot_um,
                " um vs the field's traced RMS ", field_rms_um, " um");
        CHECK(std::abs(rms_um / expected_um - 1) < 0.05);
        CHECK(std::abs(measured_spot_um / field_rms_um - 1) < 0.05);
      }
    }
  }
}

TEST_CASE("render: the distortion warp moves a point from y_ref,h to ybar_h") {
  const ImagingModel& model = model_of("doublet");  // -7.6 % at full field
  RenderOptions o;
  const Renderer renderer(model, o);
  const int width = 640, height = 360;
  const SensorGeometry geo = SensorGeometry::make(width, height, 1, model.sensor_diagonal_mm);
  for (int h : {8, 16}) {
    // A small Gaussian spot centred at field h's reference height along the diagonal.
    const double dir_x = width / std::hypot(width, height),
                 dir_y = height / std::hypot(width, height);
    const double r_px = model.reference_y_mm[h] / geo.pitch_mm;
    const double x0 = geo.axis_x + dir_x * r_px, y0 = geo.axis_y + dir_y * r_px;
    FloatImage in(width, height, 1, 0.0f);
    for (int j = 0; j < height; ++j)
      for (int i = 0; i < width; ++i) {
        const double d2 = (i + 0.5 - x0) * (i + 0.5 - x0) + (j + 0.5 - y0) * (j + 0.5 - y0);
        in.at(i, j, 0) = static_cast<float>(std::exp(-d2 / (2 * 1.5 * 1.5)));
      }
    const FloatImage out = renderer.apply_distortion(in);
    double s = 0, sx = 0, sy = 0;
    for (int j = 0; j < height; ++j)
      for (int i = 0; i < width; ++i) {
        s += out.at(i, j, 0);
        sx += out.at(i, j, 0) * (i + 0.5);
        sy += out.at(i, j, 0) * (j + 0.5);
      }
    const double r_out_mm = std::hypot(sx / s - geo.axis_x, sy / s - geo.axis_y) * geo.pitch_mm;
    INFO("field ", h, ": imaged at ", r_out_mm, " mm, centroid ", model.centroid_y_mm[h], " mm");
    CHECK(std::abs(r_out_mm - model.centroid_y_mm[h]) < 0.05 * geo.pitch_mm);
    CHECK(model.centroid_y_mm[h] < model.reference_y_mm[h]);  // barrel
  }
  // The inverse map is the inverse.
  for (double r : {0.5, 3.0, 7.9}) {
    const double rd = r + distortion_at(model, r) * model.reference_y_mm.back();
    CHECK(undistorted_radius_mm(model, rd) == doctest::Approx(r).epsilon(1e-12));
  }
}

TEST_CASE("render: the bicubic warp gives OpenImageIO's catmull-rom st_warp values") {
  const ImagingModel& model = model_of("doublet");
  const Renderer renderer(model, RenderOptions{});
  const int width = 200, height = 120;
  FloatImage in(width, height, 3);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i)
      for (int c = 0; c < 3; ++c)
        in.at(i, j, c) = static_cast<float>(0.5 + 0.4 * std::sin(0.21 * i + 0.13 * j + c) *
                                                      std::cos(0.07 * i - 0.17 * j));
  const FloatImage mine = renderer.apply_distortion(in);
  // The same inverse map as an ST map for OpenImageIO.
  const SensorGeometry geo = SensorGeometry::make(width, height, 1, model.sensor_diagonal_mm);
  OIIO::ImageBuf src(OIIO::ImageSpec(width, height, 3, OIIO::TypeDesc::FLOAT), in.pixels.data());
  std::vector<float> st(static_cast<std::size_t>(width) * height * 2);
  std::vector<char> inside(static_cast<std::size_t>(width) * height);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      const double dx = i + 0.5 - geo.axis_x, dy = j + 0.5 - geo.axis_y;
      const double r = geo.pitch_mm * std::hypot(dx, dy);
      const double k = undistorted_radius_mm(model, r) / r;
      const double sx = geo.axis_x + dx * k, sy = geo.axis_y + dy * k;
      st[(static_cast<std::size_t>(j) * width + i) * 2] = static_cast<float>(sx / width);
      st[(static_cast<std::size_t>(j) * width + i) * 2 + 1] = static_cast<float>(sy / height);
      inside[static_cast<std::size_t>(j) * width + i] =
          sx > 3 && sx < width - 3 && sy > 3 && sy < height - 3;
    }
  OIIO::ImageBuf stbuf(OIIO::ImageSpec(width, height, 2, OIIO::TypeDesc::FLOAT), st.data());
  OIIO::ImageBuf theirs;
  REQUIRE(OIIO::ImageBufAlgo::st_warp(theirs, src, stbuf, "catmull-rom", 4.0f));
  std::vector<float> ref(static_cast<std::size_t>(width) * height * 3);
  theirs.get_pixels(OIIO::ROI(0, width, 0, height, 0, 1, 0, 3), OIIO::TypeDesc::FLOAT, ref.data());
  double worst = 0;
  int compared = 0;
  for (std::size_t p = 0; p < inside.size(); ++p) {
    if (!inside[p]) continue;
    ++compared;
    for (int c = 0; c < 3; ++c)
      worst =
          std::max(worst, static_cast<double>(std::abs(mine.pixels[p * 3 + c] - ref[p * 3 + c])));
  }
  INFO("largest difference ", worst, " over ", compared, " pixels");
  CHECK(compared > width * height / 2);
  CHECK(worst < 1e-4);
}

TEST_CASE("metrics: PSNR and SSIM against known values") {
  const FloatImage x = chart(64, 48);
  CHECK(std::isinf(psnr_db(x, x, 3)));
  CHECK(ssim(x, x, 3) == doctest::Approx(1.0).epsilon(1e-12));
  // A constant offset of 0.1: MSE 0.01, PSNR 20 dB.
  FloatImage y = x;
  for (float& v : y.pixels) v += 0.1f;
  CHECK(psnr_db(x, y, 3) == doctest::Approx(20.0).epsilon(1e-5));
  // OpenImageIO's PSNR of the same pair (it takes the largest pixel value as the peak: the
  // chart's white patch is 1 and the noisy copy is clamped to [0, 1]).
  FloatImage noisy = x;
  unsigned seed = 12345;
  for (float& v : noisy.pixels) {
    seed = seed * 1664525u + 1013904223u;
    v = std::clamp(v + 0.05f * ((seed >> 8) / 16777216.0f - 0.5f), 0.0f, 1.0f);
  }
  FloatImage grey_x(64, 48, 1), grey_noisy(64, 48, 1);
  for (std::size_t p = 0; p < grey_x.pixels.size(); ++p) {
    grey_x.pixels[p] = x.pixels[3 * p];
    grey_noisy.pixels[p] = noisy.pixels[3 * p];
  }
  OIIO::ImageBuf a(OIIO::ImageSpec(64, 48, 1, OIIO::TypeDesc::FLOAT), grey_x.pixels.data());
  OIIO::ImageBuf b(OIIO::ImageSpec(64, 48, 1, OIIO::TypeDesc::FLOAT), grey_noisy.pixels.data());
  const auto cmp = OIIO::ImageBufAlgo::compare(a, b, 1.0f, 1.0f);
  CHECK(psnr_db(grey_x, grey_noisy, 1) == doctest::Approx(cmp.PSNR).epsilon(1e-6));
  // Symmetric, below 1 for a different image.
  const double s = ssim(x, noisy, 3);
  CHECK(s < 1.0);
  CHECK(s > 0.5);
  CHECK(ssim(noisy, x, 3) == doctest::Approx(s).epsilon(1e-12));
  // Two constant images a and b: the variance terms are 0, so SSIM = (2ab + C1)/(a^2 + b^2 + C1).
  const FloatImage ca(40, 30, 1, 0.3f), cb(40, 30, 1, 0.5f);
  const double c1 = 1e-4;
  const double a3 = 0.3f, b5 = 0.5f;  // the float values
  CHECK(ssim(ca, cb, 1) ==
        doctest::Approx((2 * a3 * b5 + c1) / (a3 * a3 + b5 * b5 + c1)).epsilon(1e-12));
  // A contrast-inverted image is strongly dissimilar.
  FloatImage inv = x;
  for (float& v : inv.pixels) v = 1.0f - v;
  CHECK(ssim(x, inv, 3) < 0.0);
  // Sizes must match.
  CHECK_THROWS_AS(psnr_db(x, ca, 1), Error);
}

TEST_CASE("render: bad inputs are reported, skipped, and leave nothing half-written") {
  TempDir tmp;
  const fs::path in = tmp.path / "in", out = tmp.path / "out";
  fs::create_directories(in / "sub");
  write_image(in / "good.png", chart(96, 64));
  write_image(in / "sub" / "good16.tif", chart(80, 60), image_file_spec(ImagePixelType::kUint16));
  write_image(in / "tiny.png", FloatImage(8, 8, 3, 0.5f));
  write_image(in / "strip.png", FloatImage(2000, 20, 3, 0.5f));
  { std::ofstream(in / "empty.png"); }
  { std::ofstream(in / "corrupt.jpg") << "this is not a JPEG file at all"; }
  {  // a PNG cut in the middle of its data
    const std::string bytes = read_file(in / "good.png");
    std::ofstream(in / "truncated.png", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  { std::ofstream(tmp.path / "notes.bmp") << "BM"; }
  RenderOptions ro;
  ro.threads = 1;
  const Renderer renderer(model_of("doublet"), ro);  // its PSF is wider than a 32 px image
  DatasetOptions d;
  d.inputs = {in, tmp.path / "notes.bmp", tmp.path / "missing.png"};
  d.output_dir = out;
  d.jobs = 2;
  const DatasetSummary s = render_dataset(renderer, d);
  std::map<std::string, const ImageRecord*> by_name;
  for (const ImageRecord& r : s.records) by_name[r.input.filename().string()] = &r;
  CHECK(s.rendered == 2);
  CHECK(s.failed == 7);
  auto error_of = [&](const std::string& n) {
    REQUIRE(by_name.count(n) == 1);
    CHECK(by_name[n]->status == ImageRecord::Status::kFailed);
    return by_name[n]->error;
  };
  CHECK(error_of("empty.png").find("empty") != std::string::npos);
  CHECK(error_of("corrupt.jpg").find("corrupt") != std::string::npos);
  CHECK(error_of("truncated.png").find("corrupt") != std::string::npos);
  CHECK(error_of("notes.bmp").find("unsupported image format") != std::string::npos);
  CHECK(error_of("missing.png").find("no such file") != std::string::npos);
  CHECK(error_of("tiny.png").find("too small") != std::string::npos);
  // 2000 x 20: the pitch is 8 um, the Doublet's PSF (260 um grid) about 33 pixels wide.
  CHECK(error_of("strip.png").find("smaller than the lens's PSF") != std::string::npos);
  // Only complete outputs and the metrics; no temporary file left behind.
  CHECK(list_files(out) == std::vector<std::string>{"good.png", "render_metrics.csv",
                                                    "render_metrics.json", "sub/good16.tif"});
  // Format and bit depth kept.
  auto spec_of = [](const fs::path& p) { return OIIO::ImageInput::open(p.string())->spec(); };
  CHECK(spec_of(out / "sub/good16.tif").format == OIIO::TypeDesc::UINT16);
  CHECK(spec_of(out / "good.png").format == OIIO::TypeDesc::UINT8);
  const std::string csv = read_file(out / "render_metrics.csv");
  CHECK(csv.find("truncated.png") != std::string::npos);
  CHECK(csv.find("\nmean,") != std::string::npos);

  // Resume: existing outputs are skipped and keep their metrics.
  const DatasetSummary again = render_dataset(renderer, d);
  CHECK(again.rendered == 0);
  CHECK(again.skipped == 2);
  REQUIRE(again.mean_psnr_db.has_value());
  CHECK(*again.mean_psnr_db == doctest::Approx(*s.mean_psnr_db).epsilon(1e-4));

  // Output directories that cannot be written.
  DatasetOptions bad = d;
  bad.output_dir = in / "good.png";  // a file
  CHECK_THROWS_WITH_AS(render_dataset(renderer, bad), doctest::Contains("not a directory"), Error);
  bad.output_dir = in / "good.png" / "sub";  // under a file
  CHECK_THROWS_WITH_AS(render_dataset(renderer, bad), doctest::Contains("cannot create"), Error);
  // An image too small for the PSF, directly.
  CHECK_THROWS_WITH_AS(renderer.render(FloatImage(2000, 20, 3, 0.5f)),
                       doctest::Contains("smaller than"), Error);
}

}  // namespace test_render
