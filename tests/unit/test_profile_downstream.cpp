// Surface profiles downstream of the kernel (issue 16): the branch-free chunked asphere
// intersection against the safeguarded scalar Newton, tolerancing of conic and asphere terms,
// and the optimizer's profile slope and domain bounds.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/profile_bounds.h"
#include "lensopt/tolerance/tolerance.h"
#include "lensopt/trace/kernel.h"
#include "test_support.h"

namespace test_profile_downstream {

using namespace lensopt;

namespace {

Lens doublet_asphere() {
  return read_lens(test::source_dir() / "lenses" / "doublet-asphere.toml");
}

// Rays from the vertex plane of a strong even asphere (c = 1/20 mm, k = -0.8, a4 and a6 that
// bend the rim away from the conic), some steep and some beyond the conic's domain, so that the
// chunk's plain Newton steps converge for most, set some aside (domain, g' <= 0) and leave the
// rest to the scalar loop.
struct RaySet {
  std::vector<double> x1, y1, l, m, n;
};
RaySet random_rays(std::size_t count, double radius, double max_angle_rad, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  RaySet r;
  for (std::size_t i = 0; i < count; ++i) {
    const double theta = max_angle_rad * std::abs(u(rng));
    const double phi = 3.14159265358979 * u(rng);
    r.x1.push_back(radius * u(rng));
    r.y1.push_back(radius * u(rng));
    r.l.push_back(std::sin(theta) * std::cos(phi));
    r.m.push_back(std::sin(theta) * std::sin(phi));
    r.n.push_back(std::cos(theta));
  }
  return r;
}

// The lens in Jet type J, every number a constant.
template <typename J>
TraceLens<J> as_jets(const TraceLens<double>& lens) {
  return convert_trace_lens<J>(lens, std::vector<PrescriptionVariable>{}, 0, 0,
                               [](double value, int) { return J(value); });
}

}  // namespace

TEST_CASE("asphere intersection: the chunked branch-free Newton equals the scalar Newton") {
  const double c = 1.0 / 20.0, one_plus_k = 0.2;
  const double a[8] = {0.0, 2e-5, -3e-8, 1e-11, 0.0, 0.0, 0.0, 0.0};
  // Up to 21 mm from the axis (the conic's domain ends at 1 / (c sqrt(1 + k)) = 44.7 mm; the
  // asphere terms make the rim steep), rays up to 60 deg from the axis.
  const RaySet r = random_rays(1000, 21.0, 1.05, 7);
  int hits = 0, misses = 0, noise_floor = 0;
  for (std::size_t begin = 0; begin < r.x1.size(); begin += detail::kAsphereChunk) {
    const std::size_t size = std::min(detail::kAsphereChunk, r.x1.size() - begin);
    std::vector<double> s(size);
    std::vector<std::int32_t> failure(size);
    detail::asphere_intersect_double(c, one_plus_k, a, size, &r.x1[begin], &r.y1[begin],
                                     &r.l[begin], &r.m[begin], &r.n[begin], s.data(),
                                     failure.data());
    for (std::size_t i = 0; i < size; ++i) {
      const std::size_t j = begin + i;
      double s_scalar = 0.0;
      const bool hit = detail::asphere_newton(c, one_plus_k, a, r.x1[j], r.y1[j], r.l[j], r.m[j],
                                              r.n[j], s_scalar);
      const double xs = r.x1[j] + s[i] * r.l[j], ys = r.y1[j] + s[i] * r.m[j];
      double sag = 0, slope = 0;
      detail::asphere_sag(c, one_plus_k, a, xs * xs + ys * ys, sag, slope);
      if (hit != (failure[i] == kRayOk)) {
        // The |ds| <= 1e-15 (1 + |s| + r) test sits just below the Newton noise floor of a ray
        // with a small g' (steep incidence: |ds| = |g| / g' alternates around the bound); the
        // scalar loop then runs out of steps and flags a miss where the chunk, rounding
        // differently (another instruction set), meets the test. Only that direction is
        // allowed, only for a point on the surface to rounding, and rarely.
        CHECK(failure[i] == kRayOk);
        CHECK(std::abs(s[i] * r.n[j] - sag) <= 1e-14 * (1.0 + std::abs(sag)));
        ++noise_floor;
        continue;
      }
      if (!hit) {
        ++misses;
        continue;
      }
      ++hits;
      // Both converged to |ds| <= 1e-15 (1 + |s| + r): equal to a few ulps of the path.
      CHECK(std::abs(s[i] - s_scalar) <= 1e-13 * (1.0 + std::abs(s_scalar)));
      // And s is on the surface: g(s) = s n - S(rho) = 0 to rounding.
      CHECK(std::abs(s[i] * r.n[j] - sag) <= 1e-13 * (1.0 + std::abs(sag)));
    }
  }
  // The set exercises both outcomes.
  CHECK(hits > 500);
  CHECK(misses > 0);
  CHECK(noise_floor <= 5);
}

TEST_CASE("asphere intersection: double and Jet traces of the aspheric doublet agree") {
  // The double trace (target_clones loop) and the Jet trace (chunked template, Newton step in
  // the Jet) give the same ray positions on the image plane.
  const Lens lens = doublet_asphere();
  const TraceLens<double> tl = make_trace_lens(lens);
  using J = ceres::Jet<double, 2>;
  const TraceLens<J> tj = as_jets<J>(tl);
  const RaySet r = random_rays(300, 6.0, 0.3, 3);
  RayBundle<double> bd;
  RayBundle<J> bj;
  bd.resize(r.x1.size());
  bj.resize(r.x1.size());
  for (std::size_t i = 0; i < r.x1.size(); ++i) {
    bd.x[i] = r.x1[i];
    bd.y[i] = r.y1[i];
    bd.z[i] = -1.0;
    bd.l[i] = r.l[i];
    bd.m[i] = r.m[i];
    bd.n[i] = r.n[i];
    bj.x[i] = J(r.x1[i]);
    bj.y[i] = J(r.y1[i]);
    bj.z[i] = J(-1.0);
    bj.l[i] = J(r.l[i]);
    bj.m[i] = J(r.m[i]);
    bj.n[i] = J(r.n[i]);
  }
  const int k_count = tl.surface_count();
  trace_bundle<double>(tl, 0, k_count, true, bd, nullptr);
  trace_bundle<J>(tj, 0, k_count, true, bj, nullptr);
  int ok = 0;
  for (std::size_t i = 0; i < r.x1.size(); ++i) {
    CHECK(bd.status[i] == bj.status[i]);
    if (bd.status[i] != kRayOk) continue;
    ++ok;
    CHECK(std::abs(bd.x[i] - bj.x[i].a) <= 1e-11);
    CHECK(std::abs(bd.y[i] - bj.y[i].a) <= 1e-11);
  }
  CHECK(ok > 100);
}

TEST_CASE("tolerance: conic and asphere terms of the aspheric doublet") {
  const Lens lens = doublet_asphere();
  ToleranceOptions o;
  o.trials = 6;
  o.rings = 6;
  o.fields = 4;
  o.jobs = 1;
  o.sensitivity = true;
  const ToleranceModel model(lens, o);
  // k1, a4_1, a6_1, a8_1, k5, a4_5, a6_5, a8_5, after curvatures, thicknesses and glasses.
  std::vector<std::string> names;
  for (const ToleranceParameter& p : model.parameters())
    if (p.kind == ToleranceParameter::Kind::kConic || p.kind == ToleranceParameter::Kind::kAsphere)
      names.push_back(p.name);
  CHECK(names ==
        std::vector<std::string>{"k1", "a4_1", "a6_1", "a8_1", "k5", "a4_5", "a6_5", "a8_5"});
  // Each limit moves the rim sag of its surface by 1 um (the default asphere_sag_um): exactly
  // for an asphere term, to first order for the conic. The rim is the paraxial clear
  // semi-aperture, which the limit text names.
  const Lens& scaled = model.scaled_lens();
  const std::vector<double> nominal = std::vector<double>(model.parameters().size(), 0.0);
  const TrialResult base = model.evaluate(nominal);
  for (std::size_t i = 0; i < model.parameters().size(); ++i) {
    const ToleranceParameter& p = model.parameters()[i];
    if (p.kind != ToleranceParameter::Kind::kConic && p.kind != ToleranceParameter::Kind::kAsphere)
      continue;
    CAPTURE(p.name);
    REQUIRE(p.limit > 0.0);
    const std::size_t at = p.limit_text.find("at h ");
    REQUIRE(at != std::string::npos);
    const double h = std::stod(p.limit_text.substr(at + 5));
    const Surface& s = scaled.surfaces[p.surface];
    Surface moved = s;
    if (p.kind == ToleranceParameter::Kind::kConic)
      moved.conic += p.limit;
    else
      moved.asphere[p.term - 1] += p.limit;
    const double dsag_um = (moved.sag_mm(h) - s.sag_mm(h)) * 1000.0;
    // h is printed to 4 significant digits: the sag h^(2i) moves by up to 2i x 5e-5.
    CHECK(std::abs(std::abs(dsag_um) - 1.0) <
          (p.kind == ToleranceParameter::Kind::kConic ? 0.05 : 1e-3));
    // The perturbation changes the traced result.
    std::vector<double> d = nominal;
    d[i] = p.limit;
    const TrialResult t = model.evaluate(d);
    CHECK(t.valid);
    CHECK(t.mean_spot_um != base.mean_spot_um);
  }
  // The sensitivity table lists them, each with an effect.
  const ToleranceReport report = run_tolerance(lens, o);
  int profile_rows = 0;
  for (const SensitivityRow& row : report.sensitivity) {
    const ToleranceParameter& p = report.parameters[row.parameter];
    if (p.kind != ToleranceParameter::Kind::kConic && p.kind != ToleranceParameter::Kind::kAsphere)
      continue;
    ++profile_rows;
    CHECK(row.score_um > 0.0);
  }
  CHECK(profile_rows == 8);
  // Ten times the sag tolerance: the profile terms' effects grow about tenfold.
  ToleranceOptions wide = o;
  wide.tolerances.asphere_sag_um = 10.0;
  wide.trials = 1;
  const ToleranceReport wider = run_tolerance(lens, wide);
  double narrow_sum = 0, wide_sum = 0;
  for (const SensitivityRow& row : report.sensitivity)
    if (report.parameters[row.parameter].kind == ToleranceParameter::Kind::kAsphere)
      narrow_sum += row.score_um;
  for (const SensitivityRow& row : wider.sensitivity)
    if (wider.parameters[row.parameter].kind == ToleranceParameter::Kind::kAsphere)
      wide_sum += row.score_um;
  CHECK(wide_sum > 5.0 * narrow_sum);
  // Zero: the profile terms are listed with no limit and a spherical lens has none.
  ToleranceOptions off = o;
  off.tolerances.asphere_sag_um = 0.0;
  for (const ToleranceParameter& p : tolerance_parameters(lens, off.tolerances))
    if (p.kind == ToleranceParameter::Kind::kConic || p.kind == ToleranceParameter::Kind::kAsphere)
      CHECK(p.limit == 0.0);
  for (const ToleranceParameter& p : tolerance_parameters(
           read_lens(test::source_dir() / "lenses" / "doublet.toml"), o.tolerances))
    CHECK((p.kind != ToleranceParameter::Kind::kConic &&
           p.kind != ToleranceParameter::Kind::kAsphere));
}

TEST_CASE("tolerance: asphere_sag_um in the [tolerance] table") {
  const ToleranceSettings t =
      parse_tolerance_table("[tolerance]\nasphere_sag_um = 0.5\n", "x.toml");
  REQUIRE(t.asphere_sag_um);
  CHECK(*t.asphere_sag_um == 0.5);
  CHECK_THROWS_AS(parse_tolerance_table("[tolerance]\nasphere_sag_um = -1\n", "x.toml"), Error);
}

TEST_CASE("profile bounds: slope and domain residuals, their derivatives, the report") {
  const Lens lens = doublet_asphere();
  const TraceLens<double> tl = make_trace_lens(scaled(lens, 1.0));
  const std::vector<double> h = paraxial_clear_semi_apertures_mm(tl, lens.specs);
  REQUIRE(profile_bound_count(tl) == 2 * 2 * kProfileBoundRadii);
  // The shipped design keeps its surfaces below 60 deg: every residual 0.
  std::vector<double> r(profile_bound_count(tl));
  profile_bound_residuals(tl, h, 60.0, 100.0, r.data());
  for (double v : r) CHECK(v == 0.0);
  double slope_deg = 0, min_q2 = 0;
  profile_extremes(tl, h, slope_deg, min_q2);
  CHECK(slope_deg > 5.0);
  CHECK(slope_deg < 60.0);
  // A bound below the steepest slope is violated at the rim of the steepest surface.
  profile_bound_residuals(tl, h, slope_deg - 1.0, 1.0, r.data());
  double sum = 0;
  for (double v : r) sum += v;
  CHECK(sum > 0.0);
  // The residuals' derivative with respect to a6 of surface 1 against central differences.
  TraceLens<double> steep = tl;
  const std::size_t a6 = 0 * kAsphereTerms + 2;
  steep.asphere[a6] = 3e-5;  // a6 strong enough to tilt the rim past 60 deg
  std::vector<double> rs(r.size());
  profile_bound_residuals(steep, h, 60.0, 1.0, rs.data());
  double steep_sum = 0;
  for (double v : rs) steep_sum += v;
  REQUIRE(steep_sum > 0.0);
  using J = ceres::Jet<double, 1>;
  TraceLens<J> tj = as_jets<J>(steep);
  tj.asphere[a6].v[0] = 1.0;
  std::vector<J> rj(r.size());
  profile_bound_residuals(tj, h, 60.0, 1.0, rj.data());
  const double step = 1e-12;
  TraceLens<double> plus = steep, minus = steep;
  plus.asphere[a6] += step;
  minus.asphere[a6] -= step;
  std::vector<double> rp(r.size()), rm(r.size());
  profile_bound_residuals(plus, h, 60.0, 1.0, rp.data());
  profile_bound_residuals(minus, h, 60.0, 1.0, rm.data());
  int active = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    CHECK(rj[i].a == doctest::Approx(rs[i]).epsilon(1e-14));
    if (rs[i] == 0.0) continue;
    ++active;
    const double fd = (rp[i] - rm[i]) / (2.0 * step);
    CHECK(rj[i].v[0] == doctest::Approx(fd).epsilon(1e-6));
  }
  CHECK(active > 0);
}

TEST_CASE("profile bounds: check_constraints reports the steepest slope") {
  Lens lens = doublet_asphere();
  const ConstraintReport ok = check_constraints(lens, DesignLossOptions{}, TraceOptions{});
  bool found = false;
  for (const ConstraintReport::Row& row : ok.rows) {
    if (row.name != "steepest profile slope (deg)") continue;
    found = true;
    CHECK(row.pass);
    CHECK(row.bound == 60.0);
  }
  CHECK(found);
  // A bound below the design's slope fails.
  DesignLossOptions tight;
  tight.max_surface_slope_deg = 5.0;
  bool failed = false;
  for (const ConstraintReport::Row& row : check_constraints(lens, tight, TraceOptions{}).rows)
    if (row.name == "steepest profile slope (deg)") failed = !row.pass;
  CHECK(failed);
  // A spherical lens has no such row.
  for (const ConstraintReport::Row& row :
       check_constraints(read_lens(test::source_dir() / "lenses" / "doublet.toml"),
                         DesignLossOptions{}, TraceOptions{})
           .rows)
    CHECK(row.name != "steepest profile slope (deg)");
}

TEST_CASE("profile bounds: optimize pulls a too steep asphere back below the slope bound") {
  // The aspheric doublet with a slope bound just below its own steepest slope: the optimizer,
  // free to change a4..a8 of both aspheres, must end with the bound met.
  const Lens lens = doublet_asphere();
  double slope_deg = 0, min_q2 = 0;
  const TraceSystem<double> sys = prepare_lens_system(lens, TraceOptions{});
  profile_extremes(sys.lens, paraxial_clear_semi_apertures_mm(sys.lens, lens.specs), slope_deg,
                   min_q2);
  OptimizeOptions o;
  o.verbose = false;
  o.soft_start = false;
  o.max_rounds = 3;
  o.max_iterations = 10;
  o.sampling.rings = 4;
  o.sampling.fields = 3;
  o.loss.max_surface_slope_deg = slope_deg - 3.0;
  o.freeze = {"curvatures", "spacings", "glasses", "defocus"};
  o.vary = {"a4_1", "a6_1", "a8_1", "a4_5", "a6_5", "a8_5"};
  const ConstraintReport start = check_constraints(lens, o.loss, o.sampling);
  bool start_violates = false;
  for (const ConstraintReport::Row& row : start.rows)
    if (row.name == "steepest profile slope (deg)") start_violates = !row.pass;
  REQUIRE(start_violates);
  const OptimizeResult result = optimize_lens(lens, o);
  REQUIRE(!result.kept_start);
  bool met = false;
  for (const ConstraintReport::Row& row : check_constraints(result.lens, o.loss, o.sampling).rows)
    if (row.name == "steepest profile slope (deg)") {
      met = row.pass;
      CAPTURE(row.value);
    }
  CHECK(met);
}

}  // namespace test_profile_downstream
