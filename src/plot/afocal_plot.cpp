#include "lensopt/plot/afocal_plot.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>

#include "lensopt/analysis/afocal.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/plot/canvas.h"
#include "lensopt/plot/charts.h"
#include "lensopt/plot/style.h"

namespace lensopt::plot {

SpotData afocal_spot_data(const Lens& lens, const TraceOptions& trace, int max_fields) {
  AfocalOptions options;
  options.wavefront = false;
  options.keep_points = true;
  const AfocalReport r = analyze_afocal_lens(lens, trace, options);
  SpotData out;
  out.unit = "\u00b5rad";
  out.lens_name = lens.name;
  out.wavelengths_nm.assign(lens.specs.wavelengths_nm.begin(), lens.specs.wavelengths_nm.end());
  const int count = static_cast<int>(out.wavelengths_nm.size());
  out.wavelength_channel.resize(count);
  for (int w = 0; w < count; ++w)
    out.wavelength_channel[w] = static_cast<int>(lens.specs.wavelength_channels.size()) == count
                                    ? lens.specs.wavelength_channels[w]
                                    : (out.wavelengths_nm[w] >= 580   ? 0
                                       : out.wavelengths_nm[w] >= 500 ? 1
                                                                      : 2);
  out.mean_rms_um = 1e3 * r.mean_rms_angular_spot_mrad.value_or(0.0);
  out.analyzed_fields = static_cast<int>(r.fields.size());
  const int n = static_cast<int>(r.fields.size());
  std::vector<int> shown;
  for (int i = 0; i < std::min(n, max_fields); ++i) {
    const int h =
        n <= max_fields
            ? i
            : static_cast<int>(std::lround(static_cast<double>(i) * (n - 1) / (max_fields - 1)));
    if (shown.empty() || shown.back() != h) shown.push_back(h);
  }
  for (int h : shown) {
    const AfocalField& a = r.fields[h];
    SpotField f;
    f.field = h;
    f.field_deg = a.field_deg;
    f.label = r.field_unit == "deg" ? fmt::format("{:.3g} deg", a.field_value)
                                    : fmt::format("{:.3g} mm", a.field_value);
    f.position_label = a.chief_ok ? fmt::format("out {:.3f} deg", a.output_chief_angle_deg)
                                  : std::string("chief ray failed");
    f.rms_um = 1e3 * a.rms_angular_spot_mrad.value_or(0.0);
    f.failed_rays = a.failed_rays;
    for (std::size_t i = 0; i < a.spot.x_mrad.size(); ++i) {
      f.x_um.push_back(1e3 * a.spot.x_mrad[i]);
      f.y_um.push_back(1e3 * a.spot.y_mrad[i]);
      f.wavelength.push_back(a.spot.wavelength[i]);
      f.max_radius_um = std::max(f.max_radius_um, std::hypot(f.x_um.back(), f.y_um.back()));
    }
    out.fields.push_back(std::move(f));
  }
  return out;
}

PlotSummary write_afocal_plot(const Lens& lens, const Lens* compare, const PlotOptions& options,
                              const std::filesystem::path& output) {
  options.validate();
  const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
  if (options.kind != PlotKind::kSpot && options.kind != PlotKind::kReport)
    throw Error(SourceLocation{where},
                fmt::format("plot --kind {} measures an image plane, which an afocal lens does not "
                            "have (its image is at infinity); --kind spot draws its spot in angle, "
                            "and analyze reports its angular magnification, output angles and "
                            "plane-wave wavefront",
                            plot_kind_name(options.kind)));
  if (compare && compare->specs.afocal != lens.specs.afocal)
    throw Error(SourceLocation{where},
                "cannot compare an afocal lens (spots in angle) with a focal one (spots in mm)");
  PlotSummary summary;
  summary.output = output;
  summary.format = output_format_for(output);
  const SpotData spots = afocal_spot_data(lens, options.trace);
  std::optional<SpotData> cmp;
  if (compare) cmp = afocal_spot_data(*compare, options.trace);
  std::vector<const SpotData*> rows{&spots};
  if (cmp) rows.push_back(&*cmp);
  const double box = options.spot_box_um > 0 ? options.spot_box_um : auto_spot_box_um(rows);
  const double font_px = 13;
  const double width = options.width_px > 0 ? options.width_px : 1250;
  const double header_h = font_px * 5.2;
  const double row_h = std::min(260.0, (width - 60) / 5.0) + font_px * 5;
  const double height = header_h + font_px * 5 + static_cast<double>(rows.size()) * row_h;
  const std::unique_ptr<Canvas> canvas = make_canvas(output, width, height);
  TextStyle title{font_px * 1.6, Anchor::kStart, "#111111"};
  title.bold = true;
  canvas->text({16, font_px * 2.0},
               fmt::format("{}{}: spot diagram in angle (afocal image space)", lens.name,
                           compare ? " vs " + compare->name : ""),
               title);
  canvas->text({16, font_px * 3.6},
               fmt::format("mean RMS angular spot {:.2f} \u00b5rad ({:.4f} arcmin); image at "
                           "infinity: angles from each field's centroid direction",
                           spots.mean_rms_um, spots.mean_rms_um * 1e-6 * 180.0 * 60.0 / kPi),
               TextStyle{font_px, Anchor::kStart, "#333333"});
  canvas->line({16, font_px * 4.5}, {width - 16, font_px * 4.5}, Style{"#cccccc", 1.0});
  draw_spots(*canvas, Rect{10, header_h, width - 20, height - header_h - 4}, rows, box, font_px);
  canvas->save(output);
  summary.width_px = width;
  summary.height_px = height;
  summary.spot_box_um = box;
  summary.spot_box_unit = "urad";
  if (options.kind == PlotKind::kReport)
    summary.warnings.emplace_back(
        "an afocal lens's report page is its spot diagram in angle (the layout, fans, field "
        "curves, PSF and MTF measure an image plane)");
  return summary;
}

}  // namespace lensopt::plot
