// Value and gradient of the paper's lens design loss l_lens (optimize/design_loss.h) for a
// gradient-descent optimizer (the joint optimization's Adam):
//   l_lens(x) = w_S l_S + w_RP l_RP + w_RA l_RA + w_GV l_GV,   grad_j = d l_lens / d x_j,
// by forward-mode automatic differentiation: evaluate_design runs on ceres::Jet<double, N>
// with x_j seeded as the j-th infinitesimal, and the Jet's derivative part of `total` is the
// gradient. Lenses with more than kDesignGradientWidth variables take several passes (one per
// block of variables), each seeding only its block.
#pragma once

#include <vector>

#include "lensopt/optimize/design_loss.h"
#include "lensopt/optimize/variables.h"

namespace lensopt {

inline constexpr int kDesignGradientWidth = 24;

struct DesignValueGradient {
  DesignLoss<double> loss;       // the terms' values (paper's linear hinges)
  std::vector<double> gradient;  // d total / d x, size param.size()
  bool finite = true;            // false if the evaluation was not finite
};

// l_lens and its gradient at x.
DesignValueGradient design_loss_gradient(const LensParameterization& param,
                                         const std::vector<double>& x, GlassMode mode,
                                         const std::vector<int>& fixed_glasses,
                                         const TraceOptions& sampling,
                                         const DesignLossOptions& options);

}  // namespace lensopt
