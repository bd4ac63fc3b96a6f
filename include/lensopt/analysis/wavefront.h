// The wavefront error (optical path difference, OPD) of one field and wavelength, templated on the
// scalar so the RMS wavefront has exact derivatives (a merit for `optimize --merit wavefront`).
//
// Convention (OpticStudio's):
//   * The incoming reference wavefront passes through the entrance-pupil centre E = (0, 0, z_EP)
//     (pupil_start_optical_path). For an object at infinity it is the plane normal to field
//     theta's direction d0 = (0, sin theta, cos theta): a ray starting on the entrance-pupil plane
//     at P = (x, y, z_EP) has already travelled OPL_0 = x l0 + y m0 = y sin theta from it. For an
//     object at a finite distance d it is the sphere about the field's object point
//     O = (0, y_O, -d) through E (the wave leaves O as a sphere): a ray from O through P has
//     travelled OPL_0 = n_obj (|P - O| - |E - O|) beyond it, n_obj the object-space index, so the
//     OPD is that of the whole path from the object point, as OpticStudio's for finite conjugates.
//     With D = z_EP + d: |P - O|^2 - |E - O|^2 = x^2 + y^2 - 2 y y_O, taken as
//       OPL_0 = n_obj (x^2 + y^2 - 2 y y_O) / (|P - O| + |E - O|)
//     (no cancellation of two ~d paths; -> y sin theta as d -> infinity, y_O = -D tan theta).
//   * The kernel adds n s over every segment up to the image plane (trace/kernel.h, RayRecord),
//     the first one from P to surface 1 included (signed: negative when E lies behind it).
//   * The reference sphere is centred on the image point C of the chief ray of the reference
//     wavelength (587.6 nm; pupil (0, 0) of the aimed pupil, i.e. the stop centre) and passes
//     through the point where that chief ray crosses the paraxial exit-pupil plane (the stop
//     imaged by the surfaces after it, at the reference wavelength): its signed radius is
//     s_c = z_XP / n_c, z_XP the exit pupil's axial position relative to the image plane, n_c
//     the chief ray's z direction cosine. All wavelengths share this sphere (so lateral colour
//     appears as tilt, as in OpticStudio).
//   * A ray reaching the image plane at P with direction d is followed back to the sphere:
//       |P + t d - C|^2 = s_c^2,  q = P - C:  t = -(q.d) + sign(s_c) sqrt((q.d)^2 - |q|^2 + s_c^2)
//     and OPL_sphere = OPL_image + n' t (n' the image-space index).
//     An afocal image space (Specs::afocal, analysis/afocal.h) has its reference sphere at
//     infinity: the plane normal to the chief ray through its exit-pupil point
//     (ReferenceSphere::plane), t = (s_c - q.d_c) / (d.d_c).
//   * W(p) = (OPL_sphere(p) - OPL_sphere(chief of the same wavelength)) / lambda, in waves:
//     positive where the ray's path to the sphere is longer than the chief ray's.
//   * RMS and P-V are taken after removing piston and tilt: W is fitted by least squares with
//     a + b x_p + c y_p (weighted by each sample's pupil area) and the residual is reported.
// A focus shift dz (mm, positive away from the lens) moves the image plane: every ray continues
// by dz / n_dir (adding n' dz / n_dir), and the sphere's radius grows by dz / n_c.
//
// Pupil sampling: an n x n grid of square cells over the normalized entrance pupil [-1, 1]^2
// (pupil coordinates are aimed per field and wavelength, trace/system.h); cell (i, j) has its
// centre at (-1 + (i + 1/2) 2/n, -1 + (j + 1/2) 2/n) and takes part when it overlaps the unit
// circle, with amplitude weight = the cell's area fraction inside the circle (so the pupil edge
// is anti-aliased). A ray that fails (missed surface, TIR, vignetted) has amplitude 0.
// Half grid (make_half_pupil_grid, for systems symmetric about the meridional plane, as the
// tracer's half-pupil spots assume): only the cells with x_p > 0, each weighted twice (it
// stands for its mirror (-x_p, y_p), whose W is the same), and the x_p = 0 column of an odd n
// once. The full grid's sums follow: the x-tilt is 0 and the piston and y-tilt fits, RMS and P-V
// are those of the full grid, at half the rays. A system that traces full pupils (a field's VDX or
// VAN set, TraceSystem::full_pupil) is not symmetric: it takes the full grid (a half grid throws).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/core/jet_width.h"
#include "lensopt/core/scalar.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/system.h"

namespace lensopt {

// The square pupil grid of the header.
struct PupilGrid {
  int n = 0;                   // cells across the pupil diameter
  std::vector<int> column;     // ix of each sample
  std::vector<int> row;        // iy of each sample (iy = 0 at y_p = -1)
  std::vector<double> weight;  // area fraction inside the unit circle, (0, 1]
  PupilSamples samples;        // normalized pupil coordinates (x_p, y_p)
  bool mirrored = false;       // a half grid (see the header)
  std::size_t size() const { return weight.size(); }
};

// The grid of n x n cells (n >= 2), edge cells weighted by their area inside the circle.
PupilGrid make_pupil_grid(int n);
// Its half x_p >= 0 with the weights of the header (mirrored).
PupilGrid make_half_pupil_grid(int n);

// A polar Gauss quadrature of the unit pupil (the optimizer's wavefront merit; no cells, n = 0).
// In u = r^2 the area element is dA = du dtheta / 2, so
//   int_disk f dA ~= sum_{i,j} (pi w_i / A) f(r_i sin theta_j, r_i cos theta_j)
// with r_i = sqrt(u_i), (u_i, w_i) the `rings` Gauss-Legendre nodes and weights of [0, 1]
// (sum w_i = 1) and A = 2 * `half_azimuths` equally spaced azimuths theta_j = (j + 1/2) pi /
// half_azimuths, j = 0..A-1 (theta from +y_p towards +x_p; no sample on the x_p = 0 line).
// The rule is exact for every polynomial in (x_p, y_p) of degree <= min(4 rings - 1, A - 1)
// (an odd monomial's azimuthal sum vanishes, an even one r^{2k} trig_d is exact for k < 2 rings
// and d < A), where a square grid of cells errs at first order at the rim. Its weights sum to pi
// (the pupil area). `mirrored`: only the azimuths with x_p > 0 (j < half_azimuths), each
// weighted twice, as make_half_pupil_grid (exact for meridionally symmetric systems).
PupilGrid make_pupil_quadrature(int rings, int half_azimuths, bool mirrored);

// The exit pupil's axial position relative to the image plane (mm, negative: in front of the
// image), paraxial at `wavelength_nm`: the stop centre imaged by the surfaces after the stop.
// A (nearly) telecentric image space returns -1e9 mm (the sphere becomes a plane).
template <typename T>
T exit_pupil_from_image_mm(const TraceLens<T>& lens, double wavelength_nm) {
  using std::abs;
  const int k_count = lens.surface_count();
  T y = K<T>(0.0);
  T w = K<T>(1.0);  // reduced angle after the stop (flat)
  for (int k = lens.stop + 1; k < k_count; ++k) {
    y = y + lens.thickness_mm[k - 1] * w / lens.index_at_nm(k - 1, wavelength_nm);
    w = w - y * lens.curvature_per_mm[k] *
                (lens.index_at_nm(k, wavelength_nm) - lens.index_at_nm(k - 1, wavelength_nm));
  }
  const T u = w / lens.index_at_nm(k_count - 1, wavelength_nm);
  if (!(abs(value_of(u)) > 1e-12)) return K<T>(-1e9);
  return -y / u - lens.thickness_mm[k_count - 1];
}

// The paraxial image-space NA of a finite object, NA' = |w| after the last surface (w = n u) of
// the marginal ray from the axial object point through the entrance pupil's rim, at the reference
// wavelength: the working F-number is 1 / (2 NA') (a 1:1 relay works at about twice EFL / EPD).
// 0 for an object at infinity (there the working F-number is N = EFL / EPD).
inline double finite_object_image_na(const TraceSystem<double>& sys) {
  if (sys.object_at_infinity()) return 0.0;
  const double u0 = 0.5 * sys.epd_mm / (sys.object_distance_mm + sys.entrance_pupil_z_mm);
  const ParaxialRay<double> marginal =
      paraxial_trace(sys.lens, ParaxialRay<double>{u0 * sys.object_distance_mm, u0},
                     sys.lens.surface_count(), sys.lens.reference_nm());
  return std::abs(marginal.w);
}

// The RMS spot radius (mm) per wave of RMS wavefront of a pure defocus W = W020 rho^2 in a
// system of working f-number N (EFL / EPD for an object at infinity, else 1 / (2 NA'),
// finite_object_image_na) at wavelength lambda (the reference one): the transverse ray
// aberration is -2 N lambda dW/drho = -4 N lambda W020 rho, of RMS 2 sqrt(2) N lambda W020 over
// the pupil, and the RMS of W020 rho^2 without piston is W020 / (2 sqrt(3)), so
//   mm per wave = 4 sqrt(6) N lambda   (Cooke, f/2 at 587.6 nm: 0.0115 mm per wave).
inline double wavefront_mm_per_wave(const TraceSystem<double>& sys) {
  const double lambda_mm = sys.lens.wavelengths_nm[sys.wavelength_count] * 1e-6;
  if (sys.object_at_infinity())
    return 4.0 * std::sqrt(6.0) * (std::abs(sys.efl_mm) / sys.epd_mm) * lambda_mm;
  return 4.0 * std::sqrt(6.0) * lambda_mm / (2.0 * finite_object_image_na(sys));
}

// The reference sphere of one field: centre on the (focus-shifted) image plane, signed radius.
template <typename T>
struct ReferenceSphere {
  T centre_x_mm, centre_y_mm;  // on the image plane
  T radius_mm;                 // s_c (negative: the exit pupil is in front of the image)
  bool ok = false;             // the reference chief ray reached the image
  // The sphere at infinity of an afocal image space (analysis/afocal.h): the plane normal to the
  // chief ray's direction (plane_l, plane_m, plane_n) at the signed distance radius_mm from C
  // along it (the chief ray's exit-pupil point). A ray at P = C + q on the image plane meets it
  // after t = (s_c - q.d_c) / (d.d_c).
  bool plane = false;
  T plane_l = K<T>(0.0), plane_m = K<T>(0.0), plane_n = K<T>(1.0);
};

namespace detail {

// Continues rays from the image plane by `focus_shift_mm` along z (no-op for 0).
template <typename T>
void shift_focus(RayBundle<T>& rays, std::vector<T>* opl, const T& n_image, double focus_shift_mm) {
  if (focus_shift_mm == 0.0) return;
  const T dz = K<T>(focus_shift_mm);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (rays.status[i] != kRayOk) continue;
    const T s = dz / rays.n[i];
    rays.x[i] = rays.x[i] + s * rays.l[i];
    rays.y[i] = rays.y[i] + s * rays.m[i];
    if (opl) (*opl)[i] = (*opl)[i] + n_image * s;
  }
}

}  // namespace detail

// The optical path (mm) from field h's incoming reference wavefront to ray i of `rays`, started
// on the entrance-pupil plane by start_rays (field h, wavelength w): OPL_0 of the header, the
// plane wave's x l + y m for an object at infinity, else the path from the sphere about the object
// point through the entrance-pupil centre. The one place a wavefront's optical path starts.
template <typename T>
T pupil_start_optical_path(const TraceSystem<T>& sys, int h, int w, const RayBundle<T>& rays,
                           std::size_t i) {
  using std::sqrt;
  if (sys.object_at_infinity()) return rays.x[i] * rays.l[i] + rays.y[i] * rays.m[i];
  const double y_o = sys.field_object_y_mm.empty() ? 0.0 : sys.field_object_y_mm[h];
  const T depth = sys.entrance_pupil_z_mm + K<T>(sys.object_distance_mm);  // D = z_EP + d
  const T x = rays.x[i], y = rays.y[i];
  const T dy = y - K<T>(y_o);
  const T to_p = sqrt(x * x + dy * dy + depth * depth);      // |P - O|
  const T to_e = sqrt(K<T>(y_o * y_o) + depth * depth);      // |E - O|
  const T difference = x * x + y * y - K<T>(2.0 * y_o) * y;  // |P-O|^2 - |E-O|^2
  return sys.lens.index(-1, w) * difference / (to_p + to_e);
}

// The reference sphere of field h (see the header), at the reference wavelength.
template <typename T>
ReferenceSphere<T> reference_sphere(const TraceSystem<T>& sys, int h, double focus_shift_mm = 0.0) {
  const int w_ref = sys.wavelength_count;
  PupilSamples centre;
  centre.x = {0.0};
  centre.y = {0.0};
  RayBundle<T> chief;
  start_rays(sys, h, w_ref, chief, &centre);
  trace_bundle(sys.lens, w_ref, sys.lens.surface_count(), true, chief,
               static_cast<RayRecord<T>*>(nullptr));
  detail::shift_focus<T>(chief, nullptr, K<T>(1.0), focus_shift_mm);
  ReferenceSphere<T> out;
  out.ok = chief.status[0] == kRayOk;
  out.centre_x_mm = chief.x[0];
  out.centre_y_mm = chief.y[0];
  const T z_xp =
      exit_pupil_from_image_mm(sys.lens, sys.lens.wavelengths_nm[w_ref]) - K<T>(focus_shift_mm);
  out.radius_mm = z_xp / chief.n[0];
  return out;
}

// The wavefront of one field and wavelength on a pupil grid.
template <typename T>
struct Wavefront {
  double wavelength_nm = 0;
  std::vector<T> opd_waves;      // per grid sample; W of the header (0 where !ok)
  std::vector<std::uint8_t> ok;  // the ray reached the reference sphere
  std::vector<T> image_x_mm;     // ray position on the image plane relative to C
  std::vector<T> image_y_mm;
  T piston_waves, tilt_x_waves, tilt_y_waves;  // the fitted a, b, c (per unit pupil coordinate)
  T rms_waves, pv_waves;                       // piston and tilt removed
  // Image-space direction cosines fitted as l = l0 + du_x x_p, m = m0 + du_y y_p: the scale from
  // pupil coordinates to the PSF's angular spectrum (du_y < 0 for a positive lens).
  double du_x = 0, du_y = 0;
  double valid_weight = 0;  // sum of the weights of the samples that arrived
  double total_weight = 0;  // sum of all weights (the unvignetted pupil area, in cells)
  bool chief_ok = false;
};

// W_i with the fitted piston and tilt removed (the residual the RMS and P-V are taken of).
template <typename T>
T tilt_removed_opd(const Wavefront<T>& wf, const PupilGrid& grid, std::size_t i) {
  return wf.opd_waves[i] - wf.piston_waves - wf.tilt_x_waves * K<T>(grid.samples.x[i]) -
         wf.tilt_y_waves * K<T>(grid.samples.y[i]);
}

// Traces the grid at field h, wavelength w (an index of sys.lens.wavelengths_nm) and returns
// its wavefront against `sphere` (reference_sphere of the same field and focus shift).
// `rays` and `record` are scratch (reused between calls).
template <typename T>
Wavefront<T> compute_wavefront(const TraceSystem<T>& sys, int h, int w, const PupilGrid& grid,
                               const ReferenceSphere<T>& sphere, double focus_shift_mm,
                               RayBundle<T>& rays, RayRecord<T>& record) {
  using std::sqrt;
  if (grid.mirrored && sys.full_pupil)
    throw Error(
        "a half pupil grid assumes a pupil symmetric about the meridional plane; this "
        "system (vignetting VDX or VAN, or no rotational symmetry: tilts, decenters, "
        "coordinate breaks) needs the full grid");
  const std::size_t count = grid.size();
  const int k_count = sys.lens.surface_count();
  // Grid samples and, last, the chief ray of this wavelength.
  PupilSamples samples = grid.samples;
  samples.x.push_back(0.0);
  samples.y.push_back(0.0);
  start_rays(sys, h, w, rays, &samples);
  record.resize(k_count, count + 1, true);
  for (std::size_t i = 0; i <= count; ++i)
    record.optical_path_mm[i] = pupil_start_optical_path(sys, h, w, rays, i);
  trace_bundle(sys.lens, w, k_count, true, rays, &record);
  const T n_image = sys.lens.index(k_count - 1, w);
  detail::shift_focus<T>(rays, &record.optical_path_mm, n_image, focus_shift_mm);

  Wavefront<T> out;
  out.wavelength_nm = sys.lens.wavelengths_nm[w];
  const T to_waves = K<T>(1e6 / out.wavelength_nm);  // mm -> waves
  const T zero = K<T>(0.0);
  out.opd_waves.assign(count, zero);
  out.ok.assign(count, 0);
  out.image_x_mm.assign(count, zero);
  out.image_y_mm.assign(count, zero);
  const T r = sphere.radius_mm;
  const T sign = value_of(r) < 0.0 ? K<T>(-1.0) : K<T>(1.0);
  auto opl_on_sphere = [&](std::size_t i, bool& good) {
    const T qx = rays.x[i] - sphere.centre_x_mm;
    const T qy = rays.y[i] - sphere.centre_y_mm;
    if (sphere.plane) {
      const T cos_to_normal =
          rays.l[i] * sphere.plane_l + rays.m[i] * sphere.plane_m + rays.n[i] * sphere.plane_n;
      good = rays.status[i] == kRayOk && value_of(cos_to_normal) > 0.0;
      if (!good) return zero;
      const T t = (r - (qx * sphere.plane_l + qy * sphere.plane_m)) / cos_to_normal;
      return record.optical_path_mm[i] + n_image * t;
    }
    const T b = qx * rays.l[i] + qy * rays.m[i];
    const T disc = b * b - (qx * qx + qy * qy) + r * r;
    good = rays.status[i] == kRayOk && value_of(disc) > 0.0;
    if (!good) return zero;
    const T t = -b + sign * sqrt(disc);
    return record.optical_path_mm[i] + n_image * t;
  };
  bool chief_good = false;
  const T chief_opl = opl_on_sphere(count, chief_good);
  out.chief_ok = chief_good && sphere.ok;
  // Least squares sums for piston and tilt (weights and coordinates are constants) and for the
  // direction-cosine scale.
  double s[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  T rhs[3] = {zero, zero, zero};
  double sl[4] = {0, 0, 0, 0}, sm[4] = {0, 0, 0, 0};  // sum a, sum a p, sum a p^2, sum a p d
  double sum_l = 0, sum_m = 0;
  for (std::size_t i = 0; i < count; ++i) {
    out.total_weight += grid.weight[i];
    if (!out.chief_ok) continue;
    bool good = false;
    const T opl = opl_on_sphere(i, good);
    if (!good) continue;
    out.ok[i] = 1;
    const T wv = (opl - chief_opl) * to_waves;
    out.opd_waves[i] = wv;
    out.image_x_mm[i] = rays.x[i] - sphere.centre_x_mm;
    out.image_y_mm[i] = rays.y[i] - sphere.centre_y_mm;
    const double a = grid.weight[i];
    const double px = grid.samples.x[i], py = grid.samples.y[i];
    const double basis[3] = {1.0, px, py};
    for (int u = 0; u < 3; ++u) {
      // A half grid: the mirror cancels every sum odd in x_p (x_p alone, x_p y_p, x_p W).
      for (int v = 0; v < 3; ++v)
        if (!grid.mirrored || (u == 1) == (v == 1)) s[u][v] += a * basis[u] * basis[v];
      if (!grid.mirrored || u != 1) rhs[u] = rhs[u] + K<T>(a * basis[u]) * wv;
    }
    out.valid_weight += a;
    const double l = value_of(rays.l[i]), m = value_of(rays.m[i]);
    if (!grid.mirrored) sl[1] += a * px;  // (and l is odd in x_p: sum a l = 0 mirrored)
    sl[2] += a * px * px;
    sl[3] += a * px * l;
    sm[1] += a * py;
    sm[2] += a * py * py;
    sm[3] += a * py * m;
    if (!grid.mirrored) sum_l += a * l;
    sum_m += a * m;
  }
  out.piston_waves = out.tilt_x_waves = out.tilt_y_waves = zero;
  out.rms_waves = out.pv_waves = zero;
  if (out.valid_weight <= 0.0) return out;
  const double sw = out.valid_weight;
  const double vx = sl[2] - sl[1] * sl[1] / sw, vy = sm[2] - sm[1] * sm[1] / sw;
  out.du_x = vx > 0 ? (sl[3] - sl[1] * sum_l / sw) / vx : 0.0;
  out.du_y = vy > 0 ? (sm[3] - sm[1] * sum_m / sw) / vy : 0.0;
  // Solve the 3 x 3 normal equations (double matrix, T right-hand side) by its inverse.
  const double det = s[0][0] * (s[1][1] * s[2][2] - s[1][2] * s[2][1]) -
                     s[0][1] * (s[1][0] * s[2][2] - s[1][2] * s[2][0]) +
                     s[0][2] * (s[1][0] * s[2][1] - s[1][1] * s[2][0]);
  T coef[3] = {rhs[0] / K<T>(sw), zero, zero};
  if (std::abs(det) > 1e-12 * sw * sw * sw) {
    double inv[3][3];
    for (int u = 0; u < 3; ++u)
      for (int v = 0; v < 3; ++v) {
        const int u1 = (v + 1) % 3, u2 = (v + 2) % 3, v1 = (u + 1) % 3, v2 = (u + 2) % 3;
        inv[u][v] = (s[u1][v1] * s[u2][v2] - s[u1][v2] * s[u2][v1]) / det;
      }
    for (int u = 0; u < 3; ++u)
      coef[u] = K<T>(inv[u][0]) * rhs[0] + K<T>(inv[u][1]) * rhs[1] + K<T>(inv[u][2]) * rhs[2];
  }
  out.piston_waves = coef[0];
  out.tilt_x_waves = coef[1];
  out.tilt_y_waves = coef[2];
  T sum_sq = zero;
  bool first = true;
  T lo = zero, hi = zero;
  for (std::size_t i = 0; i < count; ++i) {
    if (!out.ok[i]) continue;
    const T res = tilt_removed_opd(out, grid, i);
    sum_sq = sum_sq + K<T>(grid.weight[i]) * res * res;
    if (first || value_of(res) < value_of(lo)) lo = res;
    if (first || value_of(res) > value_of(hi)) hi = res;
    first = false;
  }
  const T var = sum_sq / K<T>(sw);
  out.rms_waves = value_of(var) > 0.0 ? sqrt(var) : zero;
  out.pv_waves = hi - lo;
  return out;
}

// The least-squares residuals of the RMS wavefront: r_i = sqrt(a_i / sum a) (W_i - piston - tilt)
// for every grid sample (0 where the ray did not arrive), so sum r_i^2 = rms_waves^2. The
// optimizer's wavefront merit (optimize/design_loss.h) uses them as its residuals: their Jets
// carry the exact Jacobian of the RMS wavefront.
template <typename T>
void rms_wavefront_residuals(const Wavefront<T>& wf, const PupilGrid& grid, T* residuals) {
  for (std::size_t i = 0; i < grid.size(); ++i) {
    if (!wf.ok[i] || !(wf.valid_weight > 0.0)) {
      residuals[i] = K<T>(0.0);
      continue;
    }
    residuals[i] =
        K<T>(std::sqrt(grid.weight[i] / wf.valid_weight)) * tilt_removed_opd(wf, grid, i);
  }
}

// The polychromatic RMS wavefront of field h (waves):
//   W_h = sqrt( sum_w omega_w RMS_{h,w}^2 / sum_w omega_w )
// over the spec wavelengths (omega: `weights`, empty = equal). `each` (may be null) is called
// with (w, wavefront) for every wavelength (the optimizer takes its residuals there).
template <typename T, typename Each>
T field_rms_wavefront(const TraceSystem<T>& sys, int h, const PupilGrid& grid,
                      const std::vector<double>& weights, RayBundle<T>& rays, RayRecord<T>& record,
                      Each&& each) {
  using std::sqrt;
  const ReferenceSphere<T> sphere = reference_sphere(sys, h);
  T sum = K<T>(0.0);
  double wsum = 0;
  for (int w = 0; w < sys.wavelength_count; ++w) {
    const double omega = weights.empty() ? 1.0 : weights[w];
    const Wavefront<T> wf = compute_wavefront(sys, h, w, grid, sphere, 0.0, rays, record);
    each(w, wf);
    sum = sum + K<T>(omega) * wf.rms_waves * wf.rms_waves;
    wsum += omega;
  }
  const T mean = sum / K<T>(wsum);
  return value_of(mean) > 0.0 ? sqrt(mean) : K<T>(0.0);
}

// The wavefront merit: mean over fields of the polychromatic RMS wavefront
//   W_h = sqrt( sum_w omega_w RMS_{h,w}^2 / sum_w omega_w )  (waves, piston and tilt removed)
// over the spec wavelengths (omega: `weights`, empty = equal). A field or wavelength whose
// chief ray fails counts as 0 (the optimizer's failure handling sees the failed rays).
template <typename T>
T mean_rms_wavefront(const TraceSystem<T>& sys, const PupilGrid& grid,
                     const std::vector<double>& weights = {}) {
  const int field_count = static_cast<int>(sys.fields_deg.size());
  RayBundle<T> rays;
  RayRecord<T> record;
  T total = K<T>(0.0);
  for (int h = 0; h < field_count; ++h)
    total = total + field_rms_wavefront(sys, h, grid, weights, rays, record,
                                        [](int, const Wavefront<T>&) {});
  return total / K<T>(field_count);
}

// compute_wavefront on double is compiled once, in src/analysis/wavefront_double.cpp, not in each
// object that measures a wavefront (BENCHMARKS.md "Build time, third round").
extern template Wavefront<double> compute_wavefront<double>(const TraceSystem<double>&, int, int,
                                                            const PupilGrid&,
                                                            const ReferenceSphere<double>&, double,
                                                            RayBundle<double>&, RayRecord<double>&);
// compute_wavefront on the Jets of core/jet_width.h (the wavefront merit's and the wavefront
// targets' Jacobians) is compiled once per width, in src/analysis/spot_jet.cpp.in (it was compiled
// in every file that differentiates a wavefront: the optimizer, five Jet files, six test files).
#define LENSOPT_COMPUTE_WAVEFRONT_JET(N)                                                        \
  extern template Wavefront<ceres::Jet<double, N>> compute_wavefront<ceres::Jet<double, N>>(    \
      const TraceSystem<ceres::Jet<double, N>>&, int, int, const PupilGrid&,                    \
      const ReferenceSphere<ceres::Jet<double, N>>&, double, RayBundle<ceres::Jet<double, N>>&, \
      RayRecord<ceres::Jet<double, N>>&);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_COMPUTE_WAVEFRONT_JET)
#undef LENSOPT_COMPUTE_WAVEFRONT_JET

}  // namespace lensopt
