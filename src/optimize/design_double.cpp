// The double instantiations of the design loss (evaluate_design, measure_targets and
// LensParameterization::to_trace_lens), declared extern in their headers, so that they are
// compiled here once instead of in each object that evaluates a design (as the Jet widths,
// src/optimize/design_loss_jet.cpp.in).
#include "lensopt/optimize/design_loss.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/optimize/variables.h"

namespace lensopt {

template bool evaluate_design<double>(const LensParameterization&, const double*, GlassMode,
                                      const std::vector<int>&, const TraceOptions&,
                                      const DesignLossOptions&, const std::vector<double>*, double*,
                                      DesignLoss<double>*, DesignExtremes*);
template TargetValues<double> measure_targets<double>(const TraceSystem<double>&,
                                                      const std::vector<DesignTarget>&,
                                                      const TargetSampling&);
template TraceLens<double> LensParameterization::to_trace_lens<double>(
    const double*, GlassMode, const std::vector<int>&) const;

}  // namespace lensopt
