// Reverse mode (adjoint) of the double ray-trace kernel (trace/kernel.h): the derivatives of one
// scalar of the traced rays with respect to every surface's parameters and every ray's start, at
// the cost of about one more trace, instead of one Jet component per variable.
//
// Forward, per surface k with curvature c, shift t (= t_{k-1}; 0 at k = 0) and mu = n/n' (the
// equations of kernel.h, every intermediate named):
//   zr = z - t,  s0 = -zr / n,  x1 = x + s0 l,  y1 = y + s0 m,
//   q = x1^2 + y1^2,  f = c q,  p = x1 l + y1 m,  g = n - c p,  zeta = g^2 - c f,
//   ci = sqrt(zeta),  s1 = f / (g + ci),  x2 = x1 + s1 l,  y2 = y1 + s1 m,  z2 = s1 n,
//   zeta' = 1 - mu^2 (1 - zeta),  gamma = sqrt(zeta') - mu ci,
//   l' = mu l - gamma c x2,  m' = mu m - gamma c y2,  n' = mu n + gamma (1 - c z2),
//   travel (the space before surface k) = z2 - zr.
// Image transfer with T = t_{K-1}: zr = z - T, s = -zr / n, X = x + s l, Y = y + s m,
// travel (last space) = -zr.
// Backward, with a_v the adjoint (dL/dv) of each quantity v, from a_x2 .. a_n' (the state after
// the surface) and the loss's own seeds a_travel, a_zeta, a_zeta' of this surface:
//   a_mu   = a_l' l + a_m' m + a_n' n,      a_gamma = -c (a_l' x2 + a_m' y2) + a_n' (1 - c z2),
//   a_c    = -gamma (a_l' x2 + a_m' y2 + a_n' z2),
//   a_x2  -= gamma c a_l',  a_y2 -= gamma c a_m',  a_z2 += a_travel - gamma c a_n',
//   a_l = mu a_l',  a_m = mu a_m',  a_n = mu a_n',
//   a_zeta' += a_gamma / (2 sqrt(zeta')),   a_mu -= a_gamma ci + 2 mu (1 - zeta) a_zeta',
//   a_ci = -mu a_gamma,  a_zeta += mu^2 a_zeta',
//   a_s1 = a_x2 l + a_y2 m + a_z2 n,  a_l += s1 a_x2,  a_m += s1 a_y2,  a_n += s1 a_z2,
//   a_f = a_s1 / (g + ci),  a_den = -a_s1 s1 / (g + ci),  a_g = a_den,  a_ci += a_den,
//   a_zeta += a_ci / (2 ci),  a_g += 2 g a_zeta,  a_c -= f a_zeta,  a_f -= c a_zeta,
//   a_n += a_g,  a_c -= p a_g,  a_p = -c a_g,  a_c += q a_f,  a_q = c a_f,
//   a_x1 = a_x2 + a_p l + 2 x1 a_q,  a_y1 = a_y2 + a_p m + 2 y1 a_q,  a_l += a_p x1,  a_m += a_p
//   y1, a_s0 = a_x1 l + a_y1 m,  a_l += s0 a_x1,  a_m += s0 a_y1, a_zr = -a_s0 / n - a_travel,  a_n
//   -= a_s0 s0 / n, a_x = a_x1,  a_y = a_y1,  a_z = a_zr,  a_t = -a_zr.
// Clamps of the forward pass are constants in the backward pass, as in the Jet trace: a miss
// (zeta < 0) traces on with zeta = 1 (no adjoint through zeta), total internal reflection with
// zeta' = zeta (a_zeta' flows into a_zeta instead). A ray is live at surface k when it had not
// failed before k (failed_surface < 0 or >= k); the adjoints of a ray not live are 0, so a
// failed ray contributes only the seeds of the surfaces up to the failing one (the design losses'
// records), and nothing that its clamped continuation computed.
// The parameter adjoints a_c, a_t, a_mu are sums over the rays (OpenMP simd reductions).
//
// Conic and even-asphere surfaces (trace/profile.h). Forward, with the converged path s from
// the vertex plane (taped: AdjointTape::path) and the profile S(rho), S'(rho) of profile.h:
//   zr, s0, x1, y1 as above,  x2 = x1 + s l,  y2 = y1 + s m,  z2 = s n,  rho = x2^2 + y2^2,
//   g(s) = s n - S(rho) = 0,  g' = n - 2 S' (x2 l + y2 m),
//   px = -2 S' x2,  py = -2 S' y2,  w = px^2 + py^2 + 1,  N = (px, py, 1) / sqrt(w),
//   ci = d . N (failed: ci <= 0, taken as 1),  zeta = ci^2,  zeta', gamma, d' as above with
//   N for (-c x2, -c y2, 1 - c z2); travel = z2 - zr.
// (A conic is the even asphere with a = 0: its closed-form normal (-c x, -c y, 1 - c (1+k) z)
// is the same unit vector, since 1 - c (1+k) z = q on the surface.)
// Backward: as for the sphere through d', gamma, zeta', zeta and ci (a_ci = 0 for a failed
// ray); then a_N -> a_px, a_py (through w) -> a_S' = -2 (a_px x2 + a_py y2), a_x2 -= 2 S' a_px,
// a_y2 -= 2 S' a_py; S'(rho; c, k, a) gives a_rho, a_c, a_k, a_a; a_x2 += 2 x2 a_rho, ....
// The path s by implicit differentiation at the converged point (ds/dp = -g_p / g'), with
// a_s = a_x2 l + a_y2 m + a_z2 n and lambda = a_s / g':
//   a_n -= lambda s,  a_x1 += 2 lambda S' x2,  a_y1 += 2 lambda S' y2,  a_l += 2 lambda S' x2 s,
//   a_m += 2 lambda S' y2 s,  a_c += lambda dS/dc,  a_k += lambda dS/dk,  a_a2i += lambda rho^i,
//   dS/dc = rho / (q (1 + q)),  dS/dk = c^3 rho^2 / (2 q (1 + q)^2),
//   dS'/drho = (1+k) c^3 / (4 q^3) + P'',  dS'/dc = 1 / (2 q) + (1+k) c^2 rho / (2 q^3),
//   dS'/dk = c^3 rho / (4 q^3),  dS'/da2i = i rho^(i-1).
// A ray whose intersection missed (taped path NaN) has s = 0, a constant, as in the Jet trace.
//
// Clear apertures and obscurations are masks: a ray outside (inside) fails there
// (kRayVignetted) and is then live up to that surface, like any failed ray, as in the Jets.
// Mirrors are refraction with mu = n / (-n) (kernel.h): the equations above unchanged.
// The placed path (kernel.h, trace_bundle_placed: 3D placements, coordinate breaks, field
// frames): for fixed tilts every frame change is affine in the ray, so its backward step is the
// transpose of its linear part. With R the surface's rotation and D its decenter:
//   to_local   p' = R^T (p - D) or R^T p - D, d' = R^T d:   a_p = R a_p', a_d = R a_d',
//              a_D -= a_p (decenter first) or a_p' (tilt first), in x and y;
//   to_parent  p = D + R p' or R (D + p'), d = R d':        a_p' = R^T a_p, a_d' = R^T a_d,
//              a_D += a_p (decenter first) or a_p' (tilt first);
//   the field frame's turn about z (an orthogonal map): its transpose is the opposite turn;
//   the shift z -= t_{k-1} before a moved surface or a coordinate break, in the parent frame:
//              a_t_{k-1} -= a_z there (the surface's own a_zr then belongs to its frame);
//   a coordinate break's recorded travel t_{k-1}: a_t_{k-1} += a_travel;
//   a ray that the kernel turns to (0, 0, 1) travelling backwards (AdjointTape::turned_back):
//              its direction adjoints are 0 before that surface.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "lensopt/trace/kernel.h"

namespace lensopt {

// The forward states of one bundle: the state (x, y, z, l, m, n) of every ray before each
// surface k = 0..K-1 and before the image transfer (k = K). Reused between bundles (no
// allocation once sized).
struct AdjointTape {
  int surfaces = 0;
  std::size_t count = 0;
  std::vector<double> state;  // [(k * 6 + component) * count + ray]
  // The path s from the vertex plane at each conic or asphere surface ([k * count + ray], NaN
  // where the intersection missed); empty for an all-spherical lens.
  std::vector<double> path;
  // The placed path (3D placements): per ray, the surface before which the kernel found it
  // travelling backwards and set its direction to the constant (0, 0, 1), the ray's first
  // failure (kRayBackwards); -1 if none. Empty on the rotationally symmetric path.
  std::vector<std::int8_t> turned_back;

  void resize(int surface_count, std::size_t ray_count, bool profiles = false) {
    surfaces = surface_count;
    count = ray_count;
    state.resize(static_cast<std::size_t>(surface_count + 1) * 6 * ray_count);
    path.resize(profiles ? static_cast<std::size_t>(surface_count) * ray_count : 0);
    turned_back.clear();
  }
  const double* at(int k, int component) const {
    return state.data() + (static_cast<std::size_t>(k) * 6 + component) * count;
  }
  double* at(int k, int component) {
    return state.data() + (static_cast<std::size_t>(k) * 6 + component) * count;
  }
};

// Seeds of the backward pass of one bundle: adjoints of the image coordinates and, optionally,
// of the records ([surface or space][ray], as RayRecord). Null entries are zero seeds.
struct AdjointSeeds {
  const double* x_image = nullptr;
  const double* y_image = nullptr;
  const std::vector<std::vector<double>>* travel = nullptr;      // K spaces
  const std::vector<std::vector<double>>* zeta = nullptr;        // K surfaces
  const std::vector<std::vector<double>>* zeta_prime = nullptr;  // K surfaces
};

// Parameter adjoints of one bundle, accumulated (+=): per surface k the curvature, the thickness
// t_k (the shift of surface k+1; for k = K-1 the image distance), mu_k at the bundle's
// wavelength, the conic constant and the asphere terms (0 at spheres), the decenter (x, y) of a
// placed surface (0 elsewhere; tilts are constants of the backward pass); per ray the start
// position and direction, in the field's frame.
struct BundleAdjoint {
  std::vector<double> curvature;   // K
  std::vector<double> thickness;   // K
  std::vector<double> mu;          // K
  std::vector<double> conic;       // K
  std::vector<double> asphere;     // K * kAsphereTerms (a2, a4, ..., a16)
  std::vector<double> decenter;    // K * 2: x, y
  std::vector<double> x0, y0, z0;  // per ray (overwritten, not accumulated)
  std::vector<double> l0, m0, n0;  // per ray, the start direction (overwritten)

  void reset(int surface_count) {
    curvature.assign(surface_count, 0.0);
    thickness.assign(surface_count, 0.0);
    mu.assign(surface_count, 0.0);
    conic.assign(surface_count, 0.0);
    asphere.assign(static_cast<std::size_t>(surface_count) * kAsphereTerms, 0.0);
    decenter.assign(static_cast<std::size_t>(surface_count) * 2, 0.0);
  }
};

// trace_bundle(lens, w, K, true, rays, record) in double, keeping the forward states in `tape`.
// Same results, bit for bit.
void trace_bundle_taped(const TraceLens<double>& lens, int w, RayBundle<double>& rays,
                        RayRecord<double>* record, AdjointTape& tape);

// The backward pass of a bundle traced by trace_bundle_taped (`rays` holds its final state and
// status): accumulates the parameter adjoints of `seeds` into `out` (out.reset first) and sets
// out.x0, y0, z0 and l0, m0, n0 to the adjoints of each ray's start position and direction.
void trace_bundle_adjoint(const TraceLens<double>& lens, int w, const RayBundle<double>& rays,
                          const AdjointTape& tape, const AdjointSeeds& seeds, BundleAdjoint& out);

namespace detail {

// The backward pass of one surface for every ray (equations of the header). state: the 6
// forward arrays before the surface; a[6]: in, the adjoints of the state after it; out, of the
// state before it. sums[3] += (a_c, a_t, a_mu) summed over rays.
void trace_surface_adjoint_double(double c, double mu, int k, std::size_t count,
                                  const double* const state[6], const std::int8_t* failed_surface,
                                  double* const a[6], const double* travel_seed,
                                  const double* zeta_seed, const double* zeta_prime_seed,
                                  double sums[3]);

// The same for a conic or even-asphere surface (equations of the header): a = its a2..a16,
// path = the taped s of this surface; sums[12] += (a_c, a_t, a_mu, a_k, a_a2, ..., a_a16).
void trace_surface_adjoint_profile_double(double c, double conic, const double* a, double mu, int k,
                                          std::size_t count, const double* const state[6],
                                          const double* path, const std::int8_t* failed_surface,
                                          double* const adjoint[6], const double* travel_seed,
                                          const double* zeta_seed, const double* zeta_prime_seed,
                                          double sums[12]);

}  // namespace detail

}  // namespace lensopt
