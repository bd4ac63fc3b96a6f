// Physics of the ray tracer and paraxial optics: Snell's law in vector form, a plate's focus
// shift, the lensmaker's formula, paraxial limit of real rays; double and Jet alike.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <cmath>

#include "lensopt/analysis/spot.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/kernel.h"
#include "test_support.h"

namespace test_trace {

using namespace lensopt;

namespace {

// A lens from (curvature, thickness, nd or 0 for air) triples; stop at `stop`.
Lens make_lens(const std::vector<std::array<double, 3>>& rows, int stop) {
  Lens lens;
  lens.name = "test";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    Surface s;
    s.curvature_per_mm = rows[i][0];
    s.thickness_mm = rows[i][1];
    if (rows[i][2] > 0) s.material = Material::model(rows[i][2], 50.0);
    s.is_stop = static_cast<int>(i) == stop;
    lens.surfaces.push_back(s);
  }
  return lens;
}

template <typename T>
TraceLens<T> as(const TraceLens<double>& lens) {
  return convert_trace_lens<T>(lens, {}, 0, 0, [](double v, int) { return K<T>(v); });
}

}  // namespace

TEST_CASE_TEMPLATE("trace: Snell's law in vector form at a sphere", T, double,
                   ceres::Jet<double, 3>) {
  // Stop, then one sphere into glass.
  const double c = 1.0 / 12.0, nd = 1.7;
  const Lens lens = make_lens({{0.0, 2.0, 0.0}, {c, 5.0, nd}, {0.0, 10.0, 0.0}}, 0);
  const TraceLens<T> tl = as<T>(make_trace_lens(lens));
  const int w = static_cast<int>(tl.wavelengths_nm.size()) - 1;  // 587.6 nm: n = nd
  RayBundle<T> rays;
  rays.resize(1);
  const double l0 = 0.1, m0 = 0.3, n0 = std::sqrt(1 - l0 * l0 - m0 * m0);
  rays.x[0] = K<T>(1.0);
  rays.y[0] = K<T>(-2.0);
  rays.z[0] = K<T>(0.0);
  rays.l[0] = K<T>(l0);
  rays.m[0] = K<T>(m0);
  rays.n[0] = K<T>(n0);
  trace_bundle(tl, w, 2, false, rays, static_cast<RayRecord<T>*>(nullptr));
  REQUIRE(rays.status[0] == kRayOk);
  const double x = value_of(rays.x[0]), y = value_of(rays.y[0]), z = value_of(rays.z[0]);
  // The hit point lies on the sphere c (x^2 + y^2 + z^2) - 2 z = 0 (relative to vertex 2).
  CHECK(c * (x * x + y * y + z * z) - 2 * z == doctest::Approx(0.0).epsilon(1e-14));
  // Unit normal at the hit point, incoming and outgoing directions.
  const double nx = -c * x, ny = -c * y, nz = 1 - c * z;
  const double dx = value_of(rays.l[0]), dy = value_of(rays.m[0]), dz = value_of(rays.n[0]);
  CHECK(dx * dx + dy * dy + dz * dz == doctest::Approx(1.0).epsilon(1e-14));
  // n (d x N) = n' (d' x N): tangential components scale by the index ratio, in one plane.
  const double in_x = l0, in_y = m0, in_z = n0;
  const double cross_in[3] = {in_y * nz - in_z * ny, in_z * nx - in_x * nz, in_x * ny - in_y * nx};
  const double cross_out[3] = {dy * nz - dz * ny, dz * nx - dx * nz, dx * ny - dy * nx};
  for (int i = 0; i < 3; ++i)
    CHECK(1.0 * cross_in[i] == doctest::Approx(nd * cross_out[i]).epsilon(1e-13));
  // Refraction bends towards the normal: the angle with N shrinks.
  const double cos_in = in_x * nx + in_y * ny + in_z * nz;
  const double cos_out = dx * nx + dy * ny + dz * nz;
  CHECK(cos_out > cos_in);
}

TEST_CASE_TEMPLATE("trace: a ray missing a sphere or reflected totally is flagged, never NaN", T,
                   double, ceres::Jet<double, 2>) {
  // A strongly curved surface (R = 2 mm) hit at height 3 mm: no intersection.
  const Lens miss = make_lens({{0.0, 1.0, 0.0}, {0.5, 2.0, 1.5}, {0.0, 5.0, 0.0}}, 0);
  TraceLens<T> tl = as<T>(make_trace_lens(miss));
  RayBundle<T> rays;
  rays.resize(2);
  for (int i = 0; i < 2; ++i) {
    rays.x[i] = K<T>(0.0);
    rays.y[i] = K<T>(i == 0 ? 3.0 : 0.5);
    rays.z[i] = K<T>(0.0);
    rays.l[i] = K<T>(0.0);
    rays.m[i] = K<T>(0.0);
    rays.n[i] = K<T>(1.0);
  }
  trace_bundle(tl, 0, tl.surface_count(), true, rays, static_cast<RayRecord<T>*>(nullptr));
  CHECK(rays.status[0] == kRayMissedSurface);
  CHECK(rays.failed_surface[0] == 1);
  CHECK(rays.status[1] == kRayOk);
  for (int i = 0; i < 2; ++i) {
    CHECK(std::isfinite(value_of(rays.x[i])));
    CHECK(std::isfinite(value_of(rays.y[i])));
  }
  // Leaving glass (n = 1.8) at a steep surface: total internal reflection at the exit.
  const Lens tir = make_lens({{0.0, 1.0, 0.0}, {0.0, 2.0, 1.8}, {0.4, 5.0, 0.0}}, 0);
  tl = as<T>(make_trace_lens(tir));
  rays.resize(1);
  rays.x[0] = K<T>(0.0);
  rays.y[0] = K<T>(2.0);
  rays.z[0] = K<T>(0.0);
  rays.l[0] = K<T>(0.0);
  rays.m[0] = K<T>(0.0);
  rays.n[0] = K<T>(1.0);
  trace_bundle(tl, 0, tl.surface_count(), true, rays, static_cast<RayRecord<T>*>(nullptr));
  CHECK(rays.status[0] == kRayTotalInternalReflection);
  CHECK(rays.failed_surface[0] == 2);
  CHECK(std::isfinite(value_of(rays.y[0])));
}

TEST_CASE("paraxial: thick lens EFL matches the lensmaker's formula") {
  for (double nd : {1.5, 1.7, 1.9}) {
    for (double t : {0.5, 3.0, 8.0}) {
      const double c1 = 1.0 / 20.0, c2 = -1.0 / 35.0;
      const Lens lens = make_lens({{0.0, 1.0, 0.0}, {c1, t, nd}, {c2, 30.0, 0.0}}, 0);
      const TraceLens<double> tl = make_trace_lens(lens);
      const ParaxialData<double> p = paraxial_data(tl, kWavelengthD_nm);
      const double power = (nd - 1) * (c1 - c2 + (nd - 1) * t * c1 * c2 / nd);
      CHECK(p.efl_mm == doctest::Approx(1.0 / power).epsilon(1e-13));
      // BFL = f (1 - (n-1) t c1 / n)
      CHECK(p.bfl_mm ==
            doctest::Approx((1.0 / power) * (1 - (nd - 1) * t * c1 / nd)).epsilon(1e-12));
    }
  }
}

TEST_CASE("paraxial: a plane-parallel plate shifts the focus by t (1 - 1/n)") {
  const double c1 = 1.0 / 25.0, c2 = -1.0 / 40.0;
  const Lens bare = make_lens({{0.0, 1.0, 0.0}, {c1, 4.0, 1.6}, {c2, 10.0, 0.0}}, 0);
  const double bfl_bare = paraxial_data(make_trace_lens(bare), kWavelengthD_nm).bfl_mm;
  for (double n : {1.45, 1.8}) {
    const double t = 3.0, gap = 2.0;
    const Lens plate = make_lens(
        {{0.0, 1.0, 0.0}, {c1, 4.0, 1.6}, {c2, gap, 0.0}, {0.0, t, n}, {0.0, 10.0, 0.0}}, 0);
    const double bfl_plate = paraxial_data(make_trace_lens(plate), kWavelengthD_nm).bfl_mm;
    // Focus from the lens's last vertex: gap + t + bfl_plate = bfl_bare + t (1 - 1/n).
    CHECK(gap + t + bfl_plate == doctest::Approx(bfl_bare + t * (1 - 1 / n)).epsilon(1e-13));
  }
}

TEST_CASE("trace: real marginal rays approach the paraxial focus as the aperture shrinks") {
  const double c1 = 1.0 / 25.0, c2 = -1.0 / 40.0;
  const Lens lens = make_lens({{0.0, 1.0, 0.0}, {c1, 4.0, 1.6}, {c2, 10.0, 0.0}}, 0);
  const TraceLens<double> tl = make_trace_lens(lens);
  const int w = static_cast<int>(tl.wavelengths_nm.size()) - 1;
  const double bfl = paraxial_data(tl, kWavelengthD_nm).bfl_mm;
  double previous_error = 1e9;
  for (double h : {2.0, 1.0, 0.5, 0.25, 0.125, 0.0625}) {
    RayBundle<double> rays;
    rays.resize(1);
    rays.x[0] = 0;
    rays.y[0] = h;
    rays.z[0] = 0;
    rays.l[0] = 0;
    rays.m[0] = 0;
    rays.n[0] = 1;
    trace_bundle(tl, w, tl.surface_count(), false, rays, static_cast<RayRecord<double>*>(nullptr));
    // Axis crossing of the real ray after the last vertex.
    const double crossing = rays.z[0] - rays.y[0] * rays.n[0] / rays.m[0];
    const double error = std::abs(crossing - bfl);
    // Spherical aberration: longitudinal error ~ h^2, so halving h divides it by about 4.
    CHECK(error < previous_error / 3.5);
    previous_error = error;
  }
  CHECK(previous_error < 1e-3);
}

TEST_CASE("trace: paper pupil sampling has 1024 rays on the half pupil, within the unit disk") {
  const PupilSamples p = paper_pupil_samples(32);
  REQUIRE(p.size() == 1024);
  double max_r = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    CHECK(p.x[i] >= 0.0);
    max_r = std::max(max_r, std::hypot(p.x[i], p.y[i]));
  }
  CHECK(max_r == doctest::Approx(1.0));
  // Ring 0: one ray; its radius is 0 for k = 0, i = 0.
  CHECK(std::hypot(p.x[0], p.y[0]) == 0.0);
  // Ring 1 (rays 1..3): k + i = 2, 3, 4 -> radii 2/63, 3/63, 2/63.
  CHECK(std::hypot(p.x[1], p.y[1]) == doctest::Approx(2.0 / 63));
  CHECK(std::hypot(p.x[2], p.y[2]) == doctest::Approx(3.0 / 63));
  const std::vector<double> fields = field_angles_deg(25.0, 21);
  REQUIRE(fields.size() == 21);
  CHECK(fields[20] == 25.0);
  CHECK(fields[1] == doctest::Approx(1.25));
}

TEST_CASE("trace: a failed ray in the bundle leaves the other rays' bits unchanged") {
  // trace_bundle skips its per-ray status loops when no ray failed (and transfers to the image
  // without the per-ray branch): the rays of a bundle with a failure (the full bookkeeping) must
  // come out bit-identical to the same rays traced alone (the skipping path).
  const TraceLens<double> lens = make_trace_lens(make_lens(
      {{0.05, 3.0, 1.6}, {-0.02, 2.0, 0}, {0.0, 2.0, 0}, {0.03, 2.5, 1.7}, {0, 30, 0}}, 2));
  const int k_count = lens.surface_count();
  auto start = [](RayBundle<double>& b, std::size_t count) {
    b.resize(count);
    for (std::size_t i = 0; i < count; ++i) {
      const double u = static_cast<double>(i) / 40.0;
      b.x[i] = 0.3 * u;
      b.y[i] = -2.0 + 4.0 * u;
      b.z[i] = -1.0;
      b.l[i] = 0.0;
      b.m[i] = std::sin(0.2 * u);
      b.n[i] = std::cos(0.2 * u);
    }
  };
  RayBundle<double> alone, mixed;
  start(alone, 37);
  start(mixed, 38);
  // Ray 37 of `mixed` travels backwards; ray 5 is sent far off axis and misses a surface.
  mixed.l[37] = 0.0;
  mixed.m[37] = 0.6;
  mixed.n[37] = -0.8;
  RayBundle<double> far = mixed;
  far.y[5] = 200.0;
  trace_bundle(lens, 0, k_count, true, alone, static_cast<RayRecord<double>*>(nullptr));
  trace_bundle(lens, 0, k_count, true, mixed, static_cast<RayRecord<double>*>(nullptr));
  trace_bundle(lens, 0, k_count, true, far, static_cast<RayRecord<double>*>(nullptr));
  CHECK(mixed.status[37] == kRayBackwards);
  CHECK(mixed.failed_surface[37] == 0);
  CHECK(far.status[5] == kRayMissedSurface);
  for (std::size_t i = 0; i < 37; ++i) {
    INFO("ray ", i);
    REQUIRE(alone.status[i] == kRayOk);
    CHECK(mixed.status[i] == kRayOk);
    CHECK(mixed.x[i] == alone.x[i]);
    CHECK(mixed.y[i] == alone.y[i]);
    CHECK(mixed.l[i] == alone.l[i]);
    CHECK(mixed.m[i] == alone.m[i]);
    CHECK(mixed.n[i] == alone.n[i]);
    if (i == 5) continue;
    CHECK(far.status[i] == kRayOk);
    CHECK(far.y[i] == alone.y[i]);
    CHECK(far.x[i] == alone.x[i]);
  }
}

}  // namespace test_trace
