#include "lensopt/analysis/analyze.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/json_number.h"
#include "lensopt/analysis/field_optics.h"
#include "lensopt/analysis/forms_image.h"
#include "lensopt/core/error.h"
#include "lensopt/lens/validate.h"
#include "lensopt/paraxial/paraxial.h"

namespace lensopt {
namespace {

std::string dispersion_name(DispersionModel m) {
  return m == DispersionModel::kAbbe ? "abbe" : "catalog";
}

}  // namespace

AnalysisReport analyze_lens(const Lens& lens_in, const AnalyzeOptions& options) {
  options.trace.validate();
  Lens lens = lens_in;
  if (options.dispersion) lens.specs.dispersion = *options.dispersion;
  const TraceSystem<double> sys = prepare_lens_system(lens, options.trace);
  FieldOpticsOptions field_options;
  field_options.threads = options.trace.threads;
  const FieldOptics<double> measured = measure_fields(sys, field_options);
  const SpotResult<double>& spots = measured.spots;

  AnalysisReport r;
  r.lens_name = lens.name;
  r.source_path = lens.source_path;
  r.scale = sys.scale;
  r.efl_mm = sys.efl_mm;
  r.bfl_mm = sys.bfl_mm;
  r.epd_mm = sys.epd_mm;
  r.f_number = sys.efl_mm / sys.epd_mm;
  r.image_distance_mm = sys.lens.thickness_mm.back();
  r.virtual_image = sys.object_at_infinity() && sys.bfl_mm < 0;
  {
    // The paraxial chief ray through the entrance-pupil centre at unit slope: y_0 = -z_EP,
    // w_0 = 1; in image space (air) its slope is the angular magnification.
    const ParaxialRay<double> chief =
        paraxial_trace(sys.lens, ParaxialRay<double>{-sys.entrance_pupil_z_mm, 1.0},
                       sys.lens.surface_count(), sys.lens.reference_nm());
    r.angular_magnification = chief.w;
  }
  r.entrance_pupil_z_mm = sys.entrance_pupil_z_mm;
  r.stop_radius_mm = sys.stop_radius_mm;
  r.total_track_mm = 0;
  for (double t : sys.lens.thickness_mm) r.total_track_mm += t;
  r.rings = options.trace.rings;
  r.rays_per_field_wavelength = static_cast<int>(sys.pupil.size());
  r.full_pupil = sys.full_pupil;
  r.wavelength_count = sys.wavelength_count;
  r.ray_aiming = options.trace.ray_aiming;
  r.dispersion = dispersion_name(lens.specs.dispersion);
  r.ray_failures = spots.total_failed;
  r.failures_by_surface = spots.failed_by_surface;
  r.vignetted_by_surface.assign(sys.lens.surface_count(), 0);
  for (std::size_t h = 0; h < spots.vignetted_by_field_surface.size(); ++h)
    for (int k = 0; k < sys.lens.surface_count(); ++k) {
      r.vignetted_by_surface[k] += spots.vignetted_by_field_surface[h][k];
      r.vignetted_rays += spots.vignetted_by_field_surface[h][k];
    }
  static const char* kKinds[] = {"angle", "object height", "paraxial image height",
                                 "real image height"};
  r.field_kind = kKinds[static_cast<int>(sys.field_type)];
  r.field_unit = sys.field_type == FieldType::kAngle ? "deg" : "mm";
  r.spec_mode = lens.specs.mode == SpecMode::kPaper ? "paper" : "as-written";
  static const char* kApertures[] = {"f-number", "entrance pupil diameter", "object-space NA",
                                     "float by stop size"};
  r.aperture = lens.specs.mode == SpecMode::kPaper
                   ? "f-number"
                   : kApertures[static_cast<int>(lens.specs.aperture_type)];
  r.object_distance_mm = sys.object_at_infinity() ? 0.0 : sys.object_distance_mm;
  r.primary_wavelength_nm = sys.lens.reference_nm();

  const int field_count = static_cast<int>(sys.fields_deg.size());

  double spot_sum = 0, weight_sum = 0;
  bool all_fields_traced = true;
  for (int h = 0; h < field_count; ++h) {
    FieldReport f;
    f.field_deg = sys.fields_deg[h];
    f.field_value = sys.field_values[h];
    f.weight = sys.field_weights[h];
    f.vignetted_rays = spots.vignetted_rays[h];
    f.traced_rays = spots.traced_rays[h];
    f.failed_rays = spots.failed_rays[h];
    if (f.traced_rays > 0) {
      f.rms_spot_um = spots.rms_spot_mm[h] * 1000.0;
      spot_sum += f.weight * *f.rms_spot_um;
      weight_sum += f.weight;
    } else {
      all_fields_traced = false;
    }
    f.centroid_y_mm = spots.centroid_y_mm[h];
    f.centroid_x_mm = spots.centroid_x_mm[h];
    f.reference_y_mm = measured.reference_y_mm[h];
    f.azimuth_deg = sys.field_azimuth(h);
    f.field_x = f.field_value * std::sin(f.azimuth_deg * kPi / 180.0);
    f.field_y = f.azimuth_deg == 0.0 ? f.field_value
                                     : f.field_value * std::cos(f.azimuth_deg * kPi / 180.0);
    sys.field_to_lens(h, f.centroid_x_mm, f.centroid_y_mm, f.image_centroid_x_mm,
                      f.image_centroid_y_mm);
    sys.field_to_lens(h, 0.0, f.reference_y_mm, f.image_reference_x_mm, f.image_reference_y_mm);
    f.distortion_percent = 100.0 * measured.distortion[h];
    if (measured.relative_illumination_known[h])
      f.relative_illumination = measured.relative_illumination[h];
    else
      f.relative_illumination_unknown = measured.relative_illumination_unknown[h];
    // Ray-aiming error over all wavelengths (and the reference one).
    double worst = 0;
    for (int w = 0; w <= sys.wavelength_count; ++w) {
      const auto stop = aimed_stop_coordinates(sys, h, w);
      const double rs = sys.stop_radius_mm;
      worst = std::max({worst, std::abs(stop[0] - rs) / rs, std::abs(stop[1] + rs) / rs,
                        std::abs(stop[2] - rs) / rs});
    }
    f.aiming_error = std::isfinite(worst) ? worst : 1.0;
    r.max_aiming_error = std::max(r.max_aiming_error, f.aiming_error);
    r.fields.push_back(f);
  }
  if (all_fields_traced && weight_sum > 0.0 && std::isfinite(spot_sum))
    r.mean_rms_spot_um = spot_sum / weight_sum;
  if (options.wave) {
    // The lens's wavelength weights unless the options give their own.
    WaveOptions wave = options.wave_options;
    if (wave.wavelength_weights.empty())
      wave.wavelength_weights = lens_wavelength_weights(lens, sys.wavelength_count);
    r.wave = analyze_wave(sys, wave, options.mtf_frequencies_cyc_mm);
  }
  return r;
}

void check_forms_image(const AnalysisReport& r) {
  std::vector<std::string> problems;
  auto need = [&](double v, const char* what, bool positive) {
    if (!std::isfinite(v) || (positive && !(v > 0)))
      problems.push_back(fmt::format("{} is {}", what, v));
  };
  if (r.fields.empty()) problems.push_back("it has no field");
  // Any sign of power forms an image (a diverging lens a virtual one); an afocal lens forms
  // none at a finite distance: its image space is in angle.
  if (!std::isfinite(r.efl_mm) || std::abs(r.efl_mm) > kMaxFocalLengthMm)
    problems.push_back(fmt::format(
        "it is afocal (no finite focal length: paraxial EFL {:g} mm, angular magnification "
        "{:.6g}): its image is at infinity, and this analysis measures spots on an image "
        "plane; afocal mode ([system] afocal = true, a .zmx FTYP afocal flag) measures it in "
        "angle (analysis/afocal.h)",
        r.efl_mm, r.angular_magnification));
  else
    need(r.efl_mm, "the focal length (mm)", false);
  if (std::isfinite(r.efl_mm) && r.efl_mm == 0) problems.push_back("the focal length is 0");
  need(r.bfl_mm, "the back focal length (mm)", false);
  need(r.epd_mm, "the entrance pupil diameter (mm)", true);
  need(r.f_number, "the f-number", false);
  need(r.scale, "the scale to the spec focal length", true);
  need(r.entrance_pupil_z_mm, "the entrance pupil position (mm)", false);
  need(r.stop_radius_mm, "the stop radius (mm)", true);
  need(r.total_track_mm, "the total track (mm)", false);
  for (const FieldReport& f : r.fields) {
    if (f.traced_rays == 0) {
      problems.push_back(fmt::format("no ray of field {:g} deg reaches the image", f.field_deg));
      continue;
    }
    if (!f.rms_spot_um || !std::isfinite(*f.rms_spot_um) || !std::isfinite(f.distortion_percent) ||
        (f.relative_illumination && !std::isfinite(*f.relative_illumination)) ||
        !std::isfinite(f.centroid_y_mm))
      problems.push_back(
          fmt::format("field {:g} deg has a non-finite spot, distortion or "
                      "illumination",
                      f.field_deg));
  }
  if (problems.empty()) return;
  if (problems.size() > 4) {
    const std::size_t more = problems.size() - 3;
    problems.resize(3);
    problems.push_back(fmt::format("{} more", more));
  }
  std::string text;
  for (const std::string& p : problems) text += (text.empty() ? "" : "; ") + p;
  throw Error(SourceLocation{r.source_path.empty() ? r.lens_name : r.source_path},
              "the lens does not form an image: " + text);
}

std::string format_report_text(const AnalysisReport& r) {
  std::string out;
  auto line = [&](const std::string& s) { out += s + "\n"; };
  line(fmt::format("Lens: {}{}", r.lens_name,
                   r.source_path.empty() ? "" : fmt::format(" ({})", r.source_path)));
  line(fmt::format("  effective focal length   {:10.4f} mm   (prescription scaled by {:.6f})",
                   r.efl_mm, r.scale));
  line(fmt::format("  back focal length        {:10.4f} mm", r.bfl_mm));
  if (r.virtual_image)
    line(
        fmt::format("  image                    virtual: the paraxial image lies {:.4f} mm "
                    "before the last vertex; image plane at {:.4f} mm{}",
                    -r.bfl_mm, r.image_distance_mm,
                    r.image_distance_mm < 0 ? " (rays traced back to it)" : ""));
  line(fmt::format("  angular magnification    {:10.6f}", r.angular_magnification));
  line(fmt::format("  f-number                 {:10.4f}", r.f_number));
  line(fmt::format("  entrance pupil diameter  {:10.4f} mm   at {:.4f} mm from the first vertex",
                   r.epd_mm, r.entrance_pupil_z_mm));
  line(fmt::format("  stop radius (real ray)   {:10.4f} mm", r.stop_radius_mm));
  line(fmt::format("  total track              {:10.4f} mm", r.total_track_mm));
  line(fmt::format(
      "  sampling: {} fields x {} wavelengths x {} {}-pupil rays ({} rings), "
      "ray aiming {}, dispersion {}",
      r.fields.size(), r.wavelength_count, r.rays_per_field_wavelength,
      r.full_pupil ? "full" : "half", r.rings, r.ray_aiming ? "on" : "off", r.dispersion));
  line(
      fmt::format("  system: spec mode {}, aperture {}, object {}, primary wavelength {} nm, "
                  "fields by {}",
                  r.spec_mode, r.aperture,
                  r.object_distance_mm > 0 ? fmt::format("at {} mm", r.object_distance_mm)
                                           : std::string("at infinity"),
                  r.primary_wavelength_nm, r.field_kind));
  line("");
  const std::string head = fmt::format("field ({})", r.field_unit);
  line(
      fmt::format("  {:>11}  angle (deg)  RMS spot (um)  distortion (%)  rel. illum.  "
                  "aiming err (%)  failed rays  vignetted",
                  head));
  for (const FieldReport& f : r.fields) {
    line(fmt::format("  {:11.3f}  {:11.3f}  {:>13}  {:14.4f}  {:>11}  {:14.4f}  {:11d}  {:9d}",
                     f.field_value, f.field_deg,
                     f.rms_spot_um ? fmt::format("{:.3f}", *f.rms_spot_um) : std::string("n/a"),
                     f.distortion_percent,
                     f.relative_illumination ? fmt::format("{:.4f}", *f.relative_illumination)
                                             : std::string("n/a"),
                     100.0 * f.aiming_error, f.failed_rays, f.vignetted_rays));
  }
  bool off_y = false;
  for (const FieldReport& f : r.fields) off_y = off_y || f.azimuth_deg != 0.0;
  if (off_y) {  // fields off the y axis: where each field and its image lie
    line("");
    line(fmt::format("  {:>22}  {:>9}  {:>26}  {:>26}",
                     fmt::format("field x, y ({})", r.field_unit), "azimuth",
                     "image centroid x, y (mm)", "paraxial chief x, y (mm)"));
    for (const FieldReport& f : r.fields)
      line(
          fmt::format("  {:>10.4f}, {:>10.4f}  {:9.3f}  {:>12.6f}, {:>12.6f}  {:>12.6f}, {:>12.6f}",
                      f.field_x, f.field_y, f.azimuth_deg, f.image_centroid_x_mm,
                      f.image_centroid_y_mm, f.image_reference_x_mm, f.image_reference_y_mm));
  }
  line("");
  line(fmt::format("  mean RMS spot: {}", r.mean_rms_spot_um
                                              ? fmt::format("{:.3f} um", *r.mean_rms_spot_um)
                                              : std::string("n/a (a field has no traced ray)")));
  if (r.ray_failures == 0) {
    line("  ray failures: none");
  } else {
    std::string where;
    for (std::size_t k = 0; k < r.failures_by_surface.size(); ++k)
      if (r.failures_by_surface[k] > 0)
        where += fmt::format("{}surface {}: {}", where.empty() ? "" : ", ", k + 1,
                             r.failures_by_surface[k]);
    std::string fields;
    for (const FieldReport& f : r.fields)
      if (f.failed_rays > 0)
        fields += fmt::format("{}{:.4g}", fields.empty() ? "" : ", ", f.field_value);
    line(fmt::format("  ray failures: {} ({}); fields affected ({}): {}", r.ray_failures, where,
                     r.field_unit, fields));
  }
  if (r.vignetted_rays > 0) {
    std::string where;
    for (std::size_t k = 0; k < r.vignetted_by_surface.size(); ++k)
      if (r.vignetted_by_surface[k] > 0)
        where += fmt::format("{}surface {}: {}", where.empty() ? "" : ", ", k + 1,
                             r.vignetted_by_surface[k]);
    line(fmt::format("  vignetted rays (clear apertures): {} ({})", r.vignetted_rays, where));
  }
  for (const FieldReport& f : r.fields)
    if (!f.relative_illumination && !f.relative_illumination_unknown.empty())
      line(fmt::format("  relative illumination n/a at field {:.4g} {}: {}", f.field_value,
                       r.field_unit, f.relative_illumination_unknown));
  line(fmt::format("  largest ray-aiming error: {:.4f} % of the stop radius",
                   100.0 * r.max_aiming_error));
  if (r.wave) out += format_wave_text(*r.wave);
  return out;
}

std::string format_report_json(const AnalysisReport& r) {
  using nlohmann::json;
  json j;
  j["lens"] = r.lens_name;
  j["source"] = r.source_path;
  j["scale"] = finite_or_null(r.scale);
  j["efl_mm"] = finite_or_null(r.efl_mm);
  j["bfl_mm"] = finite_or_null(r.bfl_mm);
  j["f_number"] = finite_or_null(r.f_number);
  j["image_distance_mm"] = finite_or_null(r.image_distance_mm);
  j["virtual_image"] = r.virtual_image;
  j["angular_magnification"] = finite_or_null(r.angular_magnification);
  j["epd_mm"] = finite_or_null(r.epd_mm);
  j["entrance_pupil_z_mm"] = finite_or_null(r.entrance_pupil_z_mm);
  j["stop_radius_mm"] = finite_or_null(r.stop_radius_mm);
  j["total_track_mm"] = finite_or_null(r.total_track_mm);
  j["rings"] = r.rings;
  j["rays_per_field_wavelength"] = r.rays_per_field_wavelength;
  j["full_pupil"] = r.full_pupil;
  j["wavelength_count"] = r.wavelength_count;
  j["ray_aiming"] = r.ray_aiming;
  j["dispersion"] = r.dispersion;
  json fields = json::array(), spots = json::array(), distortion = json::array(),
       ri = json::array(), failed = json::array(), centroid = json::array(), aiming = json::array();
  for (const FieldReport& f : r.fields) {
    fields.push_back(f.field_deg);
    spots.push_back(f.rms_spot_um ? finite_or_null(*f.rms_spot_um) : json(nullptr));
    distortion.push_back(finite_or_null(f.distortion_percent));
    ri.push_back(f.relative_illumination ? finite_or_null(*f.relative_illumination)
                                         : json(nullptr));
    failed.push_back(f.failed_rays);
    centroid.push_back(finite_or_null(f.centroid_y_mm));
    aiming.push_back(finite_or_null(f.aiming_error));
  }
  j["fields_deg"] = fields;
  json values = json::array(), weights = json::array(), vignetted = json::array();
  for (const FieldReport& f : r.fields) {
    values.push_back(finite_or_null(f.field_value));
    weights.push_back(finite_or_null(f.weight));
    vignetted.push_back(f.vignetted_rays);
  }
  j["field_values"] = values;
  j["field_unit"] = r.field_unit;
  j["field_kind"] = r.field_kind;
  j["field_weights"] = weights;
  j["spec_mode"] = r.spec_mode;
  j["aperture"] = r.aperture;
  // An object at infinity is written as object_at_infinity = true and a distance of 0 (no null
  // or infinity in an output).
  j["object_at_infinity"] = !(r.object_distance_mm > 0);
  j["object_distance_mm"] =
      r.object_distance_mm > 0 ? finite_or_null(r.object_distance_mm) : json(0.0);
  j["primary_wavelength_nm"] = finite_or_null(r.primary_wavelength_nm);
  j["vignetted_rays"] = r.vignetted_rays;
  j["vignetted_rays_per_field"] = vignetted;
  j["vignetted_rays_per_surface"] = r.vignetted_by_surface;
  j["rms_spot_um"] = spots;
  j["mean_rms_spot_um"] = r.mean_rms_spot_um ? finite_or_null(*r.mean_rms_spot_um) : json(nullptr);
  j["distortion_percent"] = distortion;
  j["relative_illumination"] = ri;
  // Why an illumination is null (unknown, never a guessed number); written only when one is.
  bool any_unknown = false;
  for (const FieldReport& f : r.fields) any_unknown = any_unknown || !f.relative_illumination;
  if (any_unknown) {
    json notes = json::array();
    for (const FieldReport& f : r.fields)
      notes.push_back(f.relative_illumination ? std::string()
                                              : (f.relative_illumination_unknown.empty()
                                                     ? std::string("unknown")
                                                     : f.relative_illumination_unknown));
    j["relative_illumination_notes"] = notes;
  }
  j["centroid_y_mm"] = centroid;
  bool off_y = false;
  for (const FieldReport& f : r.fields) off_y = off_y || f.azimuth_deg != 0.0;
  if (off_y) {  // fields off the y axis: both coordinates of each field and of its image
    json fx = json::array(), fy = json::array(), az = json::array(), ix = json::array(),
         iy = json::array(), rx = json::array(), ry = json::array();
    for (const FieldReport& f : r.fields) {
      fx.push_back(finite_or_null(f.field_x));
      fy.push_back(finite_or_null(f.field_y));
      az.push_back(finite_or_null(f.azimuth_deg));
      ix.push_back(finite_or_null(f.image_centroid_x_mm));
      iy.push_back(finite_or_null(f.image_centroid_y_mm));
      rx.push_back(finite_or_null(f.image_reference_x_mm));
      ry.push_back(finite_or_null(f.image_reference_y_mm));
    }
    j["field_x"] = fx;
    j["field_y"] = fy;
    j["field_azimuth_deg"] = az;
    j["image_centroid_x_mm"] = ix;
    j["image_centroid_y_mm"] = iy;
    j["image_reference_x_mm"] = rx;
    j["image_reference_y_mm"] = ry;
  }
  if (r.full_pupil) {  // the x centroids (0 by symmetry on a half pupil, and then not written)
    json centroid_x = json::array();
    for (const FieldReport& f : r.fields) centroid_x.push_back(finite_or_null(f.centroid_x_mm));
    j["centroid_x_mm"] = centroid_x;
  }
  j["aiming_error"] = aiming;
  j["max_aiming_error"] = finite_or_null(r.max_aiming_error);
  j["ray_failures"] = r.ray_failures;
  j["ray_failures_per_field"] = failed;
  j["ray_failures_per_surface"] = r.failures_by_surface;
  if (r.wave) j["wave"] = nlohmann::json::parse(format_wave_json(*r.wave));
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace lensopt
