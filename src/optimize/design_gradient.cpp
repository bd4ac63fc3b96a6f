#include "lensopt/optimize/design_gradient.h"

#include <algorithm>

namespace lensopt {
namespace {

template <int N>
void accumulate(const LensParameterization& param, const std::vector<double>& x, int first,
                GlassMode mode, const std::vector<int>& fixed_glasses, const TraceOptions& sampling,
                const DesignLossOptions& options, DesignValueGradient& out) {
  using J = ceres::Jet<double, N>;
  const int n = param.size();
  std::vector<J> xj(n);
  for (int i = 0; i < n; ++i) {
    xj[i] = J(x[i]);
    if (i >= first && i < first + N) xj[i].v[i - first] = 1.0;
  }
  DesignLoss<J> loss;
  out.finite = evaluate_design<J>(param, xj.data(), mode, fixed_glasses, sampling, options, nullptr,
                                  nullptr, &loss) &&
               out.finite;
  for (int i = first; i < std::min(n, first + N); ++i) out.gradient[i] = loss.total.v[i - first];
  if (first == 0) {
    out.loss.spot_mm = loss.spot_mm.a;
    out.loss.ray_path_mm = loss.ray_path_mm.a;
    out.loss.ray_angle = loss.ray_angle.a;
    out.loss.glass = loss.glass.a;
    out.loss.total = loss.total.a;
    out.loss.field_rms_mm.clear();
    for (const J& f : loss.field_rms_mm) out.loss.field_rms_mm.push_back(f.a);
    out.loss.failed_rays = loss.failed_rays;
    out.loss.rays = loss.rays;
  }
}

}  // namespace

DesignValueGradient design_loss_gradient(const LensParameterization& param,
                                         const std::vector<double>& x, GlassMode mode,
                                         const std::vector<int>& fixed_glasses,
                                         const TraceOptions& sampling,
                                         const DesignLossOptions& options) {
  DesignValueGradient out;
  const int n = param.size();
  out.gradient.assign(n, 0.0);
  // The narrowest Jet that holds the variables in one pass; blocks of kDesignGradientWidth above.
  if (n <= 8) {
    accumulate<8>(param, x, 0, mode, fixed_glasses, sampling, options, out);
  } else if (n <= 16) {
    accumulate<16>(param, x, 0, mode, fixed_glasses, sampling, options, out);
  } else {
    for (int first = 0; first < n; first += kDesignGradientWidth)
      accumulate<kDesignGradientWidth>(param, x, first, mode, fixed_glasses, sampling, options,
                                       out);
  }
  return out;
}

}  // namespace lensopt
