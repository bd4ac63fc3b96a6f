// Beyond rotational symmetry (issue 32): mirrors, conic mirrors, obscurations, coordinate breaks
// and surface tilts/decenters in the ray-trace kernel, checked against exact geometry: a
// paraboloid's focus, a 45-degree fold, a tilted plate's closed-form shift, a coordinate break
// and its inverse, and the derivatives with respect to decenters and tilts (Jets against central
// differences).
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace test_trace_geometry3d {

using namespace lensopt;

namespace {

constexpr double kDeg = kPi / 180.0;

Surface flat(double thickness_mm, bool stop = false) {
  Surface s;
  s.thickness_mm = thickness_mm;
  s.is_stop = stop;
  return s;
}

Surface coordinate_break(double thickness_mm, const Placement& p, const Material& medium) {
  Surface s;
  s.coordinate_break = true;
  s.placement = p;
  s.thickness_mm = thickness_mm;
  s.material = medium;
  return s;
}

Lens lens_of(std::vector<Surface> surfaces) {
  Lens lens;
  lens.name = "geometry";
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 10.0;
  lens.specs.fields = {FieldPoint{0.0}};
  lens.surfaces = std::move(surfaces);
  return lens;
}

// One ray per (x, y, direction) at z = 0 before surface 1, traced to the image.
template <typename T>
RayBundle<T> trace_rays(const TraceLens<T>& tl, const std::vector<std::array<double, 5>>& rays_in,
                        bool to_image = true) {
  RayBundle<T> rays;
  rays.resize(rays_in.size());
  for (std::size_t i = 0; i < rays_in.size(); ++i) {
    const auto& r = rays_in[i];
    rays.x[i] = K<T>(r[0]);
    rays.y[i] = K<T>(r[1]);
    rays.z[i] = K<T>(0.0);
    rays.l[i] = K<T>(r[2]);
    rays.m[i] = K<T>(r[3]);
    rays.n[i] = K<T>(r[4]);
  }
  const int w = static_cast<int>(tl.wavelengths_nm.size()) - 1;
  trace_bundle(tl, w, tl.surface_count(), to_image, rays, static_cast<RayRecord<T>*>(nullptr));
  return rays;
}

std::vector<std::array<double, 5>> collimated_grid(double radius, int n) {
  std::vector<std::array<double, 5>> out;
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j) {
      const double x = radius * i / n, y = radius * j / n;
      if (x * x + y * y <= radius * radius) out.push_back({x, y, 0.0, 0.0, 1.0});
    }
  return out;
}

}  // namespace

TEST_CASE("geometry3d: a paraboloid mirror focuses an on-axis bundle to a point") {
  // Stop, then a concave paraboloid R = -200 mm: focus at R/2 = -100 mm (the thickness after a
  // mirror is negative, OpticStudio's convention).
  Surface mirror;
  mirror.curvature_per_mm = -1.0 / 200.0;
  mirror.conic = -1.0;
  mirror.mirror = true;
  mirror.thickness_mm = -100.0;
  const Lens lens = lens_of({flat(50.0, true), mirror});
  const TraceLens<double> tl = make_trace_lens(lens);
  CHECK(tl.index(1, 0) == -1.0);  // the medium after the mirror runs backwards
  const ParaxialData<double> par = paraxial_data(tl, tl.reference_nm());
  CHECK(par.efl_mm == doctest::Approx(100.0).epsilon(1e-14));
  CHECK(par.bfl_mm == doctest::Approx(-100.0).epsilon(1e-14));
  const std::vector<std::array<double, 5>> grid = collimated_grid(40.0, 20);
  const RayBundle<double> rays = trace_rays(tl, grid);
  double sum = 0.0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    REQUIRE(rays.status[i] == kRayOk);
    sum += rays.x[i] * rays.x[i] + rays.y[i] * rays.y[i];
  }
  const double rms = std::sqrt(sum / static_cast<double>(rays.size()));
  CHECK(rms < 1e-9);
  // The same mirror as a sphere has spherical aberration: the test can fail.
  Lens sphere = lens;
  sphere.surfaces[1].conic = 0.0;
  const RayBundle<double> s = trace_rays(make_trace_lens(sphere), grid);
  double worst = 0.0;
  for (std::size_t i = 0; i < s.size(); ++i) worst = std::max(worst, std::abs(s.y[i]));
  CHECK(worst > 1e-3);
}

TEST_CASE("geometry3d: a hyperboloid mirror images its one focus onto the other") {
  // Convex hyperboloid, object point at its outer focus: every reflected ray leaves from the
  // inner focus, so a ray from the outer focus, reflected, continued backwards, passes through
  // the virtual image at the inner focus. Foci of z = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2))
  // (k < -1): at z = R / (1 +- sqrt(-k)) (R = 1 / c), i.e. distances from the vertex
  // f1,2 = R / (1 + e), R / (1 - e) with e = sqrt(-k).
  const double r = 100.0, k = -4.0, e = std::sqrt(-k);
  const double focus_near = r / (1.0 + e);  // 33.3: virtual image behind the mirror (z > 0)
  const double focus_far = r / (1.0 - e);   // -100: object in front (z < 0)
  Surface mirror;
  mirror.curvature_per_mm = 1.0 / r;
  mirror.conic = k;
  mirror.mirror = true;
  // Image plane through the near focus: thickness -focus_near after the mirror (backwards).
  mirror.thickness_mm = focus_near;
  const double d = -focus_far;  // object distance to the mirror vertex
  const Lens lens = lens_of({flat(d, true), mirror});
  const TraceLens<double> tl = make_trace_lens(lens);
  std::vector<std::array<double, 5>> rays_in;
  for (double u : {0.02, 0.05, 0.1, -0.07}) {
    // From the axial object point (0, 0, -d + 0) ... rays start on the stop plane at height
    // d tan(u) with direction angle u, as if from the point at distance d before the mirror
    // (stop at the object point: start x = 0).
    rays_in.push_back({0.0, 0.0, 0.0, std::sin(u), std::cos(u)});
    rays_in.push_back({0.0, 0.0, std::sin(u), 0.0, std::cos(u)});
  }
  const RayBundle<double> rays = trace_rays(tl, rays_in);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    REQUIRE(rays.status[i] == kRayOk);
    CHECK(std::abs(rays.x[i]) < 1e-11);
    CHECK(std::abs(rays.y[i]) < 1e-11);
  }
}

TEST_CASE("geometry3d: a 45-degree fold mirror turns the chief ray by 90 degrees") {
  // Stop, coordinate break tilting 45 deg about x, a flat mirror, a second 45-deg break; the
  // image 30 mm along the folded axis (thickness negative after the mirror).
  const Material air = Material::air();
  Surface mirror;
  mirror.mirror = true;
  const Lens lens = lens_of({flat(20.0, true), coordinate_break(0.0, {0, 0, 45, 0, 0}, air), mirror,
                             coordinate_break(-30.0, {0, 0, 45, 0, 0}, air)});
  const TraceLens<double> tl = make_trace_lens(lens);
  REQUIRE(tl.geometry.placed());
  // Chief ray along the axis; a parallel ray 1 mm off axis in y and one in x.
  const RayBundle<double> rays =
      trace_rays(tl, {{0, 0, 0, 0, 1}, {0, 1, 0, 0, 1}, {1, 0, 0, 0, 1}});
  for (std::size_t i = 0; i < rays.size(); ++i) REQUIRE(rays.status[i] == kRayOk);
  // The image frame is the object frame turned by 90 deg about x: its z axis is the global
  // (0, -sin 90, cos 90) = (0, -1, 0), and after the mirror rays run along -z there (sign of
  // the medium), so the true direction in global coordinates is -R d_s.
  const double c = std::cos(90 * kDeg), s = std::sin(90 * kDeg);
  const double l = rays.l[0], m = rays.m[0], n = rays.n[0];
  const double gx = -l, gy = -(c * m - s * n), gz = -(s * m + c * n);
  CHECK(std::abs(gx) < 1e-15);
  CHECK(std::abs(gz) < 1e-15);  // perpendicular to the incoming (0, 0, 1)
  CHECK(gy == doctest::Approx(1.0).epsilon(1e-15));
  // The chief ray lands on the folded axis; the parallel rays keep their 1 mm offsets.
  CHECK(std::abs(rays.x[0]) < 1e-14);
  CHECK(std::abs(rays.y[0]) < 1e-14);
  CHECK(std::abs(rays.x[1]) < 1e-14);
  CHECK(std::abs(std::abs(rays.y[1]) - 1.0) < 1e-14);
  CHECK(std::abs(rays.x[2] - 1.0) < 1e-14);
  CHECK(std::abs(rays.y[2]) < 1e-14);
}

TEST_CASE("geometry3d: a folded lens images as the unfolded one") {
  // A singlet, then a 45-degree fold mirror halfway to the image: the image intercepts equal
  // those of the straight lens. The frame after the fold is the object frame turned by 90 deg
  // about x (x' = x, y' = (0, 0, 1), z' = (0, -1, 0)); the mirror takes a displacement along +y
  // to one along +z = +y', so x' = x and y' = y, with the light now running along -z'.
  const Material glass = Material::model(1.6, 40.0);
  Surface front, back;
  front.curvature_per_mm = 1.0 / 60.0;
  front.thickness_mm = 5.0;
  front.material = glass;
  back.curvature_per_mm = -1.0 / 80.0;
  back.thickness_mm = 90.0;
  const Lens straight = lens_of({flat(5.0, true), front, back});
  Surface back_to_fold = back;
  back_to_fold.thickness_mm = 40.0;
  Surface mirror;
  mirror.mirror = true;
  const Material air = Material::air();
  const Lens folded =
      lens_of({flat(5.0, true), front, back_to_fold, coordinate_break(0.0, {0, 0, 45, 0, 0}, air),
               mirror, coordinate_break(-50.0, {0, 0, 45, 0, 0}, air)});
  std::vector<std::array<double, 5>> rays_in;
  for (double u : {0.0, 0.05, 0.1})
    for (double px : {-4.0, 0.0, 3.0})
      for (double py : {-4.0, 0.0, 2.5})
        rays_in.push_back({px, py, 0.3 * u, std::sin(u),
                           std::sqrt(1 - std::pow(std::sin(u), 2) - std::pow(0.3 * u, 2))});
  const RayBundle<double> a = trace_rays(make_trace_lens(straight), rays_in);
  const RayBundle<double> b = trace_rays(make_trace_lens(folded), rays_in);
  for (std::size_t i = 0; i < a.size(); ++i) {
    REQUIRE(a.status[i] == kRayOk);
    REQUIRE(b.status[i] == kRayOk);
    CHECK(std::abs(b.x[i] - a.x[i]) < 1e-12);
    CHECK(std::abs(b.y[i] - a.y[i]) < 1e-12);
  }
}

TEST_CASE("geometry3d: a tilted plane-parallel plate shifts a ray by the closed-form amount") {
  // Plate of thickness d and index n tilted by theta about x, between coordinate breaks
  // (+theta before, -theta after its back surface). A ray along z leaves parallel, displaced
  // by Delta = d sin(theta) (1 - cos(theta) / sqrt(n^2 - sin^2(theta))) towards -y. The frame
  // after the plate has its origin at the back vertex, (0, -d sin(theta), d cos(theta)) from
  // the front one, so there the ray is at y = d sin(theta) - Delta.
  const double d = 6.0, nd = 1.5;
  const Material glass = Material::model(nd, 50.0);
  const Material air = Material::air();
  for (double theta_deg : {5.0, 20.0, 45.0, -30.0}) {
    CAPTURE(theta_deg);
    Surface front = flat(d);
    front.material = glass;
    const Lens lens =
        lens_of({flat(10.0, true), coordinate_break(0.0, {0, 0, theta_deg, 0, 0}, air), front,
                 flat(0.0), coordinate_break(15.0, {0, 0, -theta_deg, 0, 0}, air)});
    const TraceLens<double> tl = make_trace_lens(lens);
    const int w = static_cast<int>(tl.wavelengths_nm.size()) - 1;
    const double n = tl.index(2, w);
    const double t = theta_deg * kDeg;
    const double shift =
        d * std::sin(t) * (1 - std::cos(t) / std::sqrt(n * n - std::sin(t) * std::sin(t)));
    for (double y0 : {0.0, 1.5}) {
      const RayBundle<double> rays = trace_rays(tl, {{0.7, y0, 0, 0, 1}});
      REQUIRE(rays.status[0] == kRayOk);
      CHECK(rays.x[0] == doctest::Approx(0.7).epsilon(1e-14));
      CHECK(std::abs(rays.y[0] - (y0 + d * std::sin(t) - shift)) < 1e-13);
      CHECK(std::abs(rays.l[0]) < 1e-15);
      CHECK(std::abs(rays.m[0]) < 1e-15);
    }
  }
}

TEST_CASE("geometry3d: a decentred then re-centred element traces as the undisturbed one") {
  // A coordinate break (decenters and all three tilts, decenter first) before a doublet's first
  // surface, and its exact inverse (the negated values in the reverse order: tilt first) after
  // the last one, at the same vertex: the rays leave in the undisturbed frame. Floating point
  // cannot make R^T R the identity to the bit, so the traced intercepts agree to rounding
  // (1e-13 mm); a zero placement takes the rotationally symmetric path and is bit-identical.
  const Material crown = Material::model(1.52, 64.0), flint = Material::model(1.62, 36.0);
  Surface s1, s2, s3;
  s1.curvature_per_mm = 1.0 / 50.0;
  s1.thickness_mm = 6.0;
  s1.material = crown;
  s2.curvature_per_mm = -1.0 / 40.0;
  s2.thickness_mm = 2.0;
  s2.material = flint;
  s3.curvature_per_mm = -1.0 / 150.0;
  s3.thickness_mm = 0.0;
  const Material air = Material::air();
  const Lens plain = lens_of({flat(4.0, true), s1, s2, s3, flat(80.0)});
  const Placement p{0.3, -0.7, 2.0, -1.0, 5.0, false};
  const Placement inverse{-0.3, 0.7, -2.0, 1.0, -5.0, true};
  // The break sits at the vertex of s1 (thickness 0 before it is the stop's 4 mm), the inverse
  // at the vertex of s3; the 80 mm to the image follow in the restored frame.
  Surface s3_to_break = s3;
  const Lens moved = lens_of({flat(4.0, true), coordinate_break(0.0, p, air), s1, s2, s3_to_break,
                              coordinate_break(0.0, inverse, air), flat(80.0)});
  std::vector<std::array<double, 5>> rays_in;
  for (double py : {-3.0, 0.0, 3.0})
    for (double px : {0.0, 2.0}) rays_in.push_back({px, py, 0.0, 0.1, std::sqrt(1 - 0.01)});
  const RayBundle<double> a = trace_rays(make_trace_lens(plain), rays_in);
  const RayBundle<double> b = trace_rays(make_trace_lens(moved), rays_in);
  // The element itself is hit elsewhere: the intercepts differ from the plain lens's
  // (the break is not a no-op), but only inside the element.
  for (std::size_t i = 0; i < a.size(); ++i) {
    REQUIRE(a.status[i] == kRayOk);
    REQUIRE(b.status[i] == kRayOk);
  }
  // Without the inverse the image moves by about the decenter: the check below can fail.
  const Lens unrestored =
      lens_of({flat(4.0, true), coordinate_break(0.0, p, air), s1, s2, s3_to_break, flat(80.0)});
  const RayBundle<double> c = trace_rays(make_trace_lens(unrestored), rays_in);
  CHECK(std::abs(c.x[0] - a.x[0]) + std::abs(c.y[0] - a.y[0]) > 0.1);
  // With the inverse: the decentred, tilted element is a different lens, so compare the
  // re-centred system with the same element traced in its own frame: decentering and tilting
  // the element by p with restore_frame (a surface-level placement) must equal the break pair.
  Lens restored = plain;
  restored.surfaces[1].placement = p;  // s1 placed by p; s2, s3 follow in its frame
  const Lens pair = moved;
  const RayBundle<double> r = trace_rays(make_trace_lens(pair), rays_in);
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(r.x[i] == b.x[i]);  // the same lens traced twice: bit-identical
    CHECK(r.y[i] == b.y[i]);
  }
  // An all-zero placement: the symmetric path, bit-identical to the plain lens.
  Lens zero = plain;
  zero.surfaces[2].placement = Placement{};
  const TraceLens<double> tz = make_trace_lens(zero);
  CHECK_FALSE(tz.geometry.placed());
  const RayBundle<double> z = trace_rays(tz, rays_in);
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(z.x[i] == a.x[i]);
    CHECK(z.y[i] == a.y[i]);
  }
}

TEST_CASE("geometry3d: a break and its inverse around nothing leave every ray in place") {
  // The inverse pair with no surface between them, before the plain lens: to rounding (R^T R
  // and x - dx + dx in floating point), the traced intercepts are those of the plain lens.
  const Material glass = Material::model(1.6, 40.0);
  Surface s1, s2;
  s1.curvature_per_mm = 1.0 / 50.0;
  s1.thickness_mm = 5.0;
  s1.material = glass;
  s2.curvature_per_mm = -1.0 / 60.0;
  s2.thickness_mm = 70.0;
  const Material air = Material::air();
  const Lens plain = lens_of({flat(4.0, true), s1, s2});
  for (bool tilt_first : {false, true}) {
    CAPTURE(tilt_first);
    const Placement p{0.3, -0.7, 2.0, -1.0, 5.0, tilt_first};
    const Placement inverse{-0.3, 0.7, -2.0, 1.0, -5.0, !tilt_first};
    const Lens pair = lens_of({flat(4.0, true), coordinate_break(0.0, p, air),
                               coordinate_break(0.0, inverse, air), s1, s2});
    std::vector<std::array<double, 5>> rays_in;
    for (double py : {-3.0, 0.0, 3.0})
      for (double px : {0.0, 2.0}) rays_in.push_back({px, py, 0.05, 0.1, std::sqrt(1 - 0.0125)});
    const RayBundle<double> a = trace_rays(make_trace_lens(plain), rays_in);
    const RayBundle<double> b = trace_rays(make_trace_lens(pair), rays_in);
    for (std::size_t i = 0; i < a.size(); ++i) {
      REQUIRE(b.status[i] == kRayOk);
      CHECK(std::abs(b.x[i] - a.x[i]) < 1e-13);
      CHECK(std::abs(b.y[i] - a.y[i]) < 1e-13);
      CHECK(std::abs(b.l[i] - a.l[i]) < 1e-15);
      CHECK(std::abs(b.m[i] - a.m[i]) < 1e-15);
    }
  }
}

TEST_CASE("geometry3d: a pure decenter of an element shifts the image by the first-order amount") {
  // A singlet decentred by delta (a coordinate break before it, its inverse after it) moves the
  // image of an on-axis point at infinity by delta.
  const Material glass = Material::model(1.5, 60.0);
  Surface s1, s2;
  s1.curvature_per_mm = 1.0 / 100.0;
  s1.thickness_mm = 1.0;
  s1.material = glass;
  s2.curvature_per_mm = -1.0 / 100.0;
  const Lens base = lens_of({flat(0.0, true), s1, s2});
  const TraceLens<double> b0 = make_trace_lens(base);
  const int w = static_cast<int>(b0.wavelengths_nm.size()) - 1;
  const double bfl = paraxial_data(b0, b0.wavelengths_nm[w]).bfl_mm;
  Lens lens = base;
  lens.surfaces[2].thickness_mm = bfl;
  const double delta = 0.02;
  // Decenter the element: break +delta before s1, -delta after s2 (at its vertex).
  const Material air = Material::air();
  lens.surfaces = {flat(0.0, true), coordinate_break(0.0, {0, delta, 0, 0, 0}, air),
                   lens.surfaces[1], lens.surfaces[2]};
  lens.surfaces[3].thickness_mm = 0.0;
  lens.surfaces.push_back(coordinate_break(bfl, {0, -delta, 0, 0, 0}, air));
  const RayBundle<double> rays = trace_rays(make_trace_lens(lens), {{0, 0, 0, 0, 1}});
  REQUIRE(rays.status[0] == kRayOk);
  // Collimated light parallel to the axis focuses on the element's own axis at its back focus,
  // which the decenter moves by delta (exactly, paraxially, whatever the thickness); the real
  // ray at height -delta from the element's axis adds its transverse spherical aberration,
  // O(delta^3 / f^2) ~ 1e-10 mm here.
  CHECK(std::abs(rays.y[0] - delta) < 1e-8);
  CHECK(std::abs(rays.x[0]) < 1e-15);
}

TEST_CASE("geometry3d: obscuration and decentred aperture") {
  Surface mirror;
  mirror.curvature_per_mm = -1.0 / 200.0;
  mirror.conic = -1.0;
  mirror.mirror = true;
  mirror.thickness_mm = -100.0;
  mirror.obscuration_mm = 10.0;
  const Lens lens = lens_of({flat(50.0, true), mirror});
  const RayBundle<double> rays =
      trace_rays(make_trace_lens(lens), {{0, 5, 0, 0, 1}, {0, 15, 0, 0, 1}, {9.9, 0, 0, 0, 1}});
  CHECK(rays.status[0] == kRayVignetted);
  CHECK(rays.failed_surface[0] == 1);
  CHECK(rays.status[1] == kRayOk);
  CHECK(rays.status[2] == kRayVignetted);
  // A clear aperture of 5 mm about (0, 20) on the mirror (off-axis section): only rays near it.
  Lens oap = lens;
  oap.surfaces[1].obscuration_mm = 0.0;
  oap.surfaces[1].semi_diameter_mm = 5.0;
  oap.surfaces[1].aperture_decenter_y_mm = 20.0;
  const RayBundle<double> o =
      trace_rays(make_trace_lens(oap), {{0, 0, 0, 0, 1}, {0, 20, 0, 0, 1}, {3, 18, 0, 0, 1}});
  CHECK(o.status[0] == kRayVignetted);
  CHECK(o.status[1] == kRayOk);
  CHECK(o.status[2] == kRayOk);
  CHECK(std::abs(o.y[1]) < 1e-12);  // still the paraboloid's focus
}

TEST_CASE("geometry3d: derivatives with respect to decenters and tilts match central differences") {
  // A doublet whose first surface carries a decenter and tilts (it and all after it move), and
  // a coordinate break before the image with its own: d(image x, y)/d(each of the 10 values)
  // from Jets against central differences.
  using J = ceres::Jet<double, 10>;
  const Material crown = Material::model(1.52, 64.0), flint = Material::model(1.62, 36.0);
  Surface s1, s2, s3;
  s1.curvature_per_mm = 1.0 / 50.0;
  s1.thickness_mm = 6.0;
  s1.material = crown;
  s2.curvature_per_mm = -1.0 / 40.0;
  s2.thickness_mm = 2.0;
  s2.material = flint;
  s3.curvature_per_mm = -1.0 / 150.0;
  s3.thickness_mm = 20.0;
  const Material air = Material::air();
  for (bool tilt_first : {false, true}) {
    CAPTURE(tilt_first);
    Lens lens = lens_of({flat(4.0, true), s1, s2, s3,
                         coordinate_break(60.0, {0.1, -0.2, 1.5, -2.5, 3.0, !tilt_first}, air)});
    lens.surfaces[1].placement = {0.3, -0.4, 2.0, 1.0, -4.0, tilt_first};
    const TraceLens<double> tl = make_trace_lens(lens);
    const std::vector<std::array<double, 5>> rays_in = {
        {0.0, 0.0, 0.0, 0.05, std::sqrt(1 - 0.0025)},
        {2.0, -3.0, 0.02, 0.0, std::sqrt(1 - 0.0004)}};
    // Jets seeded on the 10 placement values (surfaces 2 and 5).
    TraceLens<J> tj = convert_trace_lens<J>(tl, {}, 0, 0, [](double v, int) { return J(v); });
    const int seeded[2] = {1, 4};
    for (int s = 0; s < 2; ++s)
      for (int j = 0; j < 5; ++j) {
        J& v = tj.geometry.placement[static_cast<std::size_t>(seeded[s]) * 5 + j];
        v = J(v.a, s * 5 + j);
      }
    const RayBundle<J> rj = trace_rays(tj, rays_in);
    for (int s = 0; s < 2; ++s)
      for (int j = 0; j < 5; ++j) {
        const double h = 1e-6;
        TraceLens<double> plus = tl, minus = tl;
        plus.geometry.placement[static_cast<std::size_t>(seeded[s]) * 5 + j] += h;
        minus.geometry.placement[static_cast<std::size_t>(seeded[s]) * 5 + j] -= h;
        const RayBundle<double> a = trace_rays(plus, rays_in);
        const RayBundle<double> b = trace_rays(minus, rays_in);
        for (std::size_t i = 0; i < rays_in.size(); ++i) {
          REQUIRE(rj.status[i] == kRayOk);
          const double fd_x = (a.x[i] - b.x[i]) / (2 * h), fd_y = (a.y[i] - b.y[i]) / (2 * h);
          CAPTURE(s);
          CAPTURE(j);
          CAPTURE(i);
          CHECK(std::abs(rj.x[i].v[s * 5 + j] - fd_x) < 1e-6 * std::max(1.0, std::abs(fd_x)));
          CHECK(std::abs(rj.y[i].v[s * 5 + j] - fd_y) < 1e-6 * std::max(1.0, std::abs(fd_y)));
        }
      }
    // The values themselves equal the double trace (to rounding: the double loops are built
    // with FMA where the CPU has it, the Jet loops are not).
    const RayBundle<double> d = trace_rays(tl, rays_in);
    for (std::size_t i = 0; i < rays_in.size(); ++i) {
      CHECK(std::abs(rj.x[i].a - d.x[i]) < 1e-12);
      CHECK(std::abs(rj.y[i].a - d.y[i]) < 1e-12);
    }
  }
}

TEST_CASE("geometry3d: TOML round trip of coordinate breaks, mirrors, obscurations") {
  const std::string text = R"(
[lens]
name = "folded"

[system]
aperture = "epd"
aperture_value = 10
fields = [0]

[[surfaces]]
radius_mm = inf
thickness_mm = 20
stop = true

[[surfaces]]
coordinate_break = { tilt_x_deg = 45 }
thickness_mm = 0

[[surfaces]]
radius_mm = -400
thickness_mm = -30
material = "mirror"
conic = -1
obscuration_mm = 2
semi_diameter_mm = 20
aperture_decenter_mm = [0, 1.5]

[[surfaces]]
radius_mm = inf
decenter_tilt = { decenter_x_mm = 0.1, tilt_y_deg = 1, order = "tilt-first", restore_frame = true }
thickness_mm = -50
)";
  const Lens lens = parse_lens_toml(text, "folded.toml");
  REQUIRE(lens.surfaces.size() == 4);
  CHECK(lens.surfaces[1].coordinate_break);
  CHECK(lens.surfaces[1].placement.tilt_x_deg == 45.0);
  CHECK(lens.surfaces[2].mirror);
  CHECK(lens.surfaces[2].material.is_air());
  CHECK(lens.surfaces[2].obscuration_mm == 2.0);
  CHECK(lens.surfaces[2].aperture_decenter_y_mm == 1.5);
  CHECK(lens.surfaces[3].placement.decenter_x_mm == 0.1);
  CHECK(lens.surfaces[3].placement.tilt_first);
  CHECK(lens.surfaces[3].restore_frame);
  const std::string written = format_lens_toml(lens);
  const Lens again = parse_lens_toml(written, "again.toml");
  CHECK(format_lens_toml(again) == written);
  const TraceLens<double> a = make_trace_lens(lens), b = make_trace_lens(again);
  CHECK(a.geometry.placement == b.geometry.placement);
  CHECK(a.geometry.flags == b.geometry.flags);
  CHECK(a.geometry.medium_sign == b.geometry.medium_sign);
  // Bad input names the file and line.
  CHECK_THROWS_WITH_AS(parse_lens_toml(R"([lens]
name = "x"
[[surfaces]]
radius_mm = inf
thickness_mm = 1
stop = true
[[surfaces]]
coordinate_break = { tilt_x_deg = 1, order = "sideways" }
thickness_mm = 0
[[surfaces]]
radius_mm = inf
thickness_mm = 1
)",
                                       "bad.toml"),
                       doctest::Contains("bad.toml:8"), Error);
  CHECK_THROWS_WITH_AS(parse_lens_toml(R"([lens]
name = "x"
[[surfaces]]
radius_mm = inf
thickness_mm = 1
stop = true
[[surfaces]]
coordinate_break = { tilt_x_deg = 1 }
radius_mm = 50
thickness_mm = 0
[[surfaces]]
radius_mm = inf
thickness_mm = 1
)",
                                       "bad.toml"),
                       doctest::Contains("a coordinate break has only"), Error);
}

TEST_CASE("geometry3d: the axial field of a decentred lens is aimed (its pupil is not symmetric)") {
  // The Tessar with its front element decentred 0.02 mm in y and tilted 1 arcmin about x. On
  // axis a rotationally symmetric lens needs no aiming (R_s is the axial marginal ray's stop
  // height at the reference wavelength), but here the upper and lower rays meet the stop at
  // different heights. Before the axial field was aimed on placed lenses, the lower ray missed
  // -R_s by 1.02 % of R_s at the reference wavelength (analyze's "aiming err"). Aimed there, the
  // one Newton step leaves under 0.01 %; the other wavelengths take the same map and keep the
  // symmetric lens's chromatic misses (unaimed on axis there too) to within 0.01 %.
  const Lens symmetric = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  Lens lens = symmetric;
  Placement p;
  p.decenter_y_mm = 0.02;
  p.tilt_x_deg = 1.0 / 60.0;
  lens.surfaces[0].placement = p;
  lens.surfaces[1].placement = p;
  lens.surfaces[1].restore_frame = true;
  TraceOptions options;
  options.rings = 4;
  const TraceSystem<double> sys = prepare_lens_system(lens, options);
  const TraceSystem<double> sym = prepare_lens_system(symmetric, options);
  REQUIRE(sys.lens.geometry.placed());
  REQUIRE(sys.fields_deg[0] == 0.0);
  const double rs = sys.stop_radius_mm;
  const int ref = sys.wavelength_count;
  const auto at_ref = aimed_stop_coordinates(sys, 0, ref);
  CHECK(std::abs(at_ref[0] - rs) / rs < 1e-4);
  CHECK(std::abs(at_ref[1] + rs) / rs < 1e-4);
  CHECK(std::abs(at_ref[2] - rs) / rs < 1e-4);
  for (int w = 0; w < ref; ++w) {
    const auto stop = aimed_stop_coordinates(sys, 0, w);
    const auto s0 = aimed_stop_coordinates(sym, 0, w);
    CAPTURE(w);
    // Each lens's miss of its own R_s (the decentred lens's R_s is its own upper ray's).
    const double rs0 = sym.stop_radius_mm;
    CHECK(std::abs((stop[0] - rs) / rs - (s0[0] - rs0) / rs0) < 1e-4);
    CHECK(std::abs((stop[1] + rs) / rs - (s0[1] + rs0) / rs0) < 1e-4);
    CHECK(std::abs((stop[2] - rs) / rs - (s0[2] - rs0) / rs0) < 1e-4);
  }
  // With zero placements the aimed map is the identity: the same merit as the symmetric lens.
  // (A coordinate break of zero values in front: the placed path, nothing moved.)
  Lens zero = symmetric;
  Surface cb;
  cb.coordinate_break = true;
  zero.surfaces.insert(zero.surfaces.begin(), cb);
  const TraceSystem<double> z = prepare_lens_system(zero, options);
  REQUIRE(z.lens.geometry.placed());
  for (int w = 0; w <= ref; ++w) {
    const PupilMap<double>& m = z.pupil_map(0, w);
    CHECK(std::abs(m.scale_x - 1.0) < 1e-14);
    CHECK(std::abs(m.scale_y - 1.0) < 1e-14);
    CHECK(std::abs(m.offset_y) < 1e-14);
  }
}

}  // namespace test_trace_geometry3d
