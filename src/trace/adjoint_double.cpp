// The adjoint (reverse-mode) double ray-trace kernel (trace/adjoint.h), built like the forward
// kernel for several x86-64 levels (GCC target_clones).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "lensopt/trace/adjoint.h"

namespace lensopt {
namespace detail {
namespace {

// Pieces shared by the sphere and profile kernels below; always inlined into their SIMD loops.
#define LENSOPT_ADJOINT_INLINE inline __attribute__((always_inline))

// Snell's law at the surface, forward again (trace/kernel.h): zeta = cos^2 i (ci = cos i),
// zeta' = 1 - mu^2 (1 - zeta), taken as zeta on total internal reflection; gamma = sqrt(zeta') -
// mu cos i, the step along the normal.
struct Refraction {
  bool tir;
  double sp;  // sqrt(zeta')
  double gamma;
};
LENSOPT_ADJOINT_INLINE Refraction refraction(double mu, double mu2, double zeta, double ci) {
  const double zp_raw = 1.0 - mu2 * (1.0 - zeta);
  const bool tir = zp_raw < 0.0;
  const double sp = std::sqrt(tir ? zeta : zp_raw);
  return {tir, sp, sp - mu * ci};
}

// The adjoint seeds of ray i after the surface (0 for a ray that failed before it): direction,
// travel, and the records' zeta and zeta'. Every seed array holds `count` values (the kernels
// replace a null seed by zeros: or_zeros): loaded unconditionally, so the ray loop has no branch
// and vectorizes (a load under `live && pointer` kept it scalar, about 8x slower with AVX-512).
struct ExitSeeds {
  double l, m, n, travel, zeta, zeta_prime;
};
LENSOPT_ADJOINT_INLINE ExitSeeds exit_seeds(bool live, std::size_t i, const double* al,
                                            const double* am, const double* an,
                                            const double* travel_seed, const double* zeta_seed,
                                            const double* zeta_prime_seed) {
  const double l = al[i], m = am[i], n = an[i];
  const double travel = travel_seed[i], zeta = zeta_seed[i], zeta_prime = zeta_prime_seed[i];
  return {live ? l : 0.0,      live ? m : 0.0,    live ? n : 0.0,
          live ? travel : 0.0, live ? zeta : 0.0, live ? zeta_prime : 0.0};
}

// A seed array, or `count` zeros for a null one (a buffer of this thread, reused).
const double* or_zeros(const double* seed, std::size_t count) {
  if (seed) return seed;
  thread_local std::vector<double> zeros;
  if (zeros.size() < count) zeros.assign(count, 0.0);
  return zeros.data();
}

// Scratch of this thread for `terms` per-ray sums of `count` rays each (reused).
double* ray_sums(std::size_t count, int terms) {
  thread_local std::vector<double> scratch;
  const std::size_t size = count * static_cast<std::size_t>(terms);
  if (scratch.size() < size) scratch.resize(size);
  return scratch.data();
}

// The transfer from the taped point (x, y, zr) to the vertex plane, x1 = x + s0 l, y1 = y + s0 m,
// s0 = -zr / n, backward from the adjoints of (x1, y1); adds to those of (l, m, n), stores ray i's
// adjoint of the taped state (0 if not live) and returns that of zr.
LENSOPT_ADJOINT_INLINE double vertex_transfer_backward(bool live, std::size_t i, double a_x1,
                                                       double a_y1, double s0, double l, double m,
                                                       double n, double a_travel, double& a_l,
                                                       double& a_m, double& a_n, double* ax,
                                                       double* ay, double* az, double* al,
                                                       double* am, double* an) {
  const double a_s0 = a_x1 * l + a_y1 * m;
  a_l += s0 * a_x1;
  a_m += s0 * a_y1;
  const double a_zr = -a_s0 / n - a_travel;
  a_n -= a_s0 * s0 / n;
  ax[i] = live ? a_x1 : 0.0;
  ay[i] = live ? a_y1 : 0.0;
  az[i] = live ? a_zr : 0.0;
  al[i] = live ? a_l : 0.0;
  am[i] = live ? a_m : 0.0;
  an[i] = live ? a_n : 0.0;
  return a_zr;
}

}  // namespace

namespace {

// The ray loop of trace_surface_adjoint_double (restrict parameters, so that it vectorizes in
// each target clone); per ray: the state adjoints in place and ray_c, ray_t, ray_mu.
LENSOPT_ADJOINT_INLINE void sphere_adjoint_rays(
    double c, double mu, int k, std::size_t count, const double* __restrict px,
    const double* __restrict py, const double* __restrict pz, const double* __restrict pl,
    const double* __restrict pm, const double* __restrict pn, const std::int8_t* __restrict fs,
    double* __restrict ax, double* __restrict ay, double* __restrict az, double* __restrict al,
    double* __restrict am, double* __restrict an, const double* __restrict travel_seed,
    const double* __restrict zeta_seed, const double* __restrict zeta_prime_seed,
    double* __restrict ray_c, double* __restrict ray_t, double* __restrict ray_mu) {
  const double mu2 = mu * mu;
  // Every array is distinct (GCC otherwise wants more run-time alias checks than it makes).
#pragma GCC ivdep
  for (std::size_t i = 0; i < count; ++i) {
    // fs < 0 (never failed) or fs >= k, as one unsigned comparison (a vector mask).
    const bool live = static_cast<unsigned>(fs[i]) >= static_cast<unsigned>(k);
    // Forward again from the taped state (its z is already relative to vertex k: zr).
    const double x = px[i], y = py[i], zr = pz[i], l = pl[i], m = pm[i], n = pn[i];
    const double s0 = -zr / n;
    const double x1 = x + s0 * l;
    const double y1 = y + s0 * m;
    const double q = x1 * x1 + y1 * y1;
    const double f = c * q;
    const double p = x1 * l + y1 * m;
    const double g = n - c * p;
    const double zeta_raw = g * g - c * f;
    const bool miss = zeta_raw < 0.0;
    const double zeta = miss ? 1.0 : zeta_raw;
    const double ci = std::sqrt(zeta);
    const double den = g + ci;
    const double s1 = f / den;
    const double x2 = x1 + s1 * l;
    const double y2 = y1 + s1 * m;
    const double z2 = s1 * n;
    const Refraction r = refraction(mu, mu2, zeta, ci);
    const bool tir = r.tir;
    const double sp = r.sp, gamma = r.gamma;
    // Backward.
    const ExitSeeds e = exit_seeds(live, i, al, am, an, travel_seed, zeta_seed, zeta_prime_seed);
    const double a_l_out = e.l, a_m_out = e.m, a_n_out = e.n;
    const double a_travel = e.travel, a_zeta_seed = e.zeta, a_zp_seed = e.zeta_prime;
    double a_mu = a_l_out * l + a_m_out * m + a_n_out * n;
    const double a_gamma = -c * (a_l_out * x2 + a_m_out * y2) + a_n_out * (1.0 - c * z2);
    double a_c = -gamma * (a_l_out * x2 + a_m_out * y2 + a_n_out * z2);
    const double gc = gamma * c;
    const double ax_out = ax[i], ay_out = ay[i], az_out = az[i];  // loaded unconditionally
    const double a_x2 = (live ? ax_out : 0.0) - gc * a_l_out;
    const double a_y2 = (live ? ay_out : 0.0) - gc * a_m_out;
    const double a_z2 = (live ? az_out : 0.0) + a_travel - gc * a_n_out;
    double a_l = mu * a_l_out;
    double a_m = mu * a_m_out;
    double a_n = mu * a_n_out;
    // sqrt(zeta') of the refraction; on total internal reflection it is sqrt(zeta).
    const double a_zp_used = a_gamma / (2.0 * sp);
    const double a_zp_raw = a_zp_seed + (tir ? 0.0 : a_zp_used);
    double a_zeta = (tir ? a_zp_used : 0.0) + mu2 * a_zp_raw;
    a_mu = a_mu - a_gamma * ci - 2.0 * mu * (1.0 - zeta) * a_zp_raw;
    double a_ci = -mu * a_gamma;
    // The intersection.
    const double a_s1 = a_x2 * l + a_y2 * m + a_z2 * n;
    a_l += s1 * a_x2;
    a_m += s1 * a_y2;
    a_n += s1 * a_z2;
    double a_f = a_s1 / den;
    const double a_den = -a_s1 * s1 / den;
    double a_g = a_den;
    a_ci += a_den;
    a_zeta += a_ci / (2.0 * ci);
    // A miss traced on with the constant zeta = 1: only the record's seed reaches zeta_raw.
    const double a_zeta_raw = a_zeta_seed + (miss ? 0.0 : a_zeta);
    a_g += 2.0 * g * a_zeta_raw;
    a_c -= f * a_zeta_raw;
    a_f -= c * a_zeta_raw;
    a_n += a_g;
    a_c -= p * a_g;
    const double a_p = -c * a_g;
    a_c += q * a_f;
    const double a_q = c * a_f;
    const double a_x1 = a_x2 + a_p * l + 2.0 * x1 * a_q;
    const double a_y1 = a_y2 + a_p * m + 2.0 * y1 * a_q;
    a_l += a_p * x1;
    a_m += a_p * y1;
    const double a_zr = vertex_transfer_backward(live, i, a_x1, a_y1, s0, l, m, n, a_travel, a_l,
                                                 a_m, a_n, ax, ay, az, al, am, an);
    ray_c[i] = live ? a_c : 0.0;
    ray_t[i] = live ? -a_zr : 0.0;
    ray_mu[i] = live ? a_mu : 0.0;
  }
}

}  // namespace

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#endif
void trace_surface_adjoint_double(double c, double mu, int k, std::size_t count,
                                  const double* const state[6], const std::int8_t* failed_surface,
                                  double* const a[6], const double* travel_seed,
                                  const double* zeta_seed, const double* zeta_prime_seed,
                                  double sums[3]) {
  // Each live ray's a_c, a_t and a_mu, summed after the loop in ray order: a loop without a
  // reduction vectorizes (an `omp simd` reduction left it scalar in the target clones).
  double* ray_c = ray_sums(count, 3);
  double* ray_t = ray_c + count;
  double* ray_mu = ray_t + count;
  sphere_adjoint_rays(c, mu, k, count, state[0], state[1], state[2], state[3], state[4], state[5],
                      failed_surface, a[0], a[1], a[2], a[3], a[4], a[5],
                      or_zeros(travel_seed, count), or_zeros(zeta_seed, count),
                      or_zeros(zeta_prime_seed, count), ray_c, ray_t, ray_mu);
  double sum_c = 0.0, sum_t = 0.0, sum_mu = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    sum_c += ray_c[i];
    sum_t += ray_t[i];
    sum_mu += ray_mu[i];
  }
  sums[0] += sum_c;
  sums[1] += sum_t;
  sums[2] += sum_mu;
}

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#endif
void trace_surface_adjoint_profile_double(double c, double conic, const double* a, double mu,
                                          int k, std::size_t count, const double* const state[6],
                                          const double* path, const std::int8_t* failed_surface,
                                          double* const adjoint[6], const double* travel_seed,
                                          const double* zeta_seed, const double* zeta_prime_seed,
                                          double sums[12]) {
  const double* __restrict px_in = state[0];
  const double* __restrict py_in = state[1];
  const double* __restrict pz = state[2];
  const double* __restrict pl = state[3];
  const double* __restrict pm = state[4];
  const double* __restrict pn = state[5];
  const double* __restrict ps = path;
  double* __restrict ax = adjoint[0];
  double* __restrict ay = adjoint[1];
  double* __restrict az = adjoint[2];
  double* __restrict al = adjoint[3];
  double* __restrict am = adjoint[4];
  double* __restrict an = adjoint[5];
  const std::int8_t* __restrict fs = failed_surface;
  travel_seed = or_zeros(travel_seed, count);
  zeta_seed = or_zeros(zeta_seed, count);
  zeta_prime_seed = or_zeros(zeta_prime_seed, count);
  const double opk = 1.0 + conic;
  const double mu2 = mu * mu;
  const double a0 = a[0], a1 = a[1], a2 = a[2], a3 = a[3], a4 = a[4], a5 = a[5], a6 = a[6],
               a7 = a[7];
  const double coeff[8] = {a0, a1, a2, a3, a4, a5, a6, a7};
  double sum_c = 0.0, sum_t = 0.0, sum_mu = 0.0, sum_k = 0.0;
  double s0_ = 0.0, s1_ = 0.0, s2_ = 0.0, s3_ = 0.0, s4_ = 0.0, s5_ = 0.0, s6_ = 0.0, s7_ = 0.0;
#pragma omp simd reduction(+ : sum_c, sum_t, sum_mu, sum_k, s0_, s1_, s2_, s3_, s4_, s5_, s6_, s7_)
  for (std::size_t i = 0; i < count; ++i) {
    const bool live = fs[i] < 0 || fs[i] >= k;
    // Forward again from the taped state and path.
    const double x = px_in[i], y = py_in[i], zr = pz[i], l = pl[i], m = pm[i], n = pn[i];
    const bool miss = !(ps[i] == ps[i]);  // NaN: the intersection missed
    const bool run = live & !miss;
    const double s = run ? ps[i] : 0.0;
    const double s0 = -zr / n;
    const double x1 = x + s0 * l;
    const double y1 = y + s0 * m;
    const double x2 = x1 + s * l;
    const double y2 = y1 + s * m;
    const double rho_raw = x2 * x2 + y2 * y2;
    const double q2_raw = profile_q2(c, opk, rho_raw);
    // Rays not followed (missed, not live) are evaluated on the axis (their results unused).
    const double rho = (run & (q2_raw > 0.0)) ? rho_raw : 0.0;
    const double q = std::sqrt(profile_q2(c, opk, rho));
    // rho P(rho) = sum a_i rho^(i+1): d1 = its first, d2 its second derivative in rho.
    const double d1 = asphere_poly_slope(coeff, rho);  // lens/profile_sag.h
    const double d2 =
        2.0 * a1 +
        rho * (6.0 * a2 +
               rho * (12.0 * a3 +
                      rho * (20.0 * a4 + rho * (30.0 * a5 + rho * (42.0 * a6 + rho * 56.0 * a7)))));
    const double inv_q = 1.0 / q;
    const double slope = 0.5 * c * inv_q + d1;  // S'
    const double nx_raw = -2.0 * slope * x2;
    const double ny_raw = -2.0 * slope * y2;
    const double inv = 1.0 / std::sqrt(nx_raw * nx_raw + ny_raw * ny_raw + 1.0);
    const double nx = nx_raw * inv, ny = ny_raw * inv, nz = inv;
    const double cos_raw = miss ? 0.0 : l * nx + m * ny + n * nz;
    const bool failed = !(cos_raw > 0.0);
    const double ci = failed ? 1.0 : cos_raw;
    const double zeta = ci * ci;
    const Refraction r = refraction(mu, mu2, zeta, ci);
    const bool tir = r.tir;
    const double sp = r.sp, gamma = r.gamma;
    // Backward: the refraction.
    const ExitSeeds e = exit_seeds(live, i, al, am, an, travel_seed, zeta_seed, zeta_prime_seed);
    const double a_l_out = e.l, a_m_out = e.m, a_n_out = e.n;
    const double a_travel = e.travel, a_zeta_seed = e.zeta, a_zp_seed = e.zeta_prime;
    double a_mu = a_l_out * l + a_m_out * m + a_n_out * n;
    const double a_gamma = a_l_out * nx + a_m_out * ny + a_n_out * nz;
    double a_nx = gamma * a_l_out;
    double a_ny = gamma * a_m_out;
    double a_nz = gamma * a_n_out;
    double a_l = mu * a_l_out;
    double a_m = mu * a_m_out;
    double a_n = mu * a_n_out;
    const double a_zp_used = a_gamma / (2.0 * sp);
    const double a_zp_raw = a_zp_seed + (tir ? 0.0 : a_zp_used);
    double a_zeta = (tir ? a_zp_used : 0.0) + mu2 * a_zp_raw + (failed ? 0.0 : a_zeta_seed);
    a_mu = a_mu - a_gamma * ci - 2.0 * mu * (1.0 - zeta) * a_zp_raw;
    // ci = d . N (a constant for a failed ray).
    const double a_ci = failed ? 0.0 : -mu * a_gamma + 2.0 * ci * a_zeta;
    a_l += a_ci * nx;
    a_m += a_ci * ny;
    a_n += a_ci * nz;
    a_nx += a_ci * l;
    a_ny += a_ci * m;
    a_nz += a_ci * n;
    // The unit normal (px, py, 1) / sqrt(w).
    const double a_inv = a_nx * nx_raw + a_ny * ny_raw + a_nz;
    const double a_w = -0.5 * a_inv * inv * inv * inv;
    const double a_px = a_nx * inv + 2.0 * nx_raw * a_w;
    const double a_py = a_ny * inv + 2.0 * ny_raw * a_w;
    const double a_slope = run ? -2.0 * (a_px * x2 + a_py * y2) : 0.0;
    double a_x2 = (live ? ax[i] : 0.0) - 2.0 * slope * a_px;
    double a_y2 = (live ? ay[i] : 0.0) - 2.0 * slope * a_py;
    const double a_z2 = (live ? az[i] : 0.0) + a_travel;
    // S'(rho; c, k, a).
    const double inv_q3 = inv_q * inv_q * inv_q;
    const double a_rho = a_slope * (0.25 * opk * c * c * c * inv_q3 + d2);
    double a_c = a_slope * (0.5 * inv_q + 0.5 * opk * c * c * rho * inv_q3);
    double a_k = a_slope * 0.25 * c * c * c * rho * inv_q3;
    a_x2 += 2.0 * x2 * a_rho;
    a_y2 += 2.0 * y2 * a_rho;
    // The path s, by implicit differentiation of g(s) = s n - S(rho(s)) = 0.
    const double a_s = a_x2 * l + a_y2 * m + a_z2 * n;
    a_l += s * a_x2;
    a_m += s * a_y2;
    a_n += s * a_z2;
    const double dg = n - 2.0 * slope * (x2 * l + y2 * m);
    const double lambda = run ? a_s / dg : 0.0;
    const double two_ls = 2.0 * lambda * slope;
    a_n -= lambda * s;
    const double a_x1 = a_x2 + two_ls * x2;
    const double a_y1 = a_y2 + two_ls * y2;
    a_l += two_ls * x2 * s;
    a_m += two_ls * y2 * s;
    const double one_q = 1.0 + q;
    a_c += lambda * rho * inv_q / one_q;
    a_k += lambda * 0.5 * c * c * c * rho * rho * inv_q / (one_q * one_q);
    // The asphere terms: dS'/da_i = (i+1) rho^i (a_slope), dS/da_i = rho^(i+1) (lambda).
    double power = 1.0;
    double a_a[8];
    for (int j = 0; j < 8; ++j) {
      a_a[j] = (a_slope * (j + 1.0) + lambda * rho) * power;
      power *= rho;
    }
    const double a_zr = vertex_transfer_backward(live, i, a_x1, a_y1, s0, l, m, n, a_travel, a_l,
                                                 a_m, a_n, ax, ay, az, al, am, an);
    sum_c += live ? a_c : 0.0;
    sum_t += live ? -a_zr : 0.0;
    sum_mu += live ? a_mu : 0.0;
    sum_k += live ? a_k : 0.0;
    s0_ += live ? a_a[0] : 0.0;
    s1_ += live ? a_a[1] : 0.0;
    s2_ += live ? a_a[2] : 0.0;
    s3_ += live ? a_a[3] : 0.0;
    s4_ += live ? a_a[4] : 0.0;
    s5_ += live ? a_a[5] : 0.0;
    s6_ += live ? a_a[6] : 0.0;
    s7_ += live ? a_a[7] : 0.0;
  }
  sums[0] += sum_c;
  sums[1] += sum_t;
  sums[2] += sum_mu;
  sums[3] += sum_k;
  sums[4] += s0_;
  sums[5] += s1_;
  sums[6] += s2_;
  sums[7] += s3_;
  sums[8] += s4_;
  sums[9] += s5_;
  sums[10] += s6_;
  sums[11] += s7_;
}

}  // namespace detail

namespace {

// Surface k's step 5 (kernel.h): the clear aperture and the obscuration about (cx, cy), as
// failure masks.
void aperture_masks(const TraceLens<double>& lens, int k, double cx, double cy, std::size_t count,
                    const double* x, const double* y, std::int32_t* failure) {
  if (!lens.semi_diameter_mm.empty() && lens.semi_diameter_mm[k] > 0.0) {
    const double limit = lens.semi_diameter_mm[k] * lens.semi_diameter_mm[k];
    for (std::size_t i = 0; i < count; ++i) {
      const double dx = x[i] - cx, dy = y[i] - cy;
      const bool outside = dx * dx + dy * dy > limit;
      failure[i] = (outside && failure[i] == kRayOk) ? std::int32_t{kRayVignetted} : failure[i];
    }
  }
  const TraceGeometry<double>& g = lens.geometry;
  if (!g.obscuration_mm.empty() && g.obscuration_mm[k] > 0.0)
    detail::obscure(g.obscuration_mm[k], cx, cy, count, x, y, failure);
}

// Surface k's steps 2-4 (the sphere or the profile loop), taping the profile's path.
void intersect_taped(const TraceLens<double>& lens, int k, double c, double shift, double mu,
                     std::size_t count, double* x, double* y, double* z, double* l, double* m,
                     double* n, std::int32_t* failure, RayRecord<double>* record,
                     AdjointTape& tape) {
  double* travel = record && k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr;
  double* zeta = record ? record->cos2_incidence[k].data() : nullptr;
  double* zeta_prime = record ? record->cos2_refraction[k].data() : nullptr;
  const std::uint8_t profile = lens.has_profiles() ? lens.profile[k] : kProfileSphere;
  if (profile != kProfileSphere) {
    detail::trace_surface_profile_double(
        profile, c, lens.conic[k],
        lens.asphere.data() + static_cast<std::size_t>(k) * kAsphereTerms, shift, mu, count, x, y,
        z, l, m, n, failure, travel, zeta, zeta_prime, record != nullptr,
        tape.path.data() + static_cast<std::size_t>(k) * count);
  } else {
    detail::trace_surface_double(c, shift, mu, count, x, y, z, l, m, n, failure, travel, zeta,
                                 zeta_prime, record != nullptr);
  }
}

// The state of every ray before surface k into the tape, z relative to the vertex (the shift
// applied), so the backward pass needs no shift (a_t = -a_zr there).
void save_state(AdjointTape& tape, int k, double shift, const RayBundle<double>& rays) {
  const std::size_t count = rays.size();
  const std::size_t bytes = count * sizeof(double);
  double* tz = tape.at(k, 2);
  const double* z = rays.z.data();
  for (std::size_t i = 0; i < count; ++i) tz[i] = z[i] - shift;
  std::memcpy(tape.at(k, 0), rays.x.data(), bytes);
  std::memcpy(tape.at(k, 1), rays.y.data(), bytes);
  std::memcpy(tape.at(k, 3), rays.l.data(), bytes);
  std::memcpy(tape.at(k, 4), rays.m.data(), bytes);
  std::memcpy(tape.at(k, 5), rays.n.data(), bytes);
}

// The first failure of a ray wins.
void take_failures(int k, std::size_t count, const std::int32_t* failure, std::uint8_t* status,
                   std::int8_t* failed_at) {
  for (std::size_t i = 0; i < count; ++i) {
    if (failure[i] != kRayOk && status[i] == kRayOk) {
      status[i] = static_cast<std::uint8_t>(failure[i]);
      failed_at[i] = static_cast<std::int8_t>(k);
    }
  }
}

// detail::trace_bundle_placed (kernel.h) in double, taping: the same operations in the same
// order, so the same bits.
void trace_bundle_taped_placed(const TraceLens<double>& lens, int w, RayBundle<double>& rays,
                               RayRecord<double>* record, AdjointTape& tape) {
  const std::size_t count = rays.size();
  const int k_count = lens.surface_count();
  tape.resize(k_count, count, lens.has_profiles());
  tape.turned_back.assign(count, -1);
  double* x = rays.x.data();
  double* y = rays.y.data();
  double* z = rays.z.data();
  double* l = rays.l.data();
  double* m = rays.m.data();
  double* n = rays.n.data();
  std::uint8_t* status = rays.status.data();
  std::int8_t* failed_at = rays.failed_surface.data();
  rays.failure_scratch.resize(count);
  std::int32_t* failure = rays.failure_scratch.data();
  const TraceGeometry<double>& g = lens.geometry;
  if (rays.turned()) detail::turn_about_z(rays.frame_cos, rays.frame_sin, count, x, y, l, m);
  auto check_forward = [&](int k) {
    if (detail::all_forward(n, count)) return;
    for (std::size_t i = 0; i < count; ++i) {
      if (!(n[i] > 0.0)) {
        if (status[i] == kRayOk) {
          status[i] = kRayBackwards;
          failed_at[i] = static_cast<std::int8_t>(k);
          tape.turned_back[i] = static_cast<std::int8_t>(k);
        }
        l[i] = 0.0;
        m[i] = 0.0;
        n[i] = 1.0;
      }
    }
  };
  for (int k = 0; k < k_count; ++k) {
    const std::uint8_t flags = g.flags[k];
    double shift = k > 0 ? lens.thickness_mm[k - 1] : 0.0;
    if (flags & kPlacementMoved) {
      for (std::size_t i = 0; i < count; ++i) z[i] = z[i] - shift;
      shift = 0.0;
      detail::to_local(detail::placement_frame(g, k), count, x, y, z, l, m, n);
    }
    if (flags & kPlacementCoordinateBreak) {
      for (std::size_t i = 0; i < count; ++i) z[i] = z[i] - shift;
      if (record) {
        if (k > 0)
          for (double& v : record->axial_travel_mm[k - 1]) v = lens.thickness_mm[k - 1];
        for (double& v : record->cos2_incidence[k]) v = 1.0;
        for (double& v : record->cos2_refraction[k]) v = 1.0;
      }
      continue;
    }
    check_forward(k);
    const double c = lens.curvature_per_mm[k];
    const double mu = lens.index(k - 1, w) / lens.index(k, w);
    save_state(tape, k, shift, rays);
    intersect_taped(lens, k, c, shift, mu, count, x, y, z, l, m, n, failure, record, tape);
    aperture_masks(lens, k, g.aperture_center_mm[2 * k], g.aperture_center_mm[2 * k + 1], count, x,
                   y, failure);
    take_failures(k, count, failure, status, failed_at);
    if ((flags & kPlacementMoved) && (flags & kPlacementRestore))
      detail::to_parent(detail::placement_frame(g, k), count, x, y, z, l, m, n);
  }
  // The image plane z = t_{K-1} of the last frame, along the ray's line either way.
  const int last = k_count - 1;
  const double t = lens.thickness_mm[last];
  save_state(tape, k_count, t, rays);
  double* travel = record ? record->axial_travel_mm[last].data() : nullptr;
  for (std::size_t i = 0; i < count; ++i) {
    const double z_rel = z[i] - t;
    if (travel) travel[i] = -z_rel;
    if (n[i] == 0.0) {
      if (status[i] == kRayOk) {
        status[i] = kRayBackwards;
        failed_at[i] = static_cast<std::int8_t>(last);
      }
      continue;
    }
    const double s = -z_rel / n[i];
    x[i] = x[i] + s * l[i];
    y[i] = y[i] + s * m[i];
    z[i] = 0.0;
  }
  if (rays.turned()) detail::turn_about_z(rays.frame_cos, -rays.frame_sin, count, x, y, l, m);
}

// Backward through the rotation of a frame change: a_p <- R a_p, a_d <- R a_d (the transpose of
// to_local's R^T), or with R^T (the transpose of to_parent's R).
void rotate_adjoint(const detail::PlacementFrame<double>& f, bool transpose, std::size_t count,
                    double* const a[6]) {
  double r[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[i][j] = transpose ? f.r[j][i] : f.r[i][j];
  for (int v = 0; v < 6; v += 3) {
    double* __restrict u = a[v];
    double* __restrict s = a[v + 1];
    double* __restrict t = a[v + 2];
    for (std::size_t i = 0; i < count; ++i) {
      const double p = u[i], q = s[i], o = t[i];
      u[i] = r[0][0] * p + r[0][1] * q + r[0][2] * o;
      s[i] = r[1][0] * p + r[1][1] * q + r[1][2] * o;
      t[i] = r[2][0] * p + r[2][1] * q + r[2][2] * o;
    }
  }
}

double sum_of(const double* v, std::size_t count) {
  double s = 0.0;
  for (std::size_t i = 0; i < count; ++i) s += v[i];
  return s;
}

// Backward through to_local at surface k (a: the adjoints in its frame in, in the parent frame
// out); adds the decenter's adjoint.
void to_local_adjoint(const detail::PlacementFrame<double>& f, int k, std::size_t count,
                      double* const a[6], BundleAdjoint& out) {
  if (f.tilt_first) {
    out.decenter[2 * k] -= sum_of(a[0], count);
    out.decenter[2 * k + 1] -= sum_of(a[1], count);
  }
  rotate_adjoint(f, false, count, a);
  if (!f.tilt_first) {
    out.decenter[2 * k] -= sum_of(a[0], count);
    out.decenter[2 * k + 1] -= sum_of(a[1], count);
  }
}

// Backward through to_parent after surface k (a: the adjoints in the parent frame in, in the
// surface's frame out); adds the decenter's adjoint.
void to_parent_adjoint(const detail::PlacementFrame<double>& f, int k, std::size_t count,
                       double* const a[6], BundleAdjoint& out) {
  if (!f.tilt_first) {
    out.decenter[2 * k] += sum_of(a[0], count);
    out.decenter[2 * k + 1] += sum_of(a[1], count);
  }
  rotate_adjoint(f, true, count, a);
  if (f.tilt_first) {
    out.decenter[2 * k] += sum_of(a[0], count);
    out.decenter[2 * k + 1] += sum_of(a[1], count);
  }
}

// The image transfer backward: zr = z - T, s = -zr / n, X = x + s l, Y = y + s m, travel = -zr;
// (a_X, a_Y) the seeds in the lens frame (turned from the field frame by (cos, sin)).
void image_adjoint(const TraceLens<double>& lens, const RayBundle<double>& rays,
                   const AdjointTape& tape, const AdjointSeeds& seeds, double* const a[6],
                   BundleAdjoint& out) {
  const std::size_t count = rays.size();
  const int k_count = lens.surface_count();
  const int last = k_count - 1;
  const std::uint8_t* status = rays.status.data();
  const std::int8_t* fs = rays.failed_surface.data();
  const double* zr = tape.at(k_count, 2);
  const double* l = tape.at(k_count, 3);
  const double* m = tape.at(k_count, 4);
  const double* n = tape.at(k_count, 5);
  const double* travel_seed = seeds.travel ? (*seeds.travel)[last].data() : nullptr;
  const bool turned = rays.turned();
  const double fc = rays.frame_cos, fsin = rays.frame_sin;
  double sum_t = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    // The last space's travel is recorded for rays live there; the transfer only for traced rays.
    const bool live = fs[i] < 0 || fs[i] >= last;
    const bool traced = status[i] == kRayOk;
    double a_x_img = traced && seeds.x_image ? seeds.x_image[i] : 0.0;
    double a_y_img = traced && seeds.y_image ? seeds.y_image[i] : 0.0;
    if (turned) {
      // The turn back into the field frame, transposed.
      const double u = fc * a_x_img + fsin * a_y_img;
      const double v = fc * a_y_img - fsin * a_x_img;
      a_x_img = u;
      a_y_img = v;
    }
    const double a_travel = live && travel_seed ? travel_seed[i] : 0.0;
    const double s = -zr[i] / n[i];
    const double a_s = traced ? a_x_img * l[i] + a_y_img * m[i] : 0.0;
    const double a_zr = traced ? -a_s / n[i] - a_travel : -a_travel;
    a[0][i] = a_x_img;
    a[1][i] = a_y_img;
    a[2][i] = a_zr;
    a[3][i] = traced ? a_x_img * s : 0.0;
    a[4][i] = traced ? a_y_img * s : 0.0;
    a[5][i] = traced ? -a_s * s / n[i] : 0.0;
    sum_t -= a_zr;
  }
  out.thickness[last] += sum_t;
}

// The backward pass of surface k's steps 2-4 (sphere or profile kernel). Adds a_c, a_mu and the
// profile's terms to `out`; returns a_t of the shift applied on the taped z (sums[1]).
double surface_adjoint(const TraceLens<double>& lens, int w, int k, const AdjointTape& tape,
                       const AdjointSeeds& seeds, const std::int8_t* fs, std::size_t count,
                       double* const a[6], BundleAdjoint& out) {
  const double c = lens.curvature_per_mm[k];
  const double mu = lens.index(k - 1, w) / lens.index(k, w);
  const double* const state[6] = {tape.at(k, 0), tape.at(k, 1), tape.at(k, 2),
                                  tape.at(k, 3), tape.at(k, 4), tape.at(k, 5)};
  double sums[12] = {};
  const double* travel_seed = seeds.travel && k > 0 ? (*seeds.travel)[k - 1].data() : nullptr;
  const double* zeta_seed = seeds.zeta ? (*seeds.zeta)[k].data() : nullptr;
  const double* zeta_prime_seed = seeds.zeta_prime ? (*seeds.zeta_prime)[k].data() : nullptr;
  const std::uint8_t profile = lens.has_profiles() ? lens.profile[k] : kProfileSphere;
  if (profile != kProfileSphere) {
    detail::trace_surface_adjoint_profile_double(
        c, lens.conic[k], lens.asphere.data() + static_cast<std::size_t>(k) * kAsphereTerms, mu, k,
        count, state, tape.path.data() + static_cast<std::size_t>(k) * count, fs, a, travel_seed,
        zeta_seed, zeta_prime_seed, sums);
    out.conic[k] += sums[3];
    for (int j = 0; j < kAsphereTerms; ++j)
      out.asphere[static_cast<std::size_t>(k) * kAsphereTerms + j] += sums[4 + j];
  } else {
    detail::trace_surface_adjoint_double(c, mu, k, count, state, fs, a, travel_seed, zeta_seed,
                                         zeta_prime_seed, sums);
  }
  out.curvature[k] += sums[0];
  out.mu[k] += sums[2];
  return sums[1];
}

// The backward pass of trace_bundle_taped_placed (the equations of the header).
void trace_bundle_adjoint_placed(const TraceLens<double>& lens, int w,
                                 const RayBundle<double>& rays, const AdjointTape& tape,
                                 const AdjointSeeds& seeds, double* const a[6],
                                 BundleAdjoint& out) {
  const std::size_t count = rays.size();
  const int k_count = lens.surface_count();
  const std::int8_t* fs = rays.failed_surface.data();
  const TraceGeometry<double>& g = lens.geometry;
  image_adjoint(lens, rays, tape, seeds, a, out);
  for (int k = k_count - 1; k >= 0; --k) {
    const std::uint8_t flags = g.flags[k];
    const bool moved = (flags & kPlacementMoved) != 0;
    const detail::PlacementFrame<double> frame =
        moved ? detail::placement_frame(g, k) : detail::PlacementFrame<double>{};
    double a_shift = 0.0;  // a_t_{k-1}
    if (flags & kPlacementCoordinateBreak) {
      // z -= shift (t_{k-1} unless moved) and the recorded travel t_{k-1} of the rays live here.
      if (k > 0 && seeds.travel) {
        const double* seed = (*seeds.travel)[k - 1].data();
        for (std::size_t i = 0; i < count; ++i)
          a_shift += (fs[i] < 0 || fs[i] >= k) ? seed[i] : 0.0;
      }
      if (!moved) a_shift -= sum_of(a[2], count);
    } else {
      if (moved && (flags & kPlacementRestore)) to_parent_adjoint(frame, k, count, a, out);
      const double a_t = surface_adjoint(lens, w, k, tape, seeds, fs, count, a, out);
      if (!moved) a_shift += a_t;  // else the shift was applied before the frame change
      if (!tape.turned_back.empty()) {
        // Turned to the constant direction (0, 0, 1) before this surface.
        for (std::size_t i = 0; i < count; ++i) {
          if (tape.turned_back[i] == k) {
            a[3][i] = 0.0;
            a[4][i] = 0.0;
            a[5][i] = 0.0;
          }
        }
      }
    }
    if (moved) {
      to_local_adjoint(frame, k, count, a, out);
      a_shift -= sum_of(a[2], count);
    }
    if (k > 0) out.thickness[k - 1] += a_shift;
  }
  if (rays.turned()) {
    // The field frame's turn into the lens frame, transposed.
    const double fc = rays.frame_cos, fsin = rays.frame_sin;
    for (int v = 0; v < 6; v += 3) {
      double* __restrict p = a[v];
      double* __restrict q = a[v + 1];
      for (std::size_t i = 0; i < count; ++i) {
        const double u = fc * p[i] - fsin * q[i];
        const double t = fc * q[i] + fsin * p[i];
        p[i] = u;
        q[i] = t;
      }
    }
  }
}

}  // namespace

void trace_bundle_taped(const TraceLens<double>& lens, int w, RayBundle<double>& rays,
                        RayRecord<double>* record, AdjointTape& tape) {
  if (lens.geometry.placed()) {
    trace_bundle_taped_placed(lens, w, rays, record, tape);
    return;
  }
  const std::size_t count = rays.size();
  const int k_count = lens.surface_count();
  tape.resize(k_count, count, lens.has_profiles());
  double* x = rays.x.data();
  double* y = rays.y.data();
  double* z = rays.z.data();
  double* l = rays.l.data();
  double* m = rays.m.data();
  double* n = rays.n.data();
  std::uint8_t* status = rays.status.data();
  std::int8_t* failed_at = rays.failed_surface.data();
  rays.failure_scratch.resize(count);
  std::int32_t* failure = rays.failure_scratch.data();
  for (std::size_t i = 0; i < count; ++i) {
    if (!(n[i] > 0.0) && status[i] == kRayOk) {
      status[i] = kRayBackwards;
      failed_at[i] = 0;
      n[i] = 1.0;
    }
  }
  for (int k = 0; k < k_count; ++k) {
    const double c = lens.curvature_per_mm[k];
    const double shift = k > 0 ? lens.thickness_mm[k - 1] : 0.0;
    const double mu = lens.index(k - 1, w) / lens.index(k, w);
    save_state(tape, k, shift, rays);
    intersect_taped(lens, k, c, shift, mu, count, x, y, z, l, m, n, failure, record, tape);
    aperture_masks(lens, k, 0.0, 0.0, count, x, y, failure);
    take_failures(k, count, failure, status, failed_at);
  }
  const int last = k_count - 1;
  const double t = lens.thickness_mm[last];
  save_state(tape, k_count, t, rays);
  double* travel = record ? record->axial_travel_mm[last].data() : nullptr;
  for (std::size_t i = 0; i < count; ++i) {
    const double z_rel = z[i] - t;
    if (travel) travel[i] = -z_rel;
    if (!(n[i] > 0.0)) {
      if (status[i] == kRayOk) {
        status[i] = kRayBackwards;
        failed_at[i] = static_cast<std::int8_t>(last);
      }
      continue;
    }
    const double s = -z_rel / n[i];
    x[i] = x[i] + s * l[i];
    y[i] = y[i] + s * m[i];
    z[i] = 0.0;
  }
}

void trace_bundle_adjoint(const TraceLens<double>& lens, int w, const RayBundle<double>& rays,
                          const AdjointTape& tape, const AdjointSeeds& seeds, BundleAdjoint& out) {
  const std::size_t count = rays.size();
  const int k_count = lens.surface_count();
  out.x0.resize(count);
  out.y0.resize(count);
  out.z0.resize(count);
  out.l0.resize(count);
  out.m0.resize(count);
  out.n0.resize(count);
  // Adjoints of the state, carried from the image backwards in out.x0 .. n0.
  double* const a[6] = {out.x0.data(), out.y0.data(), out.z0.data(),
                        out.l0.data(), out.m0.data(), out.n0.data()};
  if (lens.geometry.placed()) {
    trace_bundle_adjoint_placed(lens, w, rays, tape, seeds, a, out);
    return;
  }
  const std::int8_t* fs = rays.failed_surface.data();
  image_adjoint(lens, rays, tape, seeds, a, out);
  for (int k = k_count - 1; k >= 0; --k) {
    const double a_t = surface_adjoint(lens, w, k, tape, seeds, fs, count, a, out);
    if (k > 0) out.thickness[k - 1] += a_t;
  }
}

}  // namespace lensopt
