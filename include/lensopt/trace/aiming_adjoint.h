// Reverse mode of the ray aiming of prepare_system (trace/system.h), so that a gradient by the
// adjoint (analysis/spot_adjoint.h, optimize/design_gradient.h) costs the same whatever the
// number of variables: the lens-level preparation runs on Jets without the aiming, and the
// aiming's derivatives come from one taped pass here.
//
// The aiming of field h and wavelength w (system.h): three rays from the pupil points
// (0, R_EP), (0, -R_EP), (R_EP, 0) at z_EP are traced to the stop, giving their stop
// coordinates c_i (y, y, x) and the derivatives d_i = dc_i / dp_i with respect to their
// normalized pupil coordinate p_i; with R_s the stop radius,
//   top = 1 + (R_s - c_0) / d_0,   bottom = -1 + (-R_s - c_1) / d_1,   side = 1 + (R_s - c_2) /
//   d_2, s_x = side,   o_y = (top + bottom) / 2,   s_y = (top - bottom) / 2.
// The bundle's adjoint gives a_j = dL / dS_j of the ray starts S = R_EP (s_x, o_y, s_y), so that
// A_j = a_j R_EP is the adjoint of the map entry j and
//   a_top = (A_oy + A_sy) / 2,   a_bottom = (A_oy - A_sy) / 2,   a_side = A_sx,
//   a_c0 = -a_top / d_0,   a_d0 = -a_top (R_s - c_0) / d_0^2,   a_Rs += a_top / d_0,
//   a_c1 = -a_bottom / d_1,   a_d1 = -a_bottom (-R_s - c_1) / d_1^2,   a_Rs -= a_bottom / d_1,
//   a_c2 = -a_side / d_2,   a_d2 = -a_side (R_s - c_2) / d_2^2,   a_Rs += a_side / d_2.
// (The axial field of a lens with 3D placements is aimed at the reference wavelength for every
// wavelength, with s_x = (side - side_-) / 2 from a second sagittal ray at -R_EP,
// side_- = -1 + (-R_s - c_2-) / d_2-: its A is summed over the wavelengths, a_side = A_sx / 2,
// a_side- = -A_sx / 2.)
// What remains is, per aimed ray, the gradient of a_c c + a_d d with respect to the parameters
// P the trace reads (every curvature, thickness, nd, vd, conic, asphere term and placement of
// the scaled lens, R_EP and z_EP). c(P, p) is a ray trace and d = dc/dp, so
//   a_c dc/dP + a_d dd/dP = d/de [ (a_d + e a_c) dc/dP (p + e) ]_{e=0}:
// the reverse sweep of the trace recorded on dual numbers in p (value + e derivative, the
// derivative seeded 1 at the pupil coordinate, as prepare_system's inner Jet), seeded with the
// dual a_d + e a_c at c, leaves at each input P the dual a_d dc/dP + e (a_d dd/dP + a_c dc/dP)
// (forward over reverse); its e part is the wanted gradient. The recorded trace is the kernel of
// trace/kernel.h itself, run on a taped scalar whose values are ceres::Jet<double, 1>, with two
// Newton steps at an asphere as on prepare_system's Jet<Jet<.>, 1>: the stop coordinates and
// derivatives are those of prepare_system's Jets bit for bit, and so are the maps.
// The cost is a few times one trace of the 3 rays per field and wavelength, independent of the
// number of variables (the forward-mode aiming costs that number of Jet components).
#pragma once

#include <vector>

#include "lensopt/trace/system.h"

namespace lensopt {

// The adjoints, with respect to the double parameters of an aimed system, of the pupil maps'
// part of a scalar L (the ray starts' adjoints through the maps; the maps' factor R_EP and the
// start z_EP are the caller's). Indexed as the TraceLens fields they belong to.
struct AimingAdjoint {
  std::vector<double> curvature, thickness, nd, vd;  // K
  std::vector<double> conic, asphere;                // as TraceLens::conic, asphere (or empty)
  std::vector<double> placement;                     // as TraceGeometry::placement (or empty)
  double entrance_pupil_radius = 0.0;                // R_EP = EPD / 2
  double entrance_pupil_z = 0.0;                     // z_EP
  double stop_radius = 0.0;                          // R_s
};

// Sets the pupil maps of `sys` (prepared with ray_aiming false, or any: the maps are replaced) to
// those prepare_system computes with `setup` and ray aiming, bit for bit as on its Jets.
void aim_pupil_maps(TraceSystem<double>& sys, const SystemSetup& setup);

// The same maps (set in `sys`) and the adjoint of sum_{h, w < W, j < 3} a_{h,w,j} S_{h,w,j}
// through the maps, S = R_EP (s_x, o_y, s_y), with a = start[(h W + w) * 4 + j] (the layout of
// SystemAdjoint::start; its fourth entry, z_EP's, is not used here).
AimingAdjoint aim_pupil_maps_adjoint(TraceSystem<double>& sys, const SystemSetup& setup,
                                     const std::vector<double>& start);

}  // namespace lensopt
