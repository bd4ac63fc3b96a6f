#include "lensopt/plot/plot_data.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "lensopt/analysis/field_sweep.h"
#include "lensopt/core/error.h"
#include "lensopt/render/psf.h"
#include "lensopt/trace/kernel.h"

namespace lensopt::plot {
namespace {

void trace_to_image(const TraceSystem<double>& sys, int w, RayBundle<double>& rays) {
  trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
               static_cast<RayRecord<double>*>(nullptr));
}

void validate_fractions(const std::vector<double>& fractions, const char* what) {
  if (fractions.empty()) throw Error(fmt::format("{}: no field fractions given", what));
  for (double f : fractions)
    if (!(f >= 0.0 && f <= 1.0))
      throw Error(fmt::format("{}: field fraction {} is outside [0, 1]", what, f));
}

}  // namespace

std::string glass_label(const Material& material) {
  switch (material.kind) {
    case Material::Kind::kAir:
      return "air";
    case Material::Kind::kCatalog:
      return material.glass_name;
    case Material::Kind::kModel:
      return fmt::format("{:.4f}/{:.1f}", material.nd, material.vd);
  }
  return material.label();
}

PlotContext make_plot_context(const Lens& lens, const TraceOptions& trace) {
  lens.validate();
  trace.validate();
  PlotContext ctx;
  ctx.lens = lens;
  ctx.trace = trace;
  AnalyzeOptions options;
  options.trace = trace;
  ctx.report = analyze_lens(lens, options);
  ctx.sys = prepare_lens_system(lens, trace);

  const std::vector<double>& nm = lens.specs.wavelengths_nm;
  const int count = static_cast<int>(nm.size());
  ctx.wavelength_channel.resize(count);
  for (int w = 0; w < count; ++w) {
    if (static_cast<int>(lens.specs.wavelength_channels.size()) == count)
      ctx.wavelength_channel[w] = lens.specs.wavelength_channels[w];
    else  // no channels given: split the visible range
      ctx.wavelength_channel[w] = nm[w] >= 580 ? 0 : nm[w] >= 500 ? 1 : 2;
  }
  for (int c = 0; c < 3; ++c) {
    std::vector<int> members;
    for (int w = 0; w < count; ++w)
      if (ctx.wavelength_channel[w] == c) members.push_back(w);
    std::sort(members.begin(), members.end(), [&](int a, int b) { return nm[a] < nm[b]; });
    if (!members.empty()) ctx.channel_wavelength[c] = members[members.size() / 2];
  }
  // A channel without a wavelength shows the one that feeds it (render/psf.h).
  const auto feeds = channel_wavelengths(ctx.wavelength_channel, nm);
  for (int c = 0; c < 3; ++c)
    if (!feeds[c].empty() && std::find(ctx.wavelength_channel.begin(), ctx.wavelength_channel.end(),
                                       c) == ctx.wavelength_channel.end())
      ctx.channel_wavelength[c] = feeds[c].front();
  return ctx;
}

std::vector<int> field_indices(const PlotContext& ctx, const std::vector<double>& fractions) {
  const std::vector<double>& fields = ctx.sys.fields_deg;
  const double hfov = fields.back();
  std::vector<int> out;
  for (double f : fractions) {
    int best = 0;
    for (int h = 1; h < static_cast<int>(fields.size()); ++h)
      if (std::abs(fields[h] - f * hfov) < std::abs(fields[best] - f * hfov)) best = h;
    out.push_back(best);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::string field_label(const TraceSystem<double>& sys, int h) {
  const bool written = h < static_cast<int>(sys.field_values.size());
  const double a = sys.field_azimuth(h);
  if (written && a != 0.0) {  // a field off the y axis: its x, y as written
    const double r = sys.field_values[h];
    const double fx = r * std::sin(a * kPi / 180.0), fy = r * std::cos(a * kPi / 180.0);
    switch (sys.field_type) {
      case FieldType::kAngle:
        return fmt::format("({:.1f}\u00b0, {:.1f}\u00b0)", fx, fy);
      case FieldType::kObjectHeight:
        return fmt::format("object ({:.2f}, {:.2f}) mm", fx, fy);
      case FieldType::kParaxialImageHeight:
      case FieldType::kRealImageHeight:
        return fmt::format("image ({:.2f}, {:.2f}) mm", fx, fy);
    }
  }
  switch (written ? sys.field_type : FieldType::kAngle) {
    case FieldType::kAngle:
      break;
    case FieldType::kObjectHeight:
      return fmt::format("object {:.2f} mm", sys.field_values[h]);
    case FieldType::kParaxialImageHeight:
    case FieldType::kRealImageHeight:
      return fmt::format("image {:.2f} mm", sys.field_values[h]);
  }
  return fmt::format("{:.1f}\u00b0", sys.fields_deg[h]);
}

std::vector<std::string> field_labels(const TraceSystem<double>& sys,
                                      const std::vector<int>& fields) {
  std::vector<std::string> out;
  for (int h : fields) out.push_back(field_label(sys, h));
  return out;
}

void SpotOptions::validate() const {
  validate_fractions(field_fractions, "spot diagram");
  if (draw_rings < 1 || draw_rings > 64)
    throw Error(fmt::format("spot diagram: draw_rings = {} must be in 1..64", draw_rings));
}

SpotData compute_spots(const PlotContext& ctx, const SpotOptions& options) {
  options.validate();
  SpotData out;
  out.lens_name = ctx.lens.name;
  const TraceSystem<double>& base = ctx.sys;
  out.wavelengths_nm.assign(base.lens.wavelengths_nm.begin(),
                            base.lens.wavelengths_nm.begin() + base.wavelength_count);
  out.wavelength_channel = ctx.wavelength_channel;
  out.mean_rms_um = ctx.report.mean_rms_spot_um.value_or(0.0);
  out.analyzed_fields = static_cast<int>(ctx.report.fields.size());
  TraceSystem<double> sys = base;  // same aiming, fewer drawn rays
  sys.pupil = sys.samples_for(paper_pupil_samples(options.draw_rings));
  RayBundle<double> rays;
  for (int h : field_indices(ctx, options.field_fractions)) {
    const FieldReport& report = ctx.report.fields[h];
    SpotField f;
    f.field = h;
    f.field_deg = sys.fields_deg[h];
    f.label = field_label(sys, h);
    // In the image's own x, y: a field off the y axis is traced in its frame and turned back
    // (the same bits on the y axis).
    f.centroid_y_mm = report.image_centroid_y_mm;
    f.centroid_x_mm = report.image_centroid_x_mm;
    f.rms_um = report.rms_spot_um.value_or(0.0);
    for (int w = 0; w < sys.wavelength_count; ++w) {
      start_rays(sys, h, w, rays);
      trace_to_image(sys, w, rays);
      for (std::size_t i = 0; i < rays.size(); ++i) {
        if (!ray_ok(rays, i)) {
          ++f.failed_rays;
          continue;
        }
        const double x = 1000.0 * (rays.x[i] - report.centroid_x_mm);
        const double y = 1000.0 * (rays.y[i] - report.centroid_y_mm);
        for (double sx : {1.0, -1.0}) {  // mirrored half pupil (a full pupil: each ray once)
          if (sx < 0.0 && sys.full_pupil) break;
          double px = sx * x, py = y;
          sys.field_to_lens(h, sx * x, y, px, py);
          f.x_um.push_back(px);
          f.y_um.push_back(py);
          f.wavelength.push_back(w);
        }
        f.max_radius_um = std::max(f.max_radius_um, std::hypot(x, y));
      }
    }
    out.fields.push_back(std::move(f));
  }
  return out;
}

void FanOptions::validate() const {
  validate_fractions(field_fractions, "ray fan");
  if (samples < 3 || samples > 10001)
    throw Error(fmt::format("ray fan: samples = {} must be in 3..10001", samples));
}

FanData compute_fans(const PlotContext& ctx, const FanOptions& options) {
  options.validate();
  const TraceSystem<double>& sys = ctx.sys;
  FanData out;
  out.lens_name = ctx.lens.name;
  const int n = options.samples;
  RayBundle<double> rays;
  for (int h : field_indices(ctx, options.field_fractions)) {
    FanField field;
    field.field = h;
    field.field_deg = sys.fields_deg[h];
    field.label = field_label(sys, h);
    // Chief ray of the reference wavelength.
    const int ref = sys.wavelength_count;
    rays.resize(1);
    set_pupil_ray(sys, h, 0.0, sys.pupil_map(h, ref).offset_y, rays, 0);
    trace_to_image(sys, ref, rays);
    const bool chief_ok = ray_ok(rays, 0);
    const double y_chief = rays.y[0];
    for (int c = 0; c < 3; ++c) {
      const int w = ctx.channel_wavelength[c];
      if (w < 0) continue;
      const PupilMap<double>& map = sys.pupil_map(h, w);
      for (int sagittal = 0; sagittal < 2; ++sagittal) {
        FanCurve curve;
        curve.channel = c;
        curve.wavelength_nm = sys.lens.wavelengths_nm[w];
        rays.resize(n);
        for (int i = 0; i < n; ++i) {
          const double p = -1.0 + 2.0 * i / (n - 1);
          curve.pupil.push_back(p);
          if (sagittal)
            set_pupil_ray(sys, h, map.scale_x * p, map.offset_y, rays, i);
          else
            set_pupil_ray(sys, h, 0.0, map.offset_y + map.scale_y * p, rays, i);
        }
        trace_to_image(sys, w, rays);
        for (int i = 0; i < n; ++i) {
          const bool ok = chief_ok && ray_ok(rays, i);
          const double e = ok ? 1000.0 * (sagittal ? rays.x[i] : rays.y[i] - y_chief) : 0.0;
          curve.error_um.push_back(e);
          curve.valid.push_back(ok);
          if (ok) out.max_abs_um = std::max(out.max_abs_um, std::abs(e));
        }
        (sagittal ? field.sagittal : field.tangential).push_back(std::move(curve));
      }
    }
    out.fields.push_back(std::move(field));
  }
  return out;
}

FieldCurveData compute_field_curves(const PlotContext& ctx, double delta, int fields) {
  if (!(delta > 0 && delta < 0.5)) throw Error("field curves: delta must be in (0, 0.5)");
  if (fields < 2 || fields > 1001) throw Error("field curves: fields must be in 2..1001");
  // The same (already scaled) lens, aimed at a finer field grid (analysis/field_sweep.h).
  const TraceSystem<double> sys = field_sweep_system(ctx.lens, ctx.sys, ctx.trace, fields);
  FieldCurveData out;
  out.lens_name = ctx.lens.name;
  out.field_deg = sys.fields_deg;
  for (const FieldReport& f : ctx.report.fields) {
    out.distortion_field_deg.push_back(f.field_deg);
    out.distortion_percent.push_back(f.distortion_percent);
  }
  // The distortion curve: analyze's D_h (measure_fields) at every field of the grid.
  WaveOptions wave;
  wave.threads = ctx.trace.threads;
  out.sweep_distortion_percent = field_sweep(sys, wave, {}, false).distortion_percent;
  RayBundle<double> rays;
  for (int c = 0; c < 3; ++c) {
    const int w = ctx.channel_wavelength[c];
    if (w < 0) continue;
    FocusCurve curve;
    curve.channel = c;
    curve.wavelength_nm = sys.lens.wavelengths_nm[w];
    for (int h = 0; h < static_cast<int>(sys.fields_deg.size()); ++h) {
      const PupilMap<double>& map = sys.pupil_map(h, w);
      rays.resize(3);
      set_pupil_ray(sys, h, 0.0, map.offset_y + delta * map.scale_y, rays, 0);
      set_pupil_ray(sys, h, 0.0, map.offset_y - delta * map.scale_y, rays, 1);
      set_pupil_ray(sys, h, delta * map.scale_x, map.offset_y, rays, 2);
      trace_to_image(sys, w, rays);
      const bool ok = ray_ok(rays, 0) && ray_ok(rays, 1) && ray_ok(rays, 2) && rays.l[2] != 0.0;
      const double slope_diff = rays.m[0] / rays.n[0] - rays.m[1] / rays.n[1];
      const double dz_t = ok && slope_diff != 0.0 ? -(rays.y[0] - rays.y[1]) / slope_diff : 0.0;
      const double dz_s = ok ? -rays.x[2] * rays.n[2] / rays.l[2] : 0.0;
      curve.tangential_mm.push_back(dz_t);
      curve.sagittal_mm.push_back(dz_s);
      curve.valid.push_back(ok && slope_diff != 0.0 && std::isfinite(dz_t) && std::isfinite(dz_s));
    }
    out.focus.push_back(std::move(curve));
  }
  return out;
}

}  // namespace lensopt::plot
