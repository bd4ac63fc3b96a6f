// Surface profiles (trace/profile.h): exact geometry of conics (Cartesian ovals focus perfectly,
// a paraboloid and an ellipsoid by their reflective properties), the even-asphere sag against its
// closed form, the one sag formula (lens/profile_sag.h) against a sphere, a paraboloid and an
// a4 term, the paraxial power of the r^2 term, Jet derivatives with respect to k and every
// asphere coefficient against central finite differences, and the spherical path kept.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "lensopt/analysis/gradient.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/random.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/profile_sag.h"
#include "lensopt/trace/kernel.h"
#include "test_support.h"

namespace test_surface_profiles {

using namespace lensopt;

namespace {

// A TraceLens of two surfaces: a conic from air into a medium of index `index` (at 587.6 nm),
// then a flat surface at distance t back into air.
TraceLens<double> cartesian_lens(double c, double k, double index, double t) {
  TraceLens<double> lens;
  lens.wavelengths_nm = {kWavelengthD_nm};
  lens.curvature_per_mm = {c, 0.0};
  lens.thickness_mm = {t, 10.0};
  lens.is_glass = {1, 0};
  lens.nd = {index, 1.0};
  lens.vd = {1e9, 0.0};  // no dispersion: n = nd at every wavelength
  lens.ensure_profiles();
  lens.conic[0] = k;
  lens.profile[0] = kProfileConic;
  return lens;
}

// An on-axis collimated bundle over radius `radius`, rays in a square grid within the circle.
RayBundle<double> collimated(double radius, int grid) {
  RayBundle<double> rays;
  std::vector<std::pair<double, double>> points;
  for (int i = 0; i < grid; ++i)
    for (int j = 0; j < grid; ++j) {
      const double x = radius * (2.0 * i / (grid - 1) - 1.0);
      const double y = radius * (2.0 * j / (grid - 1) - 1.0);
      if (x * x + y * y <= radius * radius) points.emplace_back(x, y);
    }
  rays.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    rays.x[i] = points[i].first;
    rays.y[i] = points[i].second;
    rays.z[i] = -5.0;
    rays.l[i] = 0.0;
    rays.m[i] = 0.0;
    rays.n[i] = 1.0;
  }
  return rays;
}

// Reflects rays at a conic mirror (the profile layer's intersection and normal) and returns the
// RMS distance (mm) of the reflected rays from the point (0, 0, z_focus) at their closest approach.
double mirror_rms(double c, double k, const std::vector<std::array<double, 6>>& rays,
                  double z_focus) {
  double sum = 0;
  for (const auto& r : rays) {
    const double s0 = -r[2] / r[5];
    const double x1 = r[0] + s0 * r[3], y1 = r[1] + s0 * r[4];
    bool miss = false;
    const double s = detail::conic_intersection(c, 1.0 + k, x1, y1, r[3], r[4], r[5], miss);
    REQUIRE(!miss);
    const double x = x1 + s * r[3], y = y1 + s * r[4], z = s * r[5];
    // The conic's unit normal (-c x, -c y, 1 - c (1 + k) z) / |.| (trace/profile.h).
    const double w = 1.0 - c * (1.0 + k) * z;
    const double inv = 1.0 / std::sqrt(c * c * (x * x + y * y) + w * w);
    const double nx = -c * x * inv, ny = -c * y * inv, nz = w * inv;
    const double dn = r[3] * nx + r[4] * ny + r[5] * nz;
    const double dx = r[3] - 2 * dn * nx, dy = r[4] - 2 * dn * ny, dz = r[5] - 2 * dn * nz;
    // Distance from the focus to the reflected line.
    const double px = -x, py = -y, pz = z_focus - z;
    const double cx = py * dz - pz * dy, cy = pz * dx - px * dz, cz = px * dy - py * dx;
    sum += (cx * cx + cy * cy + cz * cz) / (dx * dx + dy * dy + dz * dz);
  }
  return std::sqrt(sum / rays.size());
}

double mean_spot(const Lens& lens, const TraceOptions& options) {
  const TraceSystem<double> sys = prepare_system(make_trace_lens(lens), lens.specs, options);
  return evaluate_spots(sys, options.threads).mean_rms_spot_mm;
}

// The Doublet with even aspheres on its first and last surfaces (and a conic on the first).
Lens aspheric_doublet() {
  Lens lens = read_lens(test::source_dir() / "lenses/doublet.toml");
  Surface& front = lens.surfaces.front();
  front.conic = -0.4;
  front.asphere_r2_per_mm = 2e-4;
  front.asphere = {-3e-5, 2e-7, -1e-9, 3e-12, 0, 0, 0};
  Surface& back = lens.surfaces[lens.surfaces.size() - 2];
  back.asphere = {4e-5, -1e-6, 3e-8, 0, 0, 0, 1e-14};
  return lens;
}

}  // namespace

TEST_CASE("a Cartesian ellipsoid focuses a collimated bundle to a point in the glass") {
  // Air into glass n: k = -1/n^2 images infinity to the far focus at n R / (n - 1).
  const double n = 1.7, r = 20.0;
  const double focus = n * r / (n - 1.0);
  const TraceLens<double> lens = cartesian_lens(1.0 / r, -1.0 / (n * n), n, focus);
  RayBundle<double> rays = collimated(8.0, 41);
  trace_bundle(lens, 0, 2, false, rays, static_cast<RayRecord<double>*>(nullptr));
  double sum = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    REQUIRE(rays.status[i] == kRayOk);
    sum += rays.x[i] * rays.x[i] + rays.y[i] * rays.y[i];
  }
  CHECK(std::sqrt(sum / rays.size()) < 1e-9);
  // The same radius as a sphere does not (spherical aberration of a few um and more).
  TraceLens<double> sphere = lens;
  sphere.profile.clear();
  sphere.conic.clear();
  sphere.asphere.clear();
  RayBundle<double> rays_s = collimated(8.0, 41);
  trace_bundle(sphere, 0, 2, false, rays_s, static_cast<RayRecord<double>*>(nullptr));
  double sum_s = 0;
  for (std::size_t i = 0; i < rays_s.size(); ++i) sum_s += rays_s.y[i] * rays_s.y[i];
  CHECK(std::sqrt(sum_s / rays_s.size()) > 1e-3);
}

TEST_CASE("a Cartesian hyperboloid focuses a collimated bundle from glass into air") {
  // Glass n into air: k = -n^2; a parallel bundle inside the glass focuses at R / (n - 1)... in
  // air behind a concave-towards-the-image hyperboloid of curvature c < 0. Trace it as glass ->
  // air by putting the glass before a flat entrance surface.
  const double n = 1.5, r = -15.0;
  const double focus = -r / (n - 1.0) * 1.0;  // paraxial: n/s' = (1 - n) c => s' = R/(1-n)
  TraceLens<double> lens;
  lens.wavelengths_nm = {kWavelengthD_nm};
  lens.curvature_per_mm = {0.0, 1.0 / r, 0.0};
  lens.thickness_mm = {5.0, focus, 10.0};
  lens.is_glass = {1, 0, 0};
  lens.nd = {n, 1.0, 1.0};
  lens.vd = {1e9, 0.0, 0.0};
  lens.ensure_profiles();
  lens.conic[1] = -n * n;
  lens.profile[1] = kProfileConic;
  RayBundle<double> rays = collimated(6.0, 31);
  trace_bundle(lens, 0, 3, false, rays, static_cast<RayRecord<double>*>(nullptr));
  double sum = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    REQUIRE(rays.status[i] == kRayOk);
    sum += rays.x[i] * rays.x[i] + rays.y[i] * rays.y[i];
  }
  CHECK(std::sqrt(sum / rays.size()) < 1e-9);
}

TEST_CASE("a paraboloid mirror focuses an on-axis bundle to its focus") {
  // k = -1: reflected rays meet at z = 1 / (2 c) (the profile layer's intersection and normal).
  const double c = 1.0 / 40.0;
  std::vector<std::array<double, 6>> rays;
  for (int i = 0; i < 25; ++i)
    for (int j = 0; j < 25; ++j) {
      const double x = -12.0 + i, y = -12.0 + j;
      if (x * x + y * y <= 144.0) rays.push_back({x, y, -3.0, 0.0, 0.0, 1.0});
    }
  CHECK(mirror_rms(c, -1.0, rays, 1.0 / (2.0 * c)) < 1e-9);
  CHECK(mirror_rms(c, 0.0, rays, 1.0 / (2.0 * c)) > 1e-3);  // a sphere does not
}

TEST_CASE("an ellipsoidal mirror images one focus onto the other") {
  // Prolate ellipsoid with vertex at the origin: semi-axes a (along z) and b; c = a / b^2,
  // k = -e^2 = b^2 / a^2 - 1; foci at z = a -+ sqrt(a^2 - b^2).
  const double a = 30.0, b = 18.0;
  const double e = std::sqrt(a * a - b * b);
  const double c = a / (b * b), k = b * b / (a * a) - 1.0;
  const double near = a - e, far = a + e;
  // Rays from the far focus towards the vertex region, reflected to the near focus... and from
  // the near focus: start them behind the vertex plane on lines through the focus.
  std::vector<std::array<double, 6>> rays;
  for (int i = -6; i <= 6; ++i)
    for (int j = -6; j <= 6; ++j) {
      // The line through the far focus F and (x, y, 0), started at z = -3 and travelling
      // towards F (+z): it meets the mirror on that line.
      const double x = i * 2.0, y = j * 2.0;
      const double u = 3.0 / far;
      double dx = -x, dy = -y, dz = far;
      const double len = std::sqrt(dx * dx + dy * dy + dz * dz);
      rays.push_back({x * (1 + u), y * (1 + u), -3.0, dx / len, dy / len, dz / len});
    }
  // The lines pass through the far focus; after reflection they pass through the near focus.
  CHECK(mirror_rms(c, k, rays, near) < 1e-9);
}

TEST_CASE("even-asphere sag equals its closed form") {
  Surface s;
  s.curvature_per_mm = 0.0;
  s.asphere_r2_per_mm = 0.0;
  s.asphere = {1.1e-3, -2.3e-5, 3.7e-7, -4.1e-9, 5.3e-11, -6.7e-13, 7.9e-15};
  const double a[8] = {0.0, 1.1e-3, -2.3e-5, 3.7e-7, -4.1e-9, 5.3e-11, -6.7e-13, 7.9e-15};
  for (double r : {0.3, 1.0, 2.5, 4.0, 7.0}) {
    long double closed = 0;
    for (int i = 2; i <= 8; ++i)
      closed += static_cast<long double>(a[i - 1]) * std::pow((long double)r, 2 * i);
    const double expected = static_cast<double>(closed);
    CHECK(std::abs(s.sag_mm(r) - expected) <= 1e-14 * std::abs(expected));
    const double profile = profile_sag<double>(0.0, 0.0, a, r);
    CHECK(std::abs(profile - expected) <= 1e-14 * std::abs(expected));
  }
  // A conic with a2: c r^2 / (1 + sqrt(1 - (1+k) c^2 r^2)) + a2 r^2.
  Surface t;
  t.curvature_per_mm = 0.05;
  t.conic = -2.5;
  t.asphere_r2_per_mm = 1e-3;
  const double r = 6.0;
  const double expected = 0.05 * 36 / (1 + std::sqrt(1 + 1.5 * 0.0025 * 36)) + 1e-3 * 36;
  CHECK(t.sag_mm(r) == doctest::Approx(expected).epsilon(1e-15));
}

TEST_CASE("the one sag formula (lens/profile_sag.h) against closed forms, and its callers") {
  const double zeros[8] = {};
  // Sphere of radius R: z = R - sqrt(R^2 - r^2), dz/dr = r / sqrt(R^2 - r^2), so S' = dz/dr /
  // (2 r) = 1 / (2 sqrt(R^2 - r^2)); the closed form in long double (no cancellation left).
  for (double radius : {25.0, -40.0}) {
    const double c = 1.0 / radius;
    for (double r : {1.0, 5.0, 12.0, 20.0, 24.9}) {
      if (r >= std::abs(radius)) continue;
      const double rho = r * r;
      const long double big = std::abs(radius);
      const long double root = std::sqrt(big * big - (long double)rho);
      const double sign = radius > 0 ? 1.0 : -1.0;
      const double expected = sign * static_cast<double>(big - root);
      const double expected_slope = sign * static_cast<double>(0.5L / root);
      const double q = std::sqrt(profile_q2(c, 1.0, rho));
      CHECK(std::abs(profile_sag_at_q(c, zeros, rho, q) - expected) <= 1e-14 * std::abs(expected));
      CHECK(std::abs(profile_slope_at_q(c, zeros, rho, q) - expected_slope) <=
            1e-14 * std::abs(expected_slope));
    }
  }
  // Paraboloid (k = -1): q = 1, z = r^2 / (2 R), S' = 1 / (2 R), at every height.
  const double radius = 30.0;
  for (double r : {0.5, 10.0, 45.0, 200.0}) {
    const double rho = r * r;
    const double q = std::sqrt(profile_q2(1.0 / radius, 0.0, rho));
    CHECK(q == 1.0);
    CHECK(profile_sag_at_q(1.0 / radius, zeros, rho, q) ==
          doctest::Approx(rho / (2.0 * radius)).epsilon(1e-15));
    CHECK(profile_slope_at_q(1.0 / radius, zeros, rho, q) ==
          doctest::Approx(1.0 / (2.0 * radius)).epsilon(1e-15));
  }
  // A flat plate with only a4: z = a4 r^4, S' = 2 a4 r^2.
  const double a4[8] = {0.0, 2.5e-5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  for (double r : {0.5, 3.0, 8.0}) {
    const double rho = r * r;
    const double q = std::sqrt(profile_q2(0.0, 1.0, rho));
    CHECK(profile_sag_at_q(0.0, a4, rho, q) == doctest::Approx(2.5e-5 * std::pow(r, 4)));
    CHECK(profile_slope_at_q(0.0, a4, rho, q) == doctest::Approx(5e-5 * rho));
  }
  // Every caller is that formula: Surface::sag_mm and profile_sag (the tracer's) give the same bits
  // inside the domain; outside it (|c| r > 1 on a sphere) sag_mm is NaN by contract, and a
  // caller that clamps q at 0 (the tolerance edge gap, the plot) gets the rim's c r^2.
  Surface s;
  s.curvature_per_mm = 1.0 / 18.0;
  s.conic = -0.6;
  s.asphere_r2_per_mm = 2e-4;
  s.asphere = {1.1e-5, -2.3e-8, 3.7e-10, -4.1e-12, 5.3e-14, -6.7e-16, 7.9e-18};
  const double a[8] = {2e-4, 1.1e-5, -2.3e-8, 3.7e-10, -4.1e-12, 5.3e-14, -6.7e-16, 7.9e-18};
  for (double r : {0.0, 1.0, 4.0, 9.0, 15.0}) {
    CHECK(s.sag_mm(r) == profile_sag<double>(s.curvature_per_mm, s.conic, a, r));
  }
  Surface sphere;
  sphere.curvature_per_mm = 0.1;
  CHECK(std::isnan(sphere.sag_mm(10.5)));
  const double rho = 10.5 * 10.5;
  const double clamped = std::sqrt(std::max(profile_q2(0.1, 1.0, rho), 0.0));
  CHECK(profile_sag_at_q(0.1, zeros, rho, clamped) == doctest::Approx(0.1 * rho));
}

TEST_CASE("paraxial power: the r^2 term counts as a curvature 2 a2, conic and a4+ do not") {
  const Lens base = read_lens(test::source_dir() / "lenses/doublet.toml");
  const double efl = paraxial_data(make_trace_lens(base), kWavelengthD_nm).efl_mm;
  Lens conic = base;
  conic.surfaces[0].conic = -0.8;
  conic.surfaces[0].asphere[0] = 1e-4;
  conic.surfaces[0].asphere[3] = 1e-10;
  CHECK(paraxial_data(make_trace_lens(conic), kWavelengthD_nm).efl_mm ==
        doctest::Approx(efl).epsilon(1e-15));
  Lens r2 = base;
  r2.surfaces[0].asphere_r2_per_mm = 0.004;
  Lens sphere = base;
  sphere.surfaces[0].curvature_per_mm += 0.008;
  const double efl_r2 = paraxial_data(make_trace_lens(r2), kWavelengthD_nm).efl_mm;
  CHECK(efl_r2 != doctest::Approx(efl));
  CHECK(efl_r2 == doctest::Approx(paraxial_data(make_trace_lens(sphere), kWavelengthD_nm).efl_mm)
                      .epsilon(1e-14));
  // And the real rays agree near the axis: the on-axis spot of a small bundle.
  TraceOptions options;
  options.rings = 4;
  options.fields = 3;
  CHECK(mean_spot(r2, options) != doctest::Approx(mean_spot(base, options)));
}

TEST_CASE("a spherical lens traces the sphere path; forced profiles at zero agree with it") {
  const Lens lens = read_lens(test::source_dir() / "lenses/doublet.toml");
  const TraceLens<double> plain = make_trace_lens(lens);
  CHECK(!plain.has_profiles());
  TraceOptions options;
  options.rings = 8;
  options.fields = 5;
  const double spot = evaluate_spots(prepare_system(plain, lens.specs, options)).mean_rms_spot_mm;
  // Through Lens: k = 0 and no terms is the sphere, bit for bit.
  Lens zero = lens;
  for (Surface& s : zero.surfaces) s.conic = -0.0;
  CHECK(mean_spot(zero, options) == spot);
  for (std::uint8_t kind : {kProfileConic, kProfileAsphere}) {
    TraceLens<double> forced = plain;
    forced.ensure_profiles();
    for (auto& p : forced.profile) p = kind;
    const double forced_spot =
        evaluate_spots(prepare_system(forced, lens.specs, options)).mean_rms_spot_mm;
    INFO("profile kind ", int(kind));
    CHECK(forced_spot == doctest::Approx(spot).epsilon(1e-12));
  }
}

TEST_CASE("an aspheric lens: conic and asphere agree with an equivalent sphere-free check") {
  // An asphere whose terms are all zero but the conic equals the conic path.
  const Lens lens = aspheric_doublet();
  Lens conic_only = lens;
  for (Surface& s : conic_only.surfaces) {
    s.asphere_r2_per_mm = 0;
    s.asphere = {};
  }
  TraceLens<double> forced = make_trace_lens(conic_only);
  TraceOptions options;
  options.rings = 8;
  options.fields = 5;
  const double conic_spot =
      evaluate_spots(prepare_system(forced, lens.specs, options)).mean_rms_spot_mm;
  for (auto& p : forced.profile)
    if (p == kProfileConic) p = kProfileAsphere;
  CHECK(evaluate_spots(prepare_system(forced, lens.specs, options)).mean_rms_spot_mm ==
        doctest::Approx(conic_spot).epsilon(1e-12));
  // The aspheric lens traces (its strong made-up terms vignette some edge rays: flagged).
  const TraceSystem<double> sys = prepare_system(make_trace_lens(lens), lens.specs, options);
  const SpotResult<double> spots = evaluate_spots(sys);
  CHECK(std::isfinite(spots.mean_rms_spot_mm));
  CHECK(spots.mean_rms_spot_mm > 0.0);
}

TEST_CASE("Jet derivatives of the mean spot with respect to k and asphere terms") {
  const Lens lens = aspheric_doublet();
  TraceOptions options;
  options.rings = 6;
  options.fields = 4;
  std::vector<PrescriptionVariable> variables;
  for (const PrescriptionVariable& v : all_prescription_variables(lens))
    if (v.kind == PrescriptionVariable::Kind::kConic ||
        v.kind == PrescriptionVariable::Kind::kAsphere)
      variables.push_back(v);
  // The spherical second surface's conic and a4 as well (seeded at the value 0).
  variables.push_back({PrescriptionVariable::Kind::kConic, 1});
  variables.push_back({PrescriptionVariable::Kind::kAsphere, 1, 1});
  REQUIRE(variables.size() == 13);
  const SpotGradient g =
      mean_spot_gradient<16>(make_trace_lens(lens), lens.specs, variables, options);
  CHECK(g.mean_rms_spot_mm == doctest::Approx(mean_spot(lens, options)).epsilon(1e-12));
  double largest_scaled = 0;
  std::vector<double> scale(variables.size());
  const double radius_mm = 5.0;  // about the rays' largest height
  for (std::size_t i = 0; i < variables.size(); ++i) {
    const PrescriptionVariable& v = variables[i];
    // A step that moves the sag at the aperture edge by about 1e-6 mm.
    scale[i] = v.kind == PrescriptionVariable::Kind::kConic
                   ? 1e-3
                   : 1e-6 / std::pow(radius_mm, 2 * v.term + 2);
    largest_scaled = std::max(largest_scaled, std::abs(g.gradient[i]) * scale[i]);
  }
  for (std::size_t i = 0; i < variables.size(); ++i) {
    const PrescriptionVariable& v = variables[i];
    const double x0 = variable_value(lens, v);
    auto central = [&](double h) {
      Lens plus = lens, minus = lens;
      set_variable_value(plus, v, x0 + h);
      set_variable_value(minus, v, x0 - h);
      return (mean_spot(plus, options) - mean_spot(minus, options)) / (2 * h);
    };
    const double h = scale[i];
    const double fd = (4 * central(h / 2) - central(h)) / 3;
    const double denominator = std::max(std::abs(g.gradient[i]), 1e-4 * largest_scaled / scale[i]);
    INFO("d/d", v.name(), ": jet ", g.gradient[i], " fd ", fd);
    CHECK(std::abs(g.gradient[i] - fd) / denominator < 1e-6);
  }
}

TEST_CASE("profile variables parse and name themselves") {
  PrescriptionVariable v;
  REQUIRE(parse_profile_variable("k3", v));
  CHECK(v.kind == PrescriptionVariable::Kind::kConic);
  CHECK(v.surface == 2);
  CHECK(v.name() == "k3");
  REQUIRE(parse_profile_variable("a4_3", v));
  CHECK(v.kind == PrescriptionVariable::Kind::kAsphere);
  CHECK(v.term == 1);
  CHECK(v.name() == "a4_3");
  REQUIRE(parse_profile_variable("a2_1", v));
  CHECK(v.term == 0);
  REQUIRE(parse_profile_variable("a16_12", v));
  CHECK(v.term == 7);
  CHECK(!parse_profile_variable("a5_3", v));
  CHECK(!parse_profile_variable("a18_3", v));
  CHECK(!parse_profile_variable("c3", v));
  CHECK(!parse_profile_variable("k", v));
}

TEST_CASE("scaling a lens scales every sag") {
  const Lens lens = aspheric_doublet();
  const Lens big = scaled(lens, 2.5);
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k)
    for (double r : {0.5, 2.0, 3.5})
      CHECK(big.surfaces[k].sag_mm(2.5 * r) ==
            doctest::Approx(2.5 * lens.surfaces[k].sag_mm(r)).epsilon(1e-13));
}

TEST_CASE("asphere intersection finds every steep ray that meets the surface below 80 deg") {
  // A large, strongly aspheric surface (R = 60 mm, k = -0.8, a4, a6) and rays through known
  // points of it from every direction up to 80 deg off axis: each point P on the surface and a
  // direction d give the vertex-plane start P - (z_P / n) d, so the path s = z_P / n is a root.
  // Newton (chunked and scalar) must find a hit wherever the incidence there is below 80 deg
  // (cos I >= 0.17); nearer grazing, g(s) has a near-double root and a miss is allowed.
  const double c = 1.0 / 60.0, one_plus_k = 0.2;
  const double a[8] = {0.0, 2e-6, -1e-9, 0.0, 0.0, 0.0, 0.0, 0.0};
  Rng rng(2026);
  auto uniform = [&rng] { return unit_interval(rng); };
  int checked = 0, hits = 0;
  for (int i = 0; i < 20000; ++i) {
    const double r = 45.0 * std::sqrt(uniform()), phi = 2.0 * kPi * uniform();
    const double x = r * std::cos(phi), y = r * std::sin(phi);
    const double theta = 80.0 * kPi / 180.0 * uniform(), psi = 2.0 * kPi * uniform();
    const double l = std::sin(theta) * std::cos(psi), m = std::sin(theta) * std::sin(psi),
                 n = std::cos(theta);
    double sag = 0, slope = 0;
    detail::asphere_sag(c, one_plus_k, a, x * x + y * y, sag, slope);
    const double dg = n - 2.0 * slope * (x * l + y * m);  // d . (-2x S', -2y S', 1)
    const double cos_i = dg / std::sqrt(1.0 + 4.0 * (x * x + y * y) * slope * slope);
    if (cos_i < 0.17) continue;
    ++checked;
    const double x1 = x - sag / n * l, y1 = y - sag / n * m;
    double s_scalar = 0.0;
    const bool scalar_hit = detail::asphere_newton(c, one_plus_k, a, x1, y1, l, m, n, s_scalar);
    double s_chunk = 0.0;
    std::int32_t failure = -1;
    detail::asphere_intersect_chunk(c, one_plus_k, a, 1, &x1, &y1, &l, &m, &n, &s_chunk, &failure);
    // The hit is a root of g (another, nearer root is a valid first intersection too).
    auto residual = [&](double s) {
      const double xs = x1 + s * l, ys = y1 + s * m;
      double sg = 0, sl = 0;
      detail::asphere_sag(c, one_plus_k, a, xs * xs + ys * ys, sg, sl);
      return std::abs(s * n - sg);
    };
    if (scalar_hit && failure == kRayOk && residual(s_scalar) < 1e-10 && residual(s_chunk) < 1e-10)
      ++hits;
  }
  MESSAGE(checked, " rays below 80 deg incidence, ", hits, " found by both Newton stages");
  CHECK(checked > 15000);
  CHECK(hits == checked);
}

}  // namespace test_surface_profiles
