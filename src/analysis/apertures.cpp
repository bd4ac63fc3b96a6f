#include "lensopt/analysis/apertures.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace lensopt {

std::vector<double> automatic_semi_diameters(const TraceSystem<double>& sys, int edge_rays) {
  const int k_count = sys.lens.surface_count();
  std::vector<double> out(k_count, 0.0);
  std::vector<char> unknown(k_count, 0);
  PupilSamples pupil = sys.samples_for(pupil_edge_samples(edge_rays));
  pupil.x.push_back(0.0);  // the chief ray
  pupil.y.push_back(0.0);
  RayBundle<double> rays;
  const int field_count = static_cast<int>(sys.fields_deg.size());
  for (int h = 0; h < field_count; ++h) {
    for (int w = 0; w <= sys.wavelength_count; ++w) {
      for (int k = 0; k < k_count; ++k) {
        start_rays(sys, h, w, rays, &pupil);
        trace_bundle(sys.lens, w, k + 1, false, rays, static_cast<RayRecord<double>*>(nullptr));
        for (std::size_t i = 0; i < rays.size(); ++i) {
          if (rays.status[i] != kRayOk && rays.failed_surface[i] <= k) {
            // A ray that misses (not one clipped by an aperture) leaves the height unknown.
            if (rays.status[i] != kRayVignetted) unknown[k] = 1;
            continue;
          }
          out[k] = std::max(out[k], std::hypot(rays.x[i], rays.y[i]));
        }
      }
    }
  }
  for (int k = 0; k < k_count; ++k)
    out[k] = unknown[k] ? std::numeric_limits<double>::quiet_NaN() : out[k] / sys.scale;
  return out;
}

std::vector<double> automatic_semi_diameters(const Lens& lens) {
  TraceOptions options;
  options.rings = 1;
  options.threads = 1;
  return automatic_semi_diameters(prepare_lens_system(lens, options));
}

}  // namespace lensopt
