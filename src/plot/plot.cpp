#include "lensopt/plot/plot.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include "lensopt/core/error.h"
#include "lensopt/plot/afocal_plot.h"
#include "lensopt/plot/charts.h"
#include "lensopt/plot/layout.h"
#include "lensopt/plot/psf_strip.h"
#include "lensopt/plot/report_charts.h"
#include "lensopt/plot/style.h"
#include "lensopt/plot/wave_charts.h"

namespace lensopt::plot {
namespace {

constexpr double kBaseFont = 13;  // px at a kind's default page width

std::string kind_title(PlotKind kind) {
  switch (kind) {
    case PlotKind::kLayout:
      return "layout";
    case PlotKind::kSpot:
      return "spot diagrams";
    case PlotKind::kFan:
      return "transverse ray fans";
    case PlotKind::kField:
      return "field curvature and distortion";
    case PlotKind::kPsf:
      return "sampled PSFs";
    case PlotKind::kReport:
      return "report";
    case PlotKind::kMtf:
      return "diffraction MTF";
    case PlotKind::kThroughFocus:
      return "through-focus MTF";
    case PlotKind::kWavefront:
      return "wavefront error";
    case PlotKind::kPsfDiffraction:
      return "diffraction PSFs";
    case PlotKind::kMtfField:
      return "MTF and RMS spot vs field";
    case PlotKind::kChromatic:
      return "chromatic focal shift and lateral colour";
    case PlotKind::kEncircledEnergy:
      return "encircled energy";
  }
  return "";
}

// "f 17.16 mm  f/2.00  hfov 25.0 deg  ..." from analyze's report; the half field is the largest
// field's chief-ray angle (a lens with height fields has no written angle).
std::string first_order_line(const PlotContext& ctx) {
  const AnalysisReport& r = ctx.report;
  std::string s = fmt::format(
      "EFL {:.2f} mm   f/{:.2f}   half field {:.1f}\u00b0   BFL {:.2f} mm   total track "
      "{:.2f} mm   EPD {:.2f} mm",
      r.efl_mm, r.f_number, ctx.sys.fields_deg.back(), r.bfl_mm, r.total_track_mm, r.epd_mm);
  if (std::abs(r.scale - 1.0) > 5e-4) s += fmt::format("   (scaled \u00d7{:.4f})", r.scale);
  return s;
}

std::string spot_line(const PlotContext& ctx) {
  const AnalysisReport& r = ctx.report;
  std::string s = r.mean_rms_spot_um
                      ? fmt::format("mean RMS spot {:.2f} \u00b5m", *r.mean_rms_spot_um)
                      : std::string("mean RMS spot n/a");
  if (r.ray_failures > 0) s += fmt::format("   {} rays failed", r.ray_failures);
  return s;
}

// The page header: title, first-order numbers; returns its height.
double draw_header(Canvas& canvas, const PlotContext& ctx, const PlotContext* cmp, PlotKind kind,
                   double width, double font_px) {
  TextStyle title{font_px * 1.6, Anchor::kStart, "#111111"};
  title.bold = true;
  const std::string name = ctx.lens.name.empty() ? std::string("lens") : ctx.lens.name;
  canvas.text({16, font_px * 2.0},
              fmt::format("{}{}: {}", name, cmp ? " vs " + cmp->lens.name : "", kind_title(kind)),
              title);
  const TextStyle line{font_px, Anchor::kStart, "#333333"};
  double y = font_px * 3.6;
  canvas.text({16, y}, fmt::format("{}   {}", first_order_line(ctx), spot_line(ctx)), line);
  if (cmp) {
    y += font_px * 1.45;
    canvas.text({16, y},
                fmt::format("{}: {}   {}", cmp->lens.name, first_order_line(*cmp), spot_line(*cmp)),
                line);
  }
  canvas.line({16, y + font_px * 0.9}, {width - 16, y + font_px * 0.9}, Style{"#cccccc", 1.0});
  return y + font_px * 1.4;
}

double default_width(PlotKind kind) {
  switch (kind) {
    case PlotKind::kLayout:
      return 1200;
    case PlotKind::kSpot:
      return 1250;
    case PlotKind::kFan:
      return 1300;
    case PlotKind::kField:
      return 1100;
    case PlotKind::kPsf:
      return 1150;
    case PlotKind::kReport:
      return 1500;
    case PlotKind::kMtf:
    case PlotKind::kThroughFocus:
      return 1100;
    case PlotKind::kWavefront:
    case PlotKind::kPsfDiffraction:
      return 1150;
    case PlotKind::kMtfField:
    case PlotKind::kChromatic:
      return 1100;
    case PlotKind::kEncircledEnergy:
      return 1100;
  }
  return 1200;
}

// The fields of the wave-optics charts: fractions of the half field.
const std::vector<double> kMtfFractions{0.0, 0.7, 1.0};

// The polychromatic diffraction MTF of fields 0, 0.7 and 1 of the lens (61 frequencies from 0
// to the cutoff of the shortest wavelength), with its wavelength weights: the MTF page's and the
// report's chart.
WaveReport compute_mtf_curves(const PlotContext& ctx, const PlotOptions& options) {
  const TraceSystem<double>& sys = ctx.sys;
  WaveOptions wave;
  wave.pupil_samples = options.pupil_samples;
  wave.threads = options.trace.threads;
  wave.wavelength_weights = lens_wavelength_weights(ctx.lens, sys.wavelength_count);
  wave.geometric = false;
  double lambda_min = 1e9;
  for (int w = 0; w < sys.wavelength_count; ++w)
    lambda_min = std::min(lambda_min, sys.lens.wavelengths_nm[w]);
  const double cutoff = options.max_frequency_cyc_mm > 0
                            ? options.max_frequency_cyc_mm
                            : 1.0 / (lambda_min * 1e-6 * (std::abs(sys.efl_mm) / sys.epd_mm));
  std::vector<double> freqs;
  for (int k = 0; k <= 60; ++k) freqs.push_back(cutoff * k / 60.0);
  return analyze_wave(sys, wave, freqs, field_indices(ctx, kMtfFractions));
}

std::string mtf_title(const WaveReport& r) {
  return fmt::format("polychromatic diffraction MTF ({} x {} pupil, FFT {})", r.pupil_samples,
                     r.pupil_samples, r.fft_n);
}

// The chromatic focal shift across the lens's spec band (41 wavelengths from its shortest to its
// longest), or at its one wavelength.
ChromaticFocalShift chromatic_band_of_lens(const Lens& lens, const TraceSystem<double>& sys) {
  double lo = 1e9, hi = 0;
  for (int w = 0; w < sys.wavelength_count; ++w) {
    lo = std::min(lo, sys.lens.wavelengths_nm[w]);
    hi = std::max(hi, sys.lens.wavelengths_nm[w]);
  }
  if (!(hi > lo)) return chromatic_focal_shift(lens, sys);
  return chromatic_focal_shift(lens, sys, lo, hi, 41);
}

// The wave-optics page of one lens, drawn into `area` (no compare lens: one lens per page).
void draw_wave_page(Canvas& c, Rect area, const PlotContext& ctx, const PlotOptions& options,
                    double font_px) {
  const TraceSystem<double>& sys = ctx.sys;
  const std::vector<int> fields = field_indices(ctx, kMtfFractions);
  WaveOptions wave;
  wave.pupil_samples = options.pupil_samples;
  wave.threads = options.trace.threads;
  wave.wavelength_weights = lens_wavelength_weights(ctx.lens, sys.wavelength_count);
  const double f_number = std::abs(sys.efl_mm) / sys.epd_mm;
  const double lambda_ref_mm = ctx.lens.specs.primary_wavelength_nm * 1e-6;
  switch (options.kind) {
    case PlotKind::kMtf: {
      const WaveReport r = compute_mtf_curves(ctx, options);
      draw_mtf_curves(c, area, r, mtf_title(r), font_px, field_labels(sys, fields));
      break;
    }
    case PlotKind::kThroughFocus: {
      const double range = options.focus_range_mm > 0 ? options.focus_range_mm
                                                      : 8.0 * lambda_ref_mm * f_number * f_number;
      std::vector<double> shifts;
      for (int k = -15; k <= 15; ++k) shifts.push_back(range * k / 15.0);
      const ThroughFocus tf =
          through_focus_mtf(sys, wave, options.mtf_frequency_cyc_mm, shifts, fields);
      draw_through_focus(c, area, tf, font_px, field_labels(sys, fields));
      break;
    }
    case PlotKind::kWavefront: {
      const PupilGrid grid = make_pupil_grid(options.pupil_samples);
      const int w = std::max(0, ctx.channel_wavelength[1]);  // the green channel's middle
      std::vector<WavefrontPanel> panels;
      RayBundle<double> rays;
      RayRecord<double> record;
      for (int h : fields) {
        const ReferenceSphere<double> sphere = reference_sphere(sys, h);
        const Wavefront<double> wf = compute_wavefront(sys, h, w, grid, sphere, 0.0, rays, record);
        WavefrontPanel p;
        p.label = fmt::format("{}, {:.1f} nm", field_label(sys, h), wf.wavelength_nm);
        p.n = grid.n;
        p.opd_waves.assign(static_cast<std::size_t>(grid.n) * grid.n,
                           std::numeric_limits<double>::quiet_NaN());
        for (std::size_t i = 0; i < grid.size(); ++i)
          if (wf.ok[i])
            p.opd_waves[static_cast<std::size_t>(grid.n - 1 - grid.row[i]) * grid.n +
                        grid.column[i]] = wf.opd_waves[i];
        p.rms_waves = wf.rms_waves;
        p.pv_waves = wf.pv_waves;
        panels.push_back(std::move(p));
      }
      draw_wavefront_maps(c, area, panels, font_px);
      break;
    }
    case PlotKind::kPsfDiffraction: {
      wave.keep_psf = true;
      wave.geometric = false;
      const WaveReport r = analyze_wave(sys, wave, {}, fields);
      // One tile spans the shortest wavelength's FFT window, 128 pixels.
      const int pixels = 128;
      double window_um = 1e9;
      for (const MonoWave& m : r.fields[0].mono)
        if (m.ok) window_um = std::min(window_um, m.fft_n * std::abs(m.psf_dy_um));
      if (!(window_um < 1e9)) window_um = 100;
      const double spacing = window_um / pixels;
      std::vector<PsfPanel> panels;
      for (std::size_t j = 0; j < r.fields.size(); ++j) {
        const WaveField& f = r.fields[j];
        PsfPanel p;
        p.label = fmt::format("{}  Strehl {:.3f}", field_label(sys, fields[j]), f.strehl);
        p.pixels = pixels;
        p.psf = polychromatic_psf(f, pixels, spacing);
        panels.push_back(std::move(p));
      }
      draw_diffraction_psfs(c, area, panels, spacing, font_px);
      break;
    }
    case PlotKind::kMtfField: {
      const TraceSystem<double> fine =
          field_sweep_system(ctx.lens, sys, ctx.trace, options.sweep_fields);
      const FieldSweep sweep = field_sweep(fine, wave, options.mtf_frequencies_cyc_mm);
      draw_mtf_vs_field(c, area, sweep, font_px);
      break;
    }
    case PlotKind::kChromatic: {
      const ChromaticFocalShift shift =
          options.band_lo_nm > 0
              ? chromatic_focal_shift(ctx.lens, sys, options.band_lo_nm, options.band_hi_nm, 41)
              : chromatic_band_of_lens(ctx.lens, sys);
      const TraceSystem<double> fine =
          field_sweep_system(ctx.lens, sys, ctx.trace, options.sweep_fields);
      draw_chromatic(c, area, shift, lateral_colour(fine), font_px);
      break;
    }
    case PlotKind::kEncircledEnergy: {
      EncircledEnergyOptions eo;
      eo.field_indices = fields;
      eo.wave = wave;
      const EncircledEnergy ee = encircled_energy(sys, eo);
      draw_encircled_energy(c, area, ee, sys.lens.reference_nm(), field_labels(sys, fields),
                            font_px);
      break;
    }
    default:
      break;
  }
}

// Height (px) a layout needs at a width, from its aspect ratio.
double layout_height(const LayoutGeometry& g, const LayoutGeometry* cmp, double width,
                     double font_px) {
  const LayoutExtent e = layout_extent(g, cmp);
  const double h = (width - 16) / (1.08 * (e.z_hi - e.z_lo)) * (e.y_hi - e.y_lo) + font_px * 6.8;
  return std::clamp(h, 300.0, 1.2 * width);
}

}  // namespace

const std::vector<std::string>& plot_kind_names() {
  static const std::vector<std::string> names = {"layout",
                                                 "spot",
                                                 "fan",
                                                 "field",
                                                 "psf",
                                                 "report",
                                                 "mtf",
                                                 "through-focus",
                                                 "wavefront",
                                                 "psf-diffraction",
                                                 "mtf-field",
                                                 "chromatic",
                                                 "encircled-energy"};
  return names;
}

PlotKind parse_plot_kind(const std::string& name) {
  const auto& names = plot_kind_names();
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return static_cast<PlotKind>(i);
  throw Error(
      fmt::format("unknown plot kind '{}': use one of layout, spot, fan, field, psf, report, mtf, "
                  "through-focus, wavefront, psf-diffraction, mtf-field, chromatic, "
                  "encircled-energy",
                  name));
}

std::string plot_kind_name(PlotKind kind) {
  return plot_kind_names()[static_cast<int>(kind)];
}

void PlotOptions::validate() const {
  trace.validate();
  if (!(spot_box_um >= 0) || spot_box_um > 1e5)
    throw Error(fmt::format("spot box {} um must be in [0, 100000] (0: automatic)", spot_box_um));
  if (width_px != 0 && !(width_px >= 300 && width_px <= 8000))
    throw Error(fmt::format("page width {} px must be in [300, 8000] (0: default)", width_px));
  if (pupil_samples < 8 || pupil_samples > 1024)
    throw Error(fmt::format("pupil samples {} must be in [8, 1024]", pupil_samples));
  if (!(mtf_frequency_cyc_mm > 0) || !std::isfinite(mtf_frequency_cyc_mm))
    throw Error(fmt::format("MTF frequency {} cycles/mm must be > 0", mtf_frequency_cyc_mm));
  if (!(max_frequency_cyc_mm >= 0) || !std::isfinite(max_frequency_cyc_mm))
    throw Error(
        fmt::format("--max-freq {} cycles/mm must be > 0 (0: the cutoff)", max_frequency_cyc_mm));
  if (!(focus_range_mm >= 0) || !std::isfinite(focus_range_mm) || focus_range_mm > 1e3)
    throw Error(
        fmt::format("--focus-range {} mm must be in (0, 1000] (0: 8 lambda N^2)", focus_range_mm));
  if (mtf_frequencies_cyc_mm.empty() || mtf_frequencies_cyc_mm.size() > 12)
    throw Error("--mtf-freqs: give 1 to 12 frequencies");
  for (double f : mtf_frequencies_cyc_mm)
    if (!(f >= 0) || !std::isfinite(f))
      throw Error(fmt::format("MTF frequency {} cycles/mm must be >= 0", f));
  if (sweep_fields < 2 || sweep_fields > 201)
    throw Error(fmt::format("--sweep-fields {} must be in 2..201", sweep_fields));
  if (!(band_lo_nm == 0 && band_hi_nm == 0) &&
      !(band_lo_nm > 0 && band_hi_nm > band_lo_nm && std::isfinite(band_hi_nm)))
    throw Error(
        fmt::format("--colour-band {},{} nm must have 0 < lo < hi", band_lo_nm, band_hi_nm));
}

namespace {

// What a page shows, computed for the lens and the comparison lens (when given).
struct PageData {
  std::optional<LayoutGeometry> layout, layout_cmp;
  std::optional<SpotData> spots, spots_cmp;
  std::optional<FanData> fans, fans_cmp;
  std::optional<FieldCurveData> field, field_cmp;
  std::optional<PsfStrip> psf, psf_cmp;
  std::optional<WaveReport> mtf, mtf_cmp;               // the report's MTF chart
  std::vector<std::string> mtf_labels, mtf_cmp_labels;  // its fields
  std::vector<const SpotData*> spot_rows;
  std::vector<const PsfStrip*> psf_rows;
  double box_um = 0.0;  // the spot diagrams' box

  const LayoutGeometry* layout_cmp_or_null() const { return layout_cmp ? &*layout_cmp : nullptr; }
  const FanData* fans_cmp_or_null() const { return fans_cmp ? &*fans_cmp : nullptr; }
  const FieldCurveData* field_cmp_or_null() const { return field_cmp ? &*field_cmp : nullptr; }
};

// Data first (only what the page shows).
PageData compute_page_data(const PlotContext& ctx, const PlotContext* cmp,
                           const PlotOptions& options) {
  const PlotKind kind = options.kind;
  const bool report = kind == PlotKind::kReport;
  PageData d;
  if (report || kind == PlotKind::kLayout) {
    d.layout = compute_layout(ctx);
    if (cmp) d.layout_cmp = compute_layout(*cmp);
  }
  if (report || kind == PlotKind::kSpot) {
    d.spots = compute_spots(ctx);
    if (cmp) d.spots_cmp = compute_spots(*cmp);
  }
  if (report || kind == PlotKind::kFan) {
    d.fans = compute_fans(ctx);
    if (cmp) d.fans_cmp = compute_fans(*cmp);
  }
  if (report || kind == PlotKind::kField) {
    d.field = compute_field_curves(ctx);
    if (cmp) d.field_cmp = compute_field_curves(*cmp);
  }
  if (report || kind == PlotKind::kPsf) {
    d.psf = compute_psf_strip(ctx);
    if (cmp) d.psf_cmp = compute_psf_strip(*cmp);
  }
  if (report) {
    d.mtf = compute_mtf_curves(ctx, options);
    d.mtf_labels = field_labels(ctx.sys, field_indices(ctx, kMtfFractions));
    if (cmp) {
      d.mtf_cmp = compute_mtf_curves(*cmp, options);
      d.mtf_cmp_labels = field_labels(cmp->sys, field_indices(*cmp, kMtfFractions));
    }
  }
  if (d.spots) d.spot_rows.push_back(&*d.spots);
  if (d.spots_cmp) d.spot_rows.push_back(&*d.spots_cmp);
  d.box_um = d.spots
                 ? (options.spot_box_um > 0 ? options.spot_box_um : auto_spot_box_um(d.spot_rows))
                 : 0.0;
  if (d.psf) d.psf_rows.push_back(&*d.psf);
  if (d.psf_cmp) d.psf_rows.push_back(&*d.psf_cmp);
  return d;
}

// Heights (px) of a page and of the report's sections.
struct PageSize {
  double height = 0;
  double spot_h = 0, psf_h = 0;                   // spot and PSF sections, all rows
  double layout_h = 0, top_row_h = 0, fan_h = 0;  // the report's
  double mtf_h = 0;
};

PageSize page_size(PlotKind kind, const PageData& d, int rows, double width, double font_px,
                   double header_h) {
  PageSize p;
  const LayoutGeometry* lc = d.layout_cmp_or_null();
  const double spot_h_per_row = std::min(260.0, (width - 60) / 5.0) + font_px * 5;
  p.spot_h = font_px * 5 + rows * spot_h_per_row;
  const double psf_h_per_row = std::min(210.0, (width - 60) / 5.0) + font_px * 5;
  p.psf_h = font_px * 5 + rows * psf_h_per_row;
  switch (kind) {
    case PlotKind::kLayout:
      p.height = header_h + layout_height(*d.layout, lc, width, font_px);
      break;
    case PlotKind::kSpot:
      p.height = header_h + p.spot_h;
      break;
    case PlotKind::kFan:
      p.height = header_h + 0.52 * width;
      break;
    case PlotKind::kField:
      p.height = header_h + 0.45 * width;
      break;
    case PlotKind::kPsf:
      p.height = header_h + p.psf_h;
      break;
    case PlotKind::kReport:
      p.layout_h = layout_height(*d.layout, lc, 0.58 * width, font_px);
      p.top_row_h = std::max(p.layout_h, 0.30 * width);
      p.fan_h = 0.36 * width;
      p.mtf_h = 0.36 * width;
      p.height = header_h + p.top_row_h + p.spot_h + p.fan_h + p.psf_h + p.mtf_h + 10;
      break;
    case PlotKind::kMtf:
    case PlotKind::kThroughFocus:
      p.height = header_h + 0.55 * width;
      break;
    case PlotKind::kWavefront:
    case PlotKind::kPsfDiffraction:
      p.height = header_h + (width - 60) / 3.0 + font_px * 6;
      break;
    case PlotKind::kMtfField:
    case PlotKind::kChromatic:
      p.height = header_h + 0.45 * width;
      break;
    case PlotKind::kEncircledEnergy:
      p.height = header_h + 0.55 * width;
      break;
  }
  return p;
}

// The report: layout and field curves side by side, then spots, fans and PSFs, each section
// under a title.
void draw_report(Canvas& c, double top, double width, double font_px, const PageData& d,
                 const PageSize& p) {
  double y = top;
  const Rect layout_area{0, y, 0.58 * width, p.top_row_h};
  draw_layout(c, layout_area.inset(8, 4, 4, 4), *d.layout, d.layout_cmp_or_null(), font_px);
  const Rect field_area{0.58 * width, y, 0.42 * width, std::min(p.top_row_h, 0.36 * width)};
  draw_field_curves(c, field_area.inset(6, 4, 14, 4), *d.field, d.field_cmp_or_null(), font_px);
  y += p.top_row_h;
  auto section = [&](const std::string& name, double at) {
    TextStyle t{font_px * 1.15, Anchor::kStart, "#111111"};
    t.bold = true;
    c.line({16, at + 2}, {width - 16, at + 2}, Style{"#dddddd", 1.0});
    c.text({16, at + font_px * 1.5}, name, t);
    return at + font_px * 2.0;
  };
  double s0 = section("spot diagrams", y);
  draw_spots(c, Rect{0, s0, width, p.spot_h - (s0 - y)}.inset(10, 0, 10, 0), d.spot_rows, d.box_um,
             font_px);
  y += p.spot_h;
  s0 = section("transverse ray fans", y);
  draw_fans(c, Rect{0, s0, width, p.fan_h - (s0 - y)}.inset(10, 0, 14, 0), *d.fans,
            d.fans_cmp_or_null(), font_px);
  y += p.fan_h;
  s0 = section("sampled PSFs", y);
  draw_psf_strips(c, Rect{0, s0, width, p.psf_h - (s0 - y)}.inset(10, 0, 10, 0), d.psf_rows,
                  font_px);
  y += p.psf_h;
  s0 = section("diffraction MTF (tangential solid, sagittal dashed)", y);
  // One chart, or the lens and the comparison lens side by side.
  const double chart_w = d.mtf_cmp ? width / 2 : width;
  draw_mtf_curves(c, Rect{0, s0, chart_w, p.mtf_h - (s0 - y)}.inset(10, 0, 14, 0), *d.mtf,
                  mtf_title(*d.mtf), font_px, d.mtf_labels);
  if (d.mtf_cmp)
    draw_mtf_curves(c, Rect{chart_w, s0, chart_w, p.mtf_h - (s0 - y)}.inset(10, 0, 14, 0),
                    *d.mtf_cmp, mtf_title(*d.mtf_cmp), font_px, d.mtf_cmp_labels);
}

// The page's body below the header.
void draw_body(Canvas& c, double top, double width, double font_px, const PlotContext& ctx,
               const PlotOptions& options, const PageData& d, const PageSize& p) {
  const Rect body{0, top, width, c.height() - top};
  switch (options.kind) {
    case PlotKind::kLayout:
      draw_layout(c, body.inset(8, 4, 8, 4), *d.layout, d.layout_cmp_or_null(), font_px);
      break;
    case PlotKind::kSpot:
      draw_spots(c, body.inset(10, 4, 10, 4), d.spot_rows, d.box_um, font_px);
      break;
    case PlotKind::kFan:
      draw_fans(c, body.inset(10, 4, 14, 4), *d.fans, d.fans_cmp_or_null(), font_px);
      break;
    case PlotKind::kField:
      draw_field_curves(c, body.inset(10, 4, 14, 4), *d.field, d.field_cmp_or_null(), font_px);
      break;
    case PlotKind::kPsf:
      draw_psf_strips(c, body.inset(10, 4, 10, 4), d.psf_rows, font_px);
      break;
    case PlotKind::kReport:
      draw_report(c, top, width, font_px, d, p);
      break;
    case PlotKind::kMtf:
    case PlotKind::kThroughFocus:
    case PlotKind::kWavefront:
    case PlotKind::kPsfDiffraction:
    case PlotKind::kMtfField:
    case PlotKind::kChromatic:
    case PlotKind::kEncircledEnergy:
      draw_wave_page(c, body.inset(10, 4, 10, 4), ctx, options, font_px);
      break;
  }
}

void fill_summary(const Canvas& c, const PlotContext* cmp, const PageData& d,
                  PlotSummary& summary) {
  summary.width_px = c.width();
  summary.height_px = c.height();
  summary.spot_box_um = d.box_um;
  if (d.layout)
    summary.warnings.insert(summary.warnings.end(), d.layout->warnings.begin(),
                            d.layout->warnings.end());
  if (d.layout_cmp)
    for (const std::string& w : d.layout_cmp->warnings)
      summary.warnings.push_back(cmp->lens.name + ": " + w);
  for (const std::string& w : c.warnings()) summary.warnings.push_back(w);
}

}  // namespace

std::unique_ptr<Canvas> draw_plot(const PlotContext& ctx, const PlotContext* cmp,
                                  const PlotOptions& options, const CanvasFactory& make,
                                  PlotSummary* summary) {
  options.validate();
  const PlotKind kind = options.kind;
  const double width = options.width_px > 0 ? options.width_px : default_width(kind);
  // Text scales with the page below the default width (down to 70%), not above it.
  const double font_px = kBaseFont * std::clamp(width / default_width(kind), 0.7, 1.0);
  const double header_h = font_px * (cmp ? 6.2 : 4.8);

  const PageData data = compute_page_data(ctx, cmp, options);
  const PageSize size = page_size(kind, data, cmp ? 2 : 1, width, font_px, header_h);
  std::unique_ptr<Canvas> canvas = make(width, std::round(size.height));
  Canvas& c = *canvas;
  const double top = draw_header(c, ctx, cmp, kind, width, font_px);
  draw_body(c, top, width, font_px, ctx, options, data, size);
  if (summary) fill_summary(c, cmp, data, *summary);
  return canvas;
}

PlotSummary write_plot(const Lens& lens, const Lens* compare, const PlotOptions& options,
                       const std::filesystem::path& output) {
  // An afocal lens has no image plane: its spots are drawn in angle (plot/afocal_plot.h).
  if (lens.specs.afocal || (compare && compare->specs.afocal))
    return write_afocal_plot(lens, compare, options, output);
  options.validate();
  PlotSummary summary;
  summary.output = output;
  summary.format = output_format_for(output);  // before any tracing: a bad name fails fast
  const PlotContext ctx = make_plot_context(lens, options.trace);
  std::optional<PlotContext> cmp;
  if (compare) cmp = make_plot_context(*compare, options.trace);
  const std::unique_ptr<Canvas> canvas = draw_plot(
      ctx, cmp ? &*cmp : nullptr, options,
      [&](double w, double h) { return make_canvas(output, w, h); }, &summary);
  canvas->save(output);
  return summary;
}

}  // namespace lensopt::plot
