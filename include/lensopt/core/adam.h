// Adam (Kingma & Ba 2015) with bias correction, the one update of the lens variables (the plain
// Adam baseline of optimize/optimizer.h and the joint optimization, joint/joint.h). For update
// number t = 1, 2, ... with gradient g:
//   m = b1 m + (1 - b1) g,   v = b2 v + (1 - b2) g^2,
//   x -= lr (m / (1 - b1^t)) / (sqrt(v / (1 - b2^t)) + eps),
// b1 = 0.9, b2 = 0.999, eps = 1e-8 unless told. Variables with skip[i] != 0 keep x, m and v.
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

namespace lensopt {

struct AdamOptions {
  double beta1 = 0.9;
  double beta2 = 0.999;
  double eps = 1e-8;
};

// The moments of one run (saved in checkpoints with x).
struct AdamMoments {
  std::vector<double> m, v;
  explicit AdamMoments(std::size_t n = 0) : m(n, 0.0), v(n, 0.0) {}
};

// Update number t (1-based) of x by gradient g; `skip` (empty, or one entry per variable) holds
// variables fixed.
inline void adam_update(std::vector<double>& x, const std::vector<double>& g,
                        std::vector<double>& m, std::vector<double>& v, int t, double learning_rate,
                        const std::vector<char>& skip = {}, const AdamOptions& o = {}) {
  const double c1 = 1.0 - std::pow(o.beta1, t), c2 = 1.0 - std::pow(o.beta2, t);
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (!skip.empty() && skip[i]) continue;
    m[i] = o.beta1 * m[i] + (1.0 - o.beta1) * g[i];
    v[i] = o.beta2 * v[i] + (1.0 - o.beta2) * g[i] * g[i];
    x[i] -= learning_rate * (m[i] / c1) / (std::sqrt(v[i] / c2) + o.eps);
  }
}

}  // namespace lensopt
