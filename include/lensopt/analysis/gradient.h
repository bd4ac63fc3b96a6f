// The mean RMS spot and its exact gradient with respect to prescription variables, by forward
// mode automatic differentiation: the whole pipeline (scaling to the spec focal length, paraxial
// entrance pupil, stop radius, ray aiming with its own inner derivatives, exact trace, spot) runs
// on ceres::Jet<double, N>, N variables at a time.
#pragma once

#include <ceres/jet.h>

#include <cstdint>
#include <vector>

#include "lensopt/analysis/spot.h"
#include "lensopt/core/jet_width.h"

namespace lensopt {

struct SpotGradient {
  double mean_rms_spot_mm = 0.0;
  std::vector<double> gradient;  // d(mean spot, mm) / d(variable), one per variable
};

// The lens the gradients trace: every spherical surface with a profile variable anywhere in
// `variables` made a conic (k alone) or an even asphere (any a_2i), its terms still 0, so that
// every chunk of N variables traces the same profiles. convert_trace_lens gives a profile only
// to the surfaces whose terms its own chunk seeds; chunk by chunk the Jets then traced a surface
// as a sphere, a conic or an asphere, and the adjoint, which traces the first chunk's lens in
// double, ran the sphere's backward step at a surface whose k or a_2i a later chunk seeds (their
// direct derivatives lost: only the part through the stop radius and ray aiming was left).
inline TraceLens<double> with_profile_variables(
    TraceLens<double> lens, const std::vector<PrescriptionVariable>& variables) {
  for (const PrescriptionVariable& v : variables) {
    const bool conic = v.kind == PrescriptionVariable::Kind::kConic;
    if (!conic && v.kind != PrescriptionVariable::Kind::kAsphere) continue;
    lens.ensure_profiles();
    std::uint8_t& kind = lens.profile[v.surface];
    if (!conic) {
      kind = kProfileAsphere;
    } else if (kind == kProfileSphere) {
      kind = kProfileConic;
    }
  }
  return lens;
}

// Evaluates the gradient in chunks of N variables (ceil(n / N) traces on Jet<double, N>).
template <int N = 8>
SpotGradient mean_spot_gradient(const TraceLens<double>& lens_in, const Specs& specs,
                                const std::vector<PrescriptionVariable>& variables,
                                const TraceOptions& options) {
  using J = ceres::Jet<double, N>;
  const TraceLens<double> lens = with_profile_variables(lens_in, variables);
  SpotGradient out;
  out.gradient.assign(variables.size(), 0.0);
  const int count = static_cast<int>(variables.size());
  for (int first = 0; first < count || first == 0; first += N) {
    const int chunk = std::min(N, count - first);
    const TraceLens<J> lens_j = convert_trace_lens<J>(lens, variables, first, chunk,
                                                      [](double v, int j) { return J(v, j); });
    const TraceSystem<J> sys = prepare_system(lens_j, specs, options);
    const SpotResult<J> spots = evaluate_spots(sys, options.threads);
    out.mean_rms_spot_mm = spots.mean_rms_spot_mm.a;
    for (int j = 0; j < chunk; ++j) out.gradient[first + j] = spots.mean_rms_spot_mm.v[j];
    if (count == 0) break;
  }
  return out;
}

// mean_spot_gradient on the widths of core/jet_width.h is compiled once, in
// src/analysis/spot_adjoint.cpp (a file calling mean_spot_gradient_auto, below, compiled all five).
#define LENSOPT_MEAN_SPOT_GRADIENT_JET(N)                                                      \
  extern template SpotGradient mean_spot_gradient<N>(const TraceLens<double>&, const Specs&,   \
                                                     const std::vector<PrescriptionVariable>&, \
                                                     const TraceOptions&);
LENSOPT_FOR_EACH_JET_WIDTH(LENSOPT_MEAN_SPOT_GRADIENT_JET)
#undef LENSOPT_MEAN_SPOT_GRADIENT_JET

}  // namespace lensopt

namespace lensopt {

// The gradient with the Jet width that covers the variables in the fewest passes (one pass up
// to kJetWidthCap variables: every lens of the paper).
inline SpotGradient mean_spot_gradient_auto(const TraceLens<double>& lens, const Specs& specs,
                                            const std::vector<PrescriptionVariable>& variables,
                                            const TraceOptions& options) {
  return with_jet_width(static_cast<int>(variables.size()), [&](auto width) {
    return mean_spot_gradient<decltype(width)::value>(lens, specs, variables, options);
  });
}

}  // namespace lensopt
