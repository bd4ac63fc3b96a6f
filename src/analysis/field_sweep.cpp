#include "lensopt/analysis/field_sweep.h"

#include <fmt/format.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "core/json_number.h"
#include "lensopt/analysis/field_optics.h"
#include "lensopt/core/error.h"

namespace lensopt {

TraceSystem<double> field_sweep_system(const Lens& lens, const TraceSystem<double>& sys,
                                       const TraceOptions& trace, int fields) {
  if (fields < 2 || fields > 1001)
    throw Error(fmt::format("field sweep: {} fields must be in 2..1001", fields));
  TraceOptions fine = trace;
  fine.fields = fields;
  fine.scale_to_spec = false;
  // The lens's own setup (aperture, object distance), sampled at `fields` angles up to its
  // largest chief-ray angle; the lens of `sys` is already scaled.
  SystemSetup setup = specs_setup(lens.specs, fine, !lens.breaks_symmetry());
  setup.scale = false;
  if (lens.specs.mode == SpecMode::kPaper) {
    setup.aperture_type = ApertureType::kFNumber;
    setup.f_number = lens.specs.f_number;
  }
  if (setup.aperture_type == ApertureType::kFloatByStop)
    setup.stop_semi_diameter_mm = value_of(sys.stop_radius_mm);
  setup.field_type = FieldType::kAngle;
  double theta_max = 0;
  for (double f : sys.fields_deg) theta_max = std::max(theta_max, std::abs(f));
  setup.field_values = field_angles_deg(theta_max, fields);
  setup.field_weights.clear();
  setup.vignetting.clear();
  return prepare_system(sys.lens, setup, fine);
}

FieldSweep field_sweep(const TraceSystem<double>& sys, const WaveOptions& wave,
                       const std::vector<double>& frequencies_cyc_mm, bool mtf) {
  FieldSweep out;
  out.field_deg = sys.fields_deg;
  FieldOpticsOptions field_options;
  field_options.threads = wave.threads;
  const FieldOptics<double> measured = measure_fields(sys, field_options);
  for (std::size_t h = 0; h < sys.fields_deg.size(); ++h) {
    const bool ok = measured.spots.traced_rays[h] > 0;
    out.spot_valid.push_back(ok ? 1 : 0);
    out.rms_spot_um.push_back(ok ? measured.spots.rms_spot_mm[h] * 1000.0 : 0.0);
    out.distortion_percent.push_back(100.0 * measured.distortion[h]);
  }
  if (!mtf) return out;
  out.frequencies_cyc_mm = frequencies_cyc_mm;
  WaveOptions options = wave;
  options.keep_psf = false;
  options.geometric = false;
  const WaveReport r = analyze_wave(sys, options, frequencies_cyc_mm);
  out.warnings = r.warnings;
  out.mtf_t.assign(frequencies_cyc_mm.size(), std::vector<double>(r.fields.size(), 0.0));
  out.mtf_s = out.mtf_t;
  for (std::size_t h = 0; h < r.fields.size(); ++h)
    for (std::size_t k = 0; k < frequencies_cyc_mm.size(); ++k) {
      out.mtf_t[k][h] = r.fields[h].mtf_t[k];
      out.mtf_s[k][h] = r.fields[h].mtf_s[k];
    }
  return out;
}

std::string format_field_sweep_json(const FieldSweep& s) {
  using nlohmann::json;
  auto arr = [](const std::vector<double>& v) {
    json a = json::array();
    for (double x : v) a.push_back(finite_or_null(x));
    return a;
  };
  json j;
  j["fields_deg"] = arr(s.field_deg);
  json spot = json::array();
  for (std::size_t h = 0; h < s.rms_spot_um.size(); ++h)
    spot.push_back(s.spot_valid[h] ? finite_or_null(s.rms_spot_um[h]) : json(nullptr));
  j["rms_spot_um"] = spot;
  j["distortion_percent"] = arr(s.distortion_percent);
  j["frequencies_cyc_mm"] = arr(s.frequencies_cyc_mm);
  json t = json::array(), sg = json::array();
  for (const auto& v : s.mtf_t) t.push_back(arr(v));
  for (const auto& v : s.mtf_s) sg.push_back(arr(v));
  j["mtf_t"] = t;
  j["mtf_s"] = sg;
  j["warnings"] = s.warnings;
  return j.dump();
}

}  // namespace lensopt
