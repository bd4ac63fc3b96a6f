#include "lensopt/analysis/afocal.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <nlohmann/json.hpp>

#include "core/json_number.h"
#include "lensopt/analysis/angular_spot.h"
#include "lensopt/analysis/field_optics.h"
#include "lensopt/analysis/wave.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/paraxial/afocal.h"
#include "lensopt/paraxial/paraxial.h"

namespace lensopt {
namespace {

constexpr double kDeg = 180.0 / kPi;
constexpr double kArcminPerMrad = 1e-3 * 180.0 * 60.0 / kPi;

// The real chief ray of field h (pupil centre) at the primary wavelength, on the image plane.
RayBundle<double> trace_chief(const TraceSystem<double>& sys, int h) {
  PupilSamples centre;
  centre.x = {0.0};
  centre.y = {0.0};
  RayBundle<double> chief;
  start_rays(sys, h, sys.wavelength_count, chief, &centre);
  trace_bundle(sys.lens, sys.wavelength_count, sys.lens.surface_count(), true, chief,
               static_cast<RayRecord<double>*>(nullptr));
  return chief;
}

}  // namespace

AfocalFirstOrder afocal_first_order(const TraceSystem<double>& sys) {
  const TraceLens<double>& lens = sys.lens;
  const int k_count = lens.surface_count();
  const double nm = lens.reference_nm();
  AfocalFirstOrder out;
  out.image_space_index = lens.index_at_nm(k_count - 1, nm);
  out.entrance_pupil_diameter_mm = sys.epd_mm;
  out.entrance_pupil_z_mm = sys.entrance_pupil_z_mm;
  // The chief ray through the entrance-pupil centre at u = 1.
  const ParaxialRay<double> chief =
      paraxial_trace(lens, ParaxialRay<double>{-sys.entrance_pupil_z_mm, 1.0}, k_count, nm);
  const double u_chief = chief.w / out.image_space_index;
  // M (paraxial/afocal.h, the optimizer's solve and target use the same function).
  out.angular_magnification = paraxial_angular_magnification(lens, nm);
  out.exit_pupil_z_mm = -chief.y / u_chief;
  // The axial marginal ray through the entrance pupil's rim.
  const double r_ep = 0.5 * sys.epd_mm;
  ParaxialRay<double> marginal{r_ep, 0.0};
  if (!sys.object_at_infinity()) {
    const double u0 = r_ep / (sys.object_distance_mm + sys.entrance_pupil_z_mm);
    marginal = ParaxialRay<double>{u0 * sys.object_distance_mm, u0};
  }
  marginal = paraxial_trace(lens, marginal, k_count, nm);
  out.marginal_output_slope = marginal.w / out.image_space_index;
  out.exit_pupil_diameter_mm =
      2.0 * std::abs(marginal.y + out.marginal_output_slope * out.exit_pupil_z_mm);
  const ParaxialRay<double> collimated =
      paraxial_trace(lens, ParaxialRay<double>{1.0, 0.0}, k_count, nm);
  out.residual_power_diopters = -1000.0 * collimated.w;
  return out;
}

AfocalRayDirections::AfocalRayDirections(const TraceSystem<double>& sys)
    : rays_(sys.fields_deg.size()) {}

void AfocalRayDirections::operator()(int h, int w, const RayBundle<double>& rays) {
  Rays& out = rays_[h];
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (rays.status[i] != kRayOk) continue;
    out.l.push_back(rays.l[i]);
    out.m.push_back(rays.m[i]);
    out.n.push_back(rays.n[i]);
    out.wavelength.push_back(w);
  }
}

AngularSpot angular_spot(const TraceSystem<double>& sys, const AfocalRayDirections::Rays& rays,
                         bool keep_points) {
  AngularSpot out;
  const std::size_t count = rays.l.size();
  out.count = static_cast<int>(count);
  if (count == 0) return out;
  const SpotWeights weights = spot_weights(sys);
  const bool mirror = !sys.full_pupil;  // each ray stands for itself and (-l, m, n)
  std::vector<double> omega(count), ax(count), ay(count);
  for (std::size_t i = 0; i < count; ++i) omega[i] = weights.wavelength[rays.wavelength[i]];
  // The one implementation of the angular spot (analysis/angular_spot.h), as the optimizer's.
  const AngularSpotMoments<double> s =
      angular_spot_moments<double>(count, rays.l.data(), rays.m.data(), rays.n.data(), omega.data(),
                                   nullptr, mirror, ax.data(), ay.data());
  if (!s.ok) return out;
  out.centroid_l = s.d0[0];
  out.centroid_m = s.d0[1];
  out.centroid_n = s.d0[2];
  out.rms_mrad = 1e3 * std::sqrt(s.variance);
  if (keep_points) {
    for (std::size_t i = 0; i < count; ++i) {
      out.x_mrad.push_back(1e3 * (ax[i] - s.mean_x));
      out.y_mrad.push_back(1e3 * (ay[i] - s.mean_y));
      out.wavelength.push_back(rays.wavelength[i]);
      if (mirror) {
        out.x_mrad.push_back(-1e3 * ax[i]);
        out.y_mrad.push_back(1e3 * (ay[i] - s.mean_y));
        out.wavelength.push_back(rays.wavelength[i]);
      }
    }
  }
  return out;
}

void AfocalOptions::validate() const {
  if (pupil_samples < 8 || pupil_samples > 1024)
    throw Error(fmt::format("pupil samples = {} must be in [8, 1024]", pupil_samples));
  if (zernike_terms < 0 || zernike_terms > kMaxZernikeTerms)
    throw Error(
        fmt::format("Zernike terms = {} must be in [0, {}]", zernike_terms, kMaxZernikeTerms));
  if (zernike_terms > 0) zernike_term(zernike_ordering, zernike_terms);
  for (double v : wavelength_weights)
    if (!(v >= 0.0) || !std::isfinite(v))
      throw Error(fmt::format("wavelength weight {} must be finite and >= 0", v));
}

ReferenceSphere<double> afocal_reference_plane(const TraceSystem<double>& sys, int h) {
  const RayBundle<double> chief = trace_chief(sys, h);
  ReferenceSphere<double> out;
  out.plane = true;
  out.ok = chief.status[0] == kRayOk;
  out.centre_x_mm = chief.x[0];
  out.centre_y_mm = chief.y[0];
  out.plane_l = chief.l[0];
  out.plane_m = chief.m[0];
  out.plane_n = chief.n[0];
  // The chief ray's exit-pupil point: z_XP (from the image plane) along the chief ray.
  const double z_xp =
      exit_pupil_from_image_mm(sys.lens, sys.lens.wavelengths_nm[sys.wavelength_count]);
  out.radius_mm = chief.n[0] != 0.0 ? z_xp / chief.n[0] : 0.0;
  if (!std::isfinite(out.radius_mm)) out.radius_mm = 0.0;
  return out;
}

AfocalReport analyze_afocal(const TraceSystem<double>& sys, const AfocalRayDirections& directions,
                            const SpotResult<double>& spots, const AfocalOptions& options) {
  options.validate();
  AfocalReport r;
  r.first_order = afocal_first_order(sys);
  r.field_unit = sys.field_type == FieldType::kAngle ? "deg" : "mm";
  static const char* kKinds[] = {"angle", "object height", "paraxial image height",
                                 "real image height"};
  r.field_kind = kKinds[static_cast<int>(sys.field_type)];
  r.object_distance_mm = sys.object_at_infinity() ? 0.0 : sys.object_distance_mm;
  r.primary_wavelength_nm = sys.lens.reference_nm();
  r.wavelength_count = sys.wavelength_count;
  r.rays_per_field_wavelength = static_cast<int>(sys.pupil.size());
  r.full_pupil = sys.full_pupil;
  r.ray_failures = spots.total_failed;
  r.wavefront = options.wavefront;
  r.pupil_samples = options.wavefront ? options.pupil_samples : 0;
  r.zernike_terms = options.wavefront ? options.zernike_terms : 0;
  r.zernike_ordering = options.zernike_ordering;
  const double m_ang = r.first_order.angular_magnification;
  const int field_count = static_cast<int>(sys.fields_deg.size());
  std::vector<double> wl_weights = options.wavelength_weights;
  if (static_cast<int>(wl_weights.size()) != sys.wavelength_count)
    wl_weights = normalized_spot_weights(sys.wavelength_weights, sys.wavelength_count);
  const PupilGrid grid = options.wavefront ? make_pupil_grid(options.pupil_samples) : PupilGrid{};
  RayBundle<double> scratch_rays;
  RayRecord<double> scratch_record;
  const SpotWeights weights = spot_weights(sys);
  double spot_sum = 0;
  bool all_traced = true;
  for (int h = 0; h < field_count; ++h) {
    AfocalField f;
    f.field_deg = sys.fields_deg[h];
    f.field_value = sys.field_values[h];
    f.weight = sys.field_weights[h];
    f.traced_rays = spots.traced_rays[h];
    f.failed_rays = spots.failed_rays[h];
    f.vignetted_rays = spots.vignetted_rays[h];
    r.vignetted_rays += f.vignetted_rays;
    f.spot = angular_spot(sys, directions.rays(h), options.keep_points);
    if (f.spot.count > 0) {
      f.rms_angular_spot_mrad = f.spot.rms_mrad;
      spot_sum += weights.field[h] * f.spot.rms_mrad;
    } else {
      all_traced = false;
    }
    const RayBundle<double> chief = trace_chief(sys, h);
    f.chief_ok = chief.status[0] == kRayOk;
    const double tan_in = std::tan(f.field_deg / kDeg);
    f.paraxial_output_angle_deg = std::atan(m_ang * tan_in) * kDeg;
    if (f.chief_ok) {
      f.output_chief_angle_deg = std::atan2(chief.m[0], chief.n[0]) * kDeg;
      const double tan_out = chief.m[0] / chief.n[0];
      const double expected = m_ang * tan_in;
      f.angular_distortion_percent =
          expected != 0.0 ? 100.0 * (tan_out - expected) / expected : 0.0;
    }
    if (options.wavefront && f.chief_ok) {
      const ReferenceSphere<double> plane = afocal_reference_plane(sys, h);
      double sum_w = 0, sum_sq = 0, sum_strehl = 0, pv = 0;
      bool any = false;
      for (int w = 0; w < sys.wavelength_count; ++w) {
        if (!(wl_weights[w] > 0.0)) continue;
        const Wavefront<double> wf =
            compute_wavefront(sys, h, w, grid, plane, 0.0, scratch_rays, scratch_record);
        if (!wf.chief_ok || !(wf.valid_weight > 0.0)) continue;
        std::complex<double> field(0.0, 0.0);
        for (std::size_t i = 0; i < grid.size(); ++i)
          if (wf.ok[i])
            field += grid.weight[i] * std::polar(1.0, 2.0 * kPi * tilt_removed_opd(wf, grid, i));
        const double strehl = std::norm(field) / (wf.valid_weight * wf.valid_weight);
        sum_w += wl_weights[w];
        sum_sq += wl_weights[w] * wf.rms_waves * wf.rms_waves;
        sum_strehl += wl_weights[w] * strehl;
        pv = std::max(pv, wf.pv_waves);
        any = true;
      }
      if (any) {
        f.rms_wavefront_waves = std::sqrt(sum_sq / sum_w);
        f.pv_wavefront_waves = pv;
        f.strehl = sum_strehl / sum_w;
      }
      if (options.zernike_terms > 0) {
        const Wavefront<double> wf = compute_wavefront(sys, h, sys.wavelength_count, grid, plane,
                                                       0.0, scratch_rays, scratch_record);
        int arrived = 0;
        for (std::uint8_t k : wf.ok) arrived += k;
        if (wf.chief_ok && arrived >= options.zernike_terms)
          f.zernike_waves = fit_zernike(wf, grid, options.zernike_terms, options.zernike_ordering)
                                .coefficients_waves;
      }
    }
    r.fields.push_back(std::move(f));
  }
  if (all_traced && weights.field_sum > 0.0)
    r.mean_rms_angular_spot_mrad = spot_sum / weights.field_sum;
  return r;
}

AfocalReport analyze_afocal(const TraceSystem<double>& sys, const AfocalOptions& options) {
  AfocalRayDirections directions(sys);
  FieldOpticsOptions field_options;
  field_options.maps = false;
  field_options.threads = options.threads;
  const FieldOptics<double> measured = measure_fields(sys, field_options, directions);
  return analyze_afocal(sys, directions, measured.spots, options);
}

AfocalReport analyze_afocal_lens(const Lens& lens, const TraceOptions& trace,
                                 AfocalOptions options) {
  const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
  if (!lens.specs.afocal)
    throw Error(SourceLocation{where},
                "the lens is not in afocal mode (TOML [system] afocal = true, or .zmx FTYP's "
                "afocal image space flag)");
  const TraceSystem<double> sys = prepare_lens_system(lens, trace);
  if (options.wavelength_weights.empty())
    options.wavelength_weights = lens_wavelength_weights(lens, sys.wavelength_count);
  options.threads = trace.threads;
  AfocalReport r = analyze_afocal(sys, options);
  r.lens_name = lens.name;
  r.source_path = lens.source_path;
  r.rings = trace.rings;
  return r;
}

AfocalReport analyze_afocal_lens(const Lens& lens, const AnalyzeOptions& options) {
  AfocalOptions afocal;
  afocal.pupil_samples = options.wave_options.pupil_samples;
  afocal.wavelength_weights = options.wave_options.wavelength_weights;
  afocal.zernike_terms = options.wave_options.zernike_terms;
  afocal.zernike_ordering = options.wave_options.zernike_ordering;
  Lens traced = lens;
  if (options.dispersion) traced.specs.dispersion = *options.dispersion;
  return analyze_afocal_lens(traced, options.trace, afocal);
}

void refuse_afocal(const Lens& lens, std::string_view what, std::string_view why) {
  if (!lens.specs.afocal) return;
  throw Error(SourceLocation{lens.source_path.empty() ? lens.name : lens.source_path},
              fmt::format("{} cannot take an afocal lens (image at infinity, image space in "
                          "angle): {}; analyze reports its angular magnification, pupils, "
                          "angular spot and plane-wave wavefront, and plot --kind spot draws "
                          "its spot in angle",
                          what, why.empty() ? "it needs an image plane with a sensor on it" : why));
}

std::string format_afocal_text(const AfocalReport& r) {
  std::string out;
  auto line = [&](const std::string& s) { out += s + "\n"; };
  const AfocalFirstOrder& fo = r.first_order;
  line(fmt::format("Lens: {}{}", r.lens_name,
                   r.source_path.empty() ? "" : fmt::format(" ({})", r.source_path)));
  line("  afocal image space: image at infinity, measured in angle (no EFL, BFL or F-number)");
  line(fmt::format("  angular magnification    {:12.8f}", fo.angular_magnification));
  line(fmt::format("  entrance pupil diameter  {:12.6f} mm   at {:.6f} mm from the first vertex",
                   fo.entrance_pupil_diameter_mm, fo.entrance_pupil_z_mm));
  line(fmt::format("  exit pupil diameter      {:12.6f} mm   at {:.6f} mm from the last vertex",
                   fo.exit_pupil_diameter_mm, fo.exit_pupil_z_mm));
  line(
      fmt::format("  residual power           {:12.6g} diopters (marginal ray output slope "
                  "{:.3g} rad)",
                  fo.residual_power_diopters, fo.marginal_output_slope));
  line(
      fmt::format("  sampling: {} fields x {} wavelengths x {} {}-pupil rays ({} rings); "
                  "object {}, primary wavelength {} nm, fields by {}",
                  r.fields.size(), r.wavelength_count, r.rays_per_field_wavelength,
                  r.full_pupil ? "full" : "half", r.rings,
                  r.object_distance_mm > 0 ? fmt::format("at {} mm", r.object_distance_mm)
                                           : std::string("at infinity"),
                  r.primary_wavelength_nm, r.field_kind));
  line("");
  const std::string head = fmt::format("field ({})", r.field_unit);
  line(
      fmt::format("  {:>11}  angle (deg)  out chief (deg)  paraxial (deg)  ang. dist. (%)  "
                  "RMS spot (mrad)  (arcmin)  RMS WFE (waves)  Strehl  failed  vignetted",
                  head));
  auto opt = [](const std::optional<double>& v, const char* f) {
    return v ? fmt::format(fmt::runtime(f), *v) : std::string("n/a");
  };
  for (const AfocalField& f : r.fields)
    line(fmt::format(
        "  {:11.3f}  {:11.3f}  {:>15}  {:14.6f}  {:>14}  {:>15}  {:>8}  {:>15}  {:>6}  "
        "{:6d}  {:9d}",
        f.field_value, f.field_deg,
        f.chief_ok ? fmt::format("{:.6f}", f.output_chief_angle_deg) : "n/a",
        f.paraxial_output_angle_deg,
        f.chief_ok ? fmt::format("{:.5f}", f.angular_distortion_percent) : "n/a",
        opt(f.rms_angular_spot_mrad, "{:.5f}"),
        f.rms_angular_spot_mrad ? fmt::format("{:.4f}", *f.rms_angular_spot_mrad * kArcminPerMrad)
                                : "n/a",
        opt(f.rms_wavefront_waves, "{:.5f}"), opt(f.strehl, "{:.4f}"), f.failed_rays,
        f.vignetted_rays));
  line("");
  line(fmt::format("  mean RMS angular spot: {}",
                   r.mean_rms_angular_spot_mrad
                       ? fmt::format("{:.5f} mrad ({:.4f} arcmin)", *r.mean_rms_angular_spot_mrad,
                                     *r.mean_rms_angular_spot_mrad * kArcminPerMrad)
                       : std::string("n/a (a field has no traced ray)")));
  if (r.wavefront)
    line(
        fmt::format("  wavefront: against a plane wave normal to the chief ray at the exit "
                    "pupil, piston and tilt removed, {} x {} pupil cells",
                    r.pupil_samples, r.pupil_samples));
  if (r.zernike_terms > 0)
    for (const AfocalField& f : r.fields) {
      if (f.zernike_waves.empty()) continue;
      std::string row = fmt::format(
          "  Zernike ({}, waves) field {:.4g} {}:", zernike_ordering_name(r.zernike_ordering),
          f.field_value, r.field_unit);
      for (std::size_t j = 0; j < f.zernike_waves.size(); ++j)
        row += fmt::format(" Z{}{:+.5f}", j + 1, f.zernike_waves[j]);
      line(row);
    }
  line(r.ray_failures == 0 ? "  ray failures: none"
                           : fmt::format("  ray failures: {}", r.ray_failures));
  if (r.vignetted_rays > 0)
    line(fmt::format("  vignetted rays (clear apertures): {}", r.vignetted_rays));
  return out;
}

std::string format_afocal_json(const AfocalReport& r) {
  using nlohmann::json;
  const AfocalFirstOrder& fo = r.first_order;
  json j;
  j["lens"] = r.lens_name;
  j["source"] = r.source_path;
  j["afocal"] = true;
  j["angular_magnification"] = finite_or_null(fo.angular_magnification);
  j["epd_mm"] = finite_or_null(fo.entrance_pupil_diameter_mm);
  j["entrance_pupil_z_mm"] = finite_or_null(fo.entrance_pupil_z_mm);
  j["exit_pupil_diameter_mm"] = finite_or_null(fo.exit_pupil_diameter_mm);
  j["exit_pupil_z_mm"] = finite_or_null(fo.exit_pupil_z_mm);
  j["residual_power_diopters"] = finite_or_null(fo.residual_power_diopters);
  j["marginal_output_slope_rad"] = finite_or_null(fo.marginal_output_slope);
  j["image_space_index"] = finite_or_null(fo.image_space_index);
  j["field_unit"] = r.field_unit;
  j["field_kind"] = r.field_kind;
  j["object_at_infinity"] = !(r.object_distance_mm > 0);
  j["object_distance_mm"] =
      r.object_distance_mm > 0 ? finite_or_null(r.object_distance_mm) : json(0.0);
  j["primary_wavelength_nm"] = finite_or_null(r.primary_wavelength_nm);
  j["wavelength_count"] = r.wavelength_count;
  j["rings"] = r.rings;
  j["rays_per_field_wavelength"] = r.rays_per_field_wavelength;
  j["full_pupil"] = r.full_pupil;
  auto opt = [](const std::optional<double>& v) { return v ? finite_or_null(*v) : json(nullptr); };
  json fields = json::array();
  for (const AfocalField& f : r.fields) {
    json o;
    o["field_deg"] = finite_or_null(f.field_deg);
    o["field_value"] = finite_or_null(f.field_value);
    o["weight"] = finite_or_null(f.weight);
    o["traced_rays"] = f.traced_rays;
    o["failed_rays"] = f.failed_rays;
    o["vignetted_rays"] = f.vignetted_rays;
    o["chief_ok"] = f.chief_ok;
    o["output_chief_angle_deg"] =
        f.chief_ok ? finite_or_null(f.output_chief_angle_deg) : json(nullptr);
    o["paraxial_output_angle_deg"] = finite_or_null(f.paraxial_output_angle_deg);
    o["angular_distortion_percent"] =
        f.chief_ok ? finite_or_null(f.angular_distortion_percent) : json(nullptr);
    o["rms_angular_spot_mrad"] = opt(f.rms_angular_spot_mrad);
    o["rms_angular_spot_arcmin"] = f.rms_angular_spot_mrad
                                       ? finite_or_null(*f.rms_angular_spot_mrad * kArcminPerMrad)
                                       : json(nullptr);
    o["centroid_direction_cosines"] = {finite_or_null(f.spot.centroid_l),
                                       finite_or_null(f.spot.centroid_m),
                                       finite_or_null(f.spot.centroid_n)};
    if (r.wavefront) {
      o["rms_wavefront_waves"] = opt(f.rms_wavefront_waves);
      o["pv_wavefront_waves"] = opt(f.pv_wavefront_waves);
      o["strehl"] = opt(f.strehl);
    }
    if (r.zernike_terms > 0) {
      json z = json::array();
      for (double v : f.zernike_waves) z.push_back(finite_or_null(v));
      o["zernike_waves"] = z;
    }
    fields.push_back(o);
  }
  j["fields"] = fields;
  j["mean_rms_angular_spot_mrad"] = opt(r.mean_rms_angular_spot_mrad);
  j["ray_failures"] = r.ray_failures;
  j["vignetted_rays"] = r.vignetted_rays;
  if (r.wavefront) {
    j["wavefront_reference"] = "plane wave normal to the chief ray at the exit pupil";
    j["pupil_samples"] = r.pupil_samples;
  }
  if (r.zernike_terms > 0) {
    j["zernike_terms"] = r.zernike_terms;
    j["zernike_ordering"] = zernike_ordering_name(r.zernike_ordering);
  }
  return j.dump(2, ' ', false, json::error_handler_t::replace);
}

}  // namespace lensopt
