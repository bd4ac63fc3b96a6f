// The ray aiming's trace on the Jet systems (prepare_system on ceres::Jet<double, N>, the LM
// Jacobian's and the gradients' setup): detail::trace_aiming_rays of trace/system.h is
// specialized for those systems in src/trace/system_jet.cpp.in, where it runs
// trace_aiming_rays_jet below. On a rotationally symmetric lens of spheres (aiming_on_duals) the
// three rays cross the surfaces to the stop on a nested dual number of trace/dual.h's Dual<N>
// (compiled for x86-64-v4 and -v3, the inner derivative loops at those widths) instead of
// ceres::Jet<Jet<double, N>, 1>: each operation the nested Jet's of ceres/jet.h in the same order,
// without FMA, so the stop coordinates and their derivatives are the nested Jets' bit for bit
// (tests/unit/test_trace_aiming_dual.cpp). Only that source file and the test include this header.
#pragma once

#include <ceres/jet.h>

#include "lensopt/core/jet_width.h"
#include "lensopt/trace/system.h"

namespace lensopt::detail {

// clang-format off
#define LENSOPT_DECLARE_AIMING_JET(N)                                                           \
  /* trace_aiming_rays on these Jets; use_duals false: the nested Jets (trace_bundle), as the   \
     template of system.h; true: the duals where aiming_on_duals allows. */                     \
  void trace_aiming_rays_jet(const TraceLens<ceres::Jet<ceres::Jet<double, N>, 1>>& lens_a,     \
                             int w, const TraceSystem<ceres::Jet<double, N>>& sys, int h,       \
                             const ceres::Jet<double, N>& r_ep,                                 \
                             const ceres::Jet<double, N>& z_ep,                                 \
                             const PupilMap<ceres::Jet<double, N>>& map,                        \
                             ceres::Jet<double, N> stop_coord[3],                               \
                             ceres::Jet<double, N> stop_derivative[3],                          \
                             RayBundle<ceres::Jet<ceres::Jet<double, N>, 1>>* scratch,          \
                             bool use_duals);                                                   \
  /* Whether the duals trace surfaces [0, end) of lens_a on this CPU: x86-64-v3 or above, the   \
     lens unplaced and every one of those surfaces a sphere. */                                 \
  bool aiming_on_duals(const TraceLens<ceres::Jet<ceres::Jet<double, N>, 1>>& lens_a, int end);
// clang-format on
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_DECLARE_AIMING_JET)
#undef LENSOPT_DECLARE_AIMING_JET

}  // namespace lensopt::detail
