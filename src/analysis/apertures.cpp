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

std::vector<SurfaceCrossing> crossing_surfaces(const Lens& lens) {
  const auto& s = lens.surfaces;
  const int k_count = static_cast<int>(s.size());
  std::vector<double> automatic;
  try {
    automatic = automatic_semi_diameters(lens);
  } catch (const std::exception&) {
    // No traced apertures (the lens's own checks report why): the vertex gaps alone.
  }
  auto aperture = [&](int k) {
    if (s[k].semi_diameter_mm > 0.0) return s[k].semi_diameter_mm;
    const double h = k < static_cast<int>(automatic.size()) ? automatic[k] : 0.0;
    return std::isfinite(h) ? h : 0.0;
  };
  auto dummy = [&](int k) {
    const bool air_before = k == 0 || s[k - 1].material.is_air();
    return s[k].is_stop || (s[k].curvature_per_mm == 0.0 && s[k].is_spherical() && air_before &&
                            s[k].material.is_air());
  };
  constexpr int kHeights = 8;
  std::vector<SurfaceCrossing> out;
  int previous = -1;
  double axial_mm = 0.0;  // t_previous + ... up to the current surface
  for (int k = 0; k < k_count; ++k) {
    if (dummy(k)) {
      if (previous >= 0) axial_mm += s[k].thickness_mm;
      continue;
    }
    if (previous >= 0) {
      const double h = std::min(aperture(previous), aperture(k));
      for (int m = 0; m <= kHeights; ++m) {
        const double r = h * m / kHeights;
        if (m > 0 && !(r > 0.0)) break;
        const double gap = axial_mm + s[k].sag_mm(r) - s[previous].sag_mm(r);
        if (gap < 0.0) {
          out.push_back(SurfaceCrossing{previous, k, r, gap});
          break;
        }
      }
    }
    previous = k;
    axial_mm = s[k].thickness_mm;
  }
  return out;
}

}  // namespace lensopt
