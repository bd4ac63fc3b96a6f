#include "lensopt/plot/style.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace lensopt::plot {

std::string field_colour(int j, int n) {
  if (n <= 3) {
    static const char* three[] = {"#1f5fbf", "#2a9d3a", "#d1342b"};
    return three[n == 1 ? 0 : n == 2 ? (j == 0 ? 0 : 2) : std::clamp(j, 0, 2)];
  }
  static const std::array<std::array<double, 3>, 4> ramp = {
      {{31, 95, 191}, {42, 157, 58}, {224, 138, 0}, {209, 52, 43}}};
  const double t = std::clamp(static_cast<double>(j) / (n - 1), 0.0, 1.0) * (ramp.size() - 1);
  const std::size_t k = std::min<std::size_t>(static_cast<std::size_t>(t), ramp.size() - 2);
  const double f = t - k;
  int rgb[3];
  for (int c = 0; c < 3; ++c)
    rgb[c] = static_cast<int>(std::lround(ramp[k][c] * (1 - f) + ramp[k + 1][c] * f));
  return fmt::format("#{:02x}{:02x}{:02x}", rgb[0], rgb[1], rgb[2]);
}

}  // namespace lensopt::plot
