#include <fmt/format.h>

#include "lensopt/core/error.h"
#include "lensopt/trace/system.h"

namespace lensopt {

void TraceOptions::validate() const {
  if (rings < 1 || rings > 256) throw Error(fmt::format("rings = {} must be in [1, 256]", rings));
  if (fields < 1 || fields > 1000)
    throw Error(fmt::format("fields = {} must be in [1, 1000]", fields));
  if (threads < 0) throw Error(fmt::format("threads = {} must be >= 0", threads));
}

PupilSamples paper_pupil_samples(int rings) {
  PupilSamples out;
  const double spacing = 1.0 / (2.0 * rings - 1.0);
  int k = 0;  // running ray index over all rings
  for (int i = 0; i < rings; ++i) {
    const int ring_count = 2 * i + 1;
    for (int j = 0; j < ring_count; ++j, ++k) {
      const double azimuth = ((j + 0.5) / ring_count - 0.5) * kPi;
      const double radius = 2.0 * i * spacing + ((k + i) % 2) * spacing;
      out.x.push_back(radius * std::cos(azimuth));
      out.y.push_back(radius * std::sin(azimuth));
    }
  }
  return out;
}

PupilSamples pupil_edge_samples(int count) {
  PupilSamples out;
  for (int j = 0; j < count; ++j) {
    const double azimuth = count == 1 ? 0.0 : (-0.5 + static_cast<double>(j) / (count - 1)) * kPi;
    out.x.push_back(std::cos(azimuth));
    out.y.push_back(std::sin(azimuth));
  }
  return out;
}

std::vector<double> field_angles_deg(double half_field_deg, int count) {
  std::vector<double> out;
  if (count == 1) return {0.0};
  for (int i = 0; i < count; ++i) out.push_back(half_field_deg * i / (count - 1));
  return out;
}

}  // namespace lensopt
