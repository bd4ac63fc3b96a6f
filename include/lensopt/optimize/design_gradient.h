// Value and gradient of the paper's lens design loss l_lens (optimize/design_loss.h) for a
// gradient-descent optimizer (the joint optimization's Adam):
//   l_lens(x) = w_S l_S + w_RP l_RP + w_RA l_RA + w_GV l_GV,   grad_j = d l_lens / d x_j,
// by reverse mode (adjoint, the default): the forward map x -> TraceLens and prepare_system run
// on ceres::Jet<double, N> (few rays: the paraxial solves, stop radius; the ray aiming's maps and
// their adjoint by a taped trace, trace/aiming_adjoint.h), every ray in
// double with the backward pass of trace/adjoint.h, and the chain rule through the Jets
// (analysis/spot_adjoint.h). The seeds of the backward pass are the derivatives of the terms of
// evaluate_design (design_loss.h) with respect to what the rays give:
//   spot   dl/dY = w_S (Y - ybar_h) / (F N_h S_h),  dl/dX = w_S X / (F N_h S_h)   (traced rays)
//   path   dl/d dz_{k,r} = (w_RP / n_r) ([dz > upper_k] - [dz < lower_k])   (spaces the ray
//   crossed) angle  dl/d zeta = -(w_RA / n_r) [zeta < cos^2 t_max], the same for zeta' (surfaces
//   reached) glass  dl/dg = 2 w_GV (g - g*)  (direct, no ray)
// ([.] = 1 where true; a path hinge at exactly its bound has derivative 0, as the Jets have;
// an angle hinge within round-off of its bound, a tie, half: detail::tied_hinge of design_loss.h.)
// The wavefront merit and an afocal lens's angular spot (design_loss.h) have no adjoint seeds:
// design_loss_gradient takes the forward-mode Jets for them (as optimize's LM always does).
// design_loss_gradient_jets is the forward-mode reference: evaluate_design on
// ceres::Jet<double, N> with x_j seeded as the j-th infinitesimal, in blocks of
// kDesignGradientWidth variables.
#pragma once

#include <vector>

#include "lensopt/core/jet_width.h"
#include "lensopt/optimize/design_loss.h"
#include "lensopt/optimize/variables.h"

namespace lensopt {

inline constexpr int kDesignGradientWidth = kJetWidthCap;

struct DesignValueGradient {
  DesignLoss<double> loss;       // the terms' values (paper's linear hinges)
  std::vector<double> gradient;  // d total / d x, size param.size()
  bool finite = true;            // false if the evaluation was not finite
};

// l_lens and its gradient at x (adjoint).
DesignValueGradient design_loss_gradient(const LensParameterization& param,
                                         const std::vector<double>& x, GlassMode mode,
                                         const std::vector<int>& fixed_glasses,
                                         const TraceOptions& sampling,
                                         const DesignLossOptions& options);

// The same by forward-mode Jets (the reference the adjoint is tested against).
DesignValueGradient design_loss_gradient_jets(const LensParameterization& param,
                                              const std::vector<double>& x, GlassMode mode,
                                              const std::vector<int>& fixed_glasses,
                                              const TraceOptions& sampling,
                                              const DesignLossOptions& options);

}  // namespace lensopt
