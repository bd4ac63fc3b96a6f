#include "lensopt/analysis/chromatic.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/json_number.h"
#include "lensopt/core/error.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/kernel.h"

namespace lensopt {
namespace {

// The paraxial marginal ray of the axial object point at the first vertex plane (object space
// n = 1): parallel for an object at infinity, else from the object at distance d (any slope: the
// image distance does not depend on it).
ParaxialRay<double> axial_ray(const TraceSystem<double>& sys) {
  if (sys.object_at_infinity()) return {1.0, 0.0};
  const double u = 1e-3;
  return {u * sys.object_distance_mm, u};
}

// Last vertex to the paraxial image of the axial object point at `wavelength_nm` (mm).
double image_distance_mm(const TraceLens<double>& lens, const ParaxialRay<double>& start,
                         double wavelength_nm) {
  const int k_count = lens.surface_count();
  const ParaxialRay<double> r = paraxial_trace(lens, start, k_count, wavelength_nm);
  return -r.y * lens.index_at_nm(k_count - 1, wavelength_nm) / r.w;
}

// The working F-number 1 / (2 |n' u'|) of the marginal ray through the entrance-pupil rim at
// the primary wavelength.
double working_f_number(const TraceSystem<double>& sys) {
  const TraceLens<double>& lens = sys.lens;
  const double r_ep = 0.5 * sys.epd_mm;
  ParaxialRay<double> m{r_ep, 0.0};
  if (!sys.object_at_infinity()) {
    const double u = r_ep / (sys.entrance_pupil_z_mm + sys.object_distance_mm);
    m = {u * sys.object_distance_mm, u};
  }
  m = paraxial_trace(lens, m, lens.surface_count(), lens.reference_nm());
  return 1.0 / (2.0 * std::abs(m.w));
}

}  // namespace

ChromaticFocalShift chromatic_focal_shift(const Lens& lens, const TraceSystem<double>& sys,
                                          double lo_nm, double hi_nm, int samples) {
  ChromaticFocalShift out;
  const TraceLens<double>& traced = sys.lens;
  out.primary_nm = traced.reference_nm();
  out.band = !(lo_nm == 0 && hi_nm == 0);
  std::vector<double> wavelengths;
  if (out.band) {
    if (!(lo_nm > 0 && hi_nm > lo_nm && std::isfinite(hi_nm)))
      throw Error(fmt::format("chromatic focal shift: the band {} to {} nm must have 0 < lo < hi",
                              lo_nm, hi_nm));
    if (samples < 2 || samples > 10000)
      throw Error(fmt::format("chromatic focal shift: {} samples must be in 2..10000", samples));
    for (int i = 0; i < samples; ++i)
      wavelengths.push_back(lo_nm + (hi_nm - lo_nm) * i / (samples - 1));
  } else {
    wavelengths.assign(traced.wavelengths_nm.begin(),
                       traced.wavelengths_nm.begin() + sys.wavelength_count);
    std::sort(wavelengths.begin(), wavelengths.end());
    wavelengths.erase(std::unique(wavelengths.begin(), wavelengths.end()), wavelengths.end());
  }
  // The traced geometry (scaled, as analyzed) with indices at the sample wavelengths: a catalog
  // glass holds its corrections at its own wavelengths only, so the band's come from a TraceLens
  // made for them (make_trace_lens checks each glass's range).
  TraceLens<double> at_band = traced;
  if (out.band) {
    Lens copy = lens;
    copy.specs.wavelengths_nm = wavelengths;
    copy.specs.wavelength_channels = default_wavelength_channels(wavelengths);
    copy.specs.wavelength_weights.clear();
    copy.specs.primary_wavelength_nm = out.primary_nm;
    const TraceLens<double> band = make_trace_lens(copy);
    at_band.wavelengths_nm = band.wavelengths_nm;
    at_band.catalog_offset = band.catalog_offset;
  }
  const ParaxialRay<double> start = axial_ray(sys);
  const double z_primary = image_distance_mm(traced, start, out.primary_nm);
  if (!std::isfinite(z_primary))
    throw Error(
        "chromatic focal shift: the paraxial image of the axial object point is not finite "
        "(an afocal system has no focus)");
  double lo = 0, hi = 0;
  for (double nm : wavelengths) {
    const double dz = image_distance_mm(at_band, start, nm) - z_primary;
    if (!std::isfinite(dz))
      throw Error(fmt::format("chromatic focal shift: no finite paraxial focus at {} nm", nm));
    out.wavelengths_nm.push_back(nm);
    out.shift_mm.push_back(dz);
    lo = std::min(lo, dz);
    hi = std::max(hi, dz);
  }
  out.max_range_mm = hi - lo;
  out.working_f_number = working_f_number(sys);
  out.diffraction_depth_mm =
      4.0 * out.primary_nm * 1e-6 * out.working_f_number * out.working_f_number;
  return out;
}

LateralColour lateral_colour(const TraceSystem<double>& sys) {
  LateralColour out;
  const int wc = sys.wavelength_count;
  const int field_count = static_cast<int>(sys.fields_deg.size());
  out.field_deg = sys.fields_deg;
  out.field_values = sys.field_values;
  out.primary_nm = sys.lens.reference_nm();
  out.wavelengths_nm.assign(sys.lens.wavelengths_nm.begin(), sys.lens.wavelengths_nm.begin() + wc);
  int w_short = 0, w_long = 0;
  for (int w = 0; w < wc; ++w) {
    if (sys.lens.wavelengths_nm[w] < sys.lens.wavelengths_nm[w_short]) w_short = w;
    if (sys.lens.wavelengths_nm[w] > sys.lens.wavelengths_nm[w_long]) w_long = w;
  }
  out.short_nm = sys.lens.wavelengths_nm[w_short];
  out.long_nm = sys.lens.wavelengths_nm[w_long];
  out.airy_radius_um = 1.22 * out.primary_nm * 1e-3 * working_f_number(sys);
  const double r_ep = 0.5 * sys.epd_mm;
  RayBundle<double> rays;
  for (int h = 0; h < field_count; ++h) {
    const double theta = sys.fields_deg[h] * kPi / 180.0;
    const double object_y = sys.field_object_y_mm.empty() ? 0.0 : sys.field_object_y_mm[h];
    // Chief rays of every spec wavelength and the primary (w = W), each through its own aimed
    // stop centre.
    rays.resize(wc + 1);
    for (int w = 0; w <= wc; ++w)
      start_pupil_ray(rays, w, 0.0, r_ep * sys.pupil_map(h, w).offset_y, sys.entrance_pupil_z_mm,
                      sys.object_distance_mm, std::sin(theta), std::cos(theta), object_y);
    bool ok = true;
    std::vector<double> y(wc + 1, 0.0);
    for (int w = 0; w <= wc; ++w) {
      RayBundle<double> one;
      one.resize(1);
      one.x[0] = rays.x[w];
      one.y[0] = rays.y[w];
      one.z[0] = rays.z[w];
      one.l[0] = rays.l[w];
      one.m[0] = rays.m[w];
      one.n[0] = rays.n[w];
      set_field_frame(sys, h, one);
      trace_bundle(sys.lens, w, sys.lens.surface_count(), true, one,
                   static_cast<RayRecord<double>*>(nullptr));
      ok = ok && one.status[0] == kRayOk && std::isfinite(one.y[0]);
      y[w] = one.y[0];
    }
    std::vector<double> rel(wc, 0.0);
    if (ok)
      for (int w = 0; w < wc; ++w) rel[w] = (y[w] - y[wc]) * 1e3;
    out.relative_um.push_back(rel);
    out.lateral_colour_um.push_back(ok ? (y[w_short] - y[w_long]) * 1e3 : 0.0);
    out.valid.push_back(ok ? 1 : 0);
  }
  return out;
}

std::string format_chromatic_text(const ChromaticFocalShift& s, const LateralColour& lc,
                                  const std::string& field_unit) {
  std::string out;
  auto line = [&](const std::string& t) { out += t + "\n"; };
  line(fmt::format(
      "Chromatic focal shift (paraxial focus less the primary's {:.4f} nm, {}):", s.primary_nm,
      s.band ? fmt::format("{} samples from {:g} to {:g} nm", s.wavelengths_nm.size(),
                           s.wavelengths_nm.front(), s.wavelengths_nm.back())
             : std::string("at the spec wavelengths")));
  line("  wavelength (nm)   shift (um)");
  // A band of many samples: every one up to 21, else about 21 of them (the JSON has all).
  const std::size_t step = std::max<std::size_t>(1, (s.wavelengths_nm.size() + 19) / 20);
  for (std::size_t i = 0; i < s.wavelengths_nm.size(); ++i)
    if (i % step == 0 || i + 1 == s.wavelengths_nm.size())
      line(fmt::format("  {:15.4f}   {:10.3f}", s.wavelengths_nm[i], s.shift_mm[i] * 1e3));
  line(
      fmt::format("  maximum focal shift range {:.3f} um; diffraction-limited depth 4 lambda "
                  "N_w^2 = {:.3f} um (N_w {:.4f})",
                  s.max_range_mm * 1e3, s.diffraction_depth_mm * 1e3, s.working_f_number));
  line("");
  line(
      fmt::format("Lateral colour (real chief rays on the image plane, {:.1f} less {:.1f} nm; "
                  "Airy radius {:.3f} um):",
                  lc.short_nm, lc.long_nm, lc.airy_radius_um));
  line(fmt::format("  {:>11}  angle (deg)  lateral colour (um)", "field (" + field_unit + ")"));
  for (std::size_t h = 0; h < lc.field_deg.size(); ++h)
    line(fmt::format("  {:11.3f}  {:11.3f}  {:>19}", lc.field_values[h], lc.field_deg[h],
                     lc.valid[h] ? fmt::format("{:.4f}", lc.lateral_colour_um[h])
                                 : std::string("n/a (a chief ray failed)")));
  return out;
}

std::string format_focal_shift_json(const ChromaticFocalShift& s) {
  nlohmann::json j;
  j["primary_wavelength_nm"] = finite_or_null(s.primary_nm);
  j["band"] = s.band;
  j["wavelengths_nm"] = s.wavelengths_nm;
  nlohmann::json shift = nlohmann::json::array();
  for (double v : s.shift_mm) shift.push_back(finite_or_null(v * 1e3));
  j["shift_um"] = shift;
  j["max_range_um"] = finite_or_null(s.max_range_mm * 1e3);
  j["diffraction_depth_um"] = finite_or_null(s.diffraction_depth_mm * 1e3);
  j["working_f_number"] = finite_or_null(s.working_f_number);
  return j.dump();
}

std::string format_lateral_colour_json(const LateralColour& lc) {
  nlohmann::json j;
  j["fields_deg"] = lc.field_deg;
  j["field_values"] = lc.field_values;
  j["wavelengths_nm"] = lc.wavelengths_nm;
  j["primary_wavelength_nm"] = finite_or_null(lc.primary_nm);
  j["short_nm"] = finite_or_null(lc.short_nm);
  j["long_nm"] = finite_or_null(lc.long_nm);
  j["airy_radius_um"] = finite_or_null(lc.airy_radius_um);
  nlohmann::json lateral = nlohmann::json::array(), rel = nlohmann::json::array();
  for (std::size_t h = 0; h < lc.field_deg.size(); ++h) {
    lateral.push_back(lc.valid[h] ? finite_or_null(lc.lateral_colour_um[h]) : nullptr);
    nlohmann::json row = nlohmann::json::array();
    for (double v : lc.relative_um[h])
      row.push_back(lc.valid[h] ? finite_or_null(v) : nlohmann::json(nullptr));
    rel.push_back(row);
  }
  j["lateral_colour_um"] = lateral;
  j["relative_to_primary_um"] = rel;
  return j.dump();
}

}  // namespace lensopt
