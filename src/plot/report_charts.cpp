#include "lensopt/plot/report_charts.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "lensopt/core/constants.h"
#include "lensopt/plot/style.h"

namespace lensopt::plot {
namespace {

// Two side-by-side frames in `area` below a legend band of `legend_h` px.
void two_frames(Rect area, double font_px, double legend_h, Rect& f1, Rect& f2) {
  const double left = font_px * 4.8, bottom = font_px * 3.4, gap = font_px * 5.5;
  const double top = legend_h + font_px * 2.2;
  const double pw = (area.width - left - gap - 8) / 2;
  const double ph = area.height - top - bottom;
  f1 = Rect{area.x + left, area.y + top, pw, ph};
  f2 = Rect{f1.right() + gap, area.y + top, pw, ph};
}

// Limits [lo, hi] of values with a margin, never empty.
void value_range(const std::vector<double>& values, double& lo, double& hi, double min_span) {
  lo = 0;
  hi = 0;
  for (double v : values)
    if (std::isfinite(v)) {
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  const double span = std::max(hi - lo, min_span);
  const double mid = 0.5 * (hi + lo);
  lo = lo < 0 ? mid - 0.55 * span : 0.0;
  hi = mid + 0.55 * span;
  if (lo == 0.0) hi = std::max(hi, 1.05 * span);
}

}  // namespace

double airy_encircled_energy(double radius_um, double airy_radius_um) {
  if (!(airy_radius_um > 0)) return 0.0;
  const double v = kPi * radius_um * 1.22 / airy_radius_um;  // pi r / (lambda N)
  const double j0 = std::cyl_bessel_j(0.0, v), j1 = std::cyl_bessel_j(1.0, v);
  return 1.0 - j0 * j0 - j1 * j1;
}

void draw_mtf_vs_field(Canvas& canvas, Rect area, const FieldSweep& sweep, double font_px) {
  const double hfov = sweep.field_deg.empty() ? 1.0 : std::max(1e-9, sweep.field_deg.back());
  const int nf = static_cast<int>(sweep.frequencies_cyc_mm.size());
  std::vector<LegendEntry> legend;
  for (int k = 0; k < nf; ++k)
    legend.push_back({fmt::format("{:g} cycles/mm", sweep.frequencies_cyc_mm[k]),
                      field_colour(k, std::max(nf, 2))});
  legend.push_back({"tangential", "#444444"});
  legend.push_back({"sagittal", "#444444", "6 4"});
  const double legend_h = draw_legend(canvas, {area.x + font_px * 4.5, area.y + 2}, legend,
                                      font_px * 0.9, true, area.width - font_px * 4.5)
                              .y;
  Rect f1, f2;
  two_frames(area, font_px, legend_h, f1, f2);
  const Axes a1(f1, 0.0, hfov, 0.0, 1.0);
  AxesLabels l1;
  l1.title = "MTF vs field";
  l1.x_label = "field angle (\u00b0)";
  l1.y_label = "MTF";
  l1.font_px = font_px * 0.9;
  a1.draw_grid(canvas, l1);
  for (int k = 0; k < nf; ++k) {
    const std::string colour = field_colour(k, std::max(nf, 2));
    std::vector<Point> t, s;
    for (std::size_t h = 0; h < sweep.field_deg.size(); ++h) {
      t.push_back(a1.to_px(sweep.field_deg[h], sweep.mtf_t[k][h]));
      s.push_back(a1.to_px(sweep.field_deg[h], sweep.mtf_s[k][h]));
    }
    canvas.polyline(t, Style{colour, 1.6});
    canvas.polyline(s, Style{colour, 1.6, "none", 1.0, "6 4"});
  }
  a1.draw_frame(canvas, l1);

  double hi = 0;
  for (std::size_t h = 0; h < sweep.rms_spot_um.size(); ++h)
    if (sweep.spot_valid[h]) hi = std::max(hi, sweep.rms_spot_um[h]);
  const Axes a2(f2, 0.0, hfov, 0.0, fine_ceil(std::max(1e-3, 1.1 * hi)));
  AxesLabels l2;
  l2.title = "RMS spot radius vs field";
  l2.x_label = "field angle (\u00b0)";
  l2.y_label = "RMS spot radius (\u00b5m)";
  l2.font_px = font_px * 0.9;
  a2.draw_grid(canvas, l2);
  std::vector<std::vector<Point>> runs(1);
  for (std::size_t h = 0; h < sweep.field_deg.size(); ++h) {
    if (!sweep.spot_valid[h]) {
      if (!runs.back().empty()) runs.emplace_back();
      continue;
    }
    runs.back().push_back(a2.to_px(sweep.field_deg[h], sweep.rms_spot_um[h]));
  }
  for (const auto& run : runs) canvas.polyline(run, Style{"#222222", 1.8});
  a2.draw_frame(canvas, l2);
}

void draw_chromatic(Canvas& canvas, Rect area, const ChromaticFocalShift& shift,
                    const LateralColour& lateral, double font_px) {
  std::vector<LegendEntry> legend{{"focal shift", "#222222"},
                                  {"diffraction-limited depth", "#9ecae1"},
                                  {"lateral colour", "#b03a2e"},
                                  {"+/- Airy radius", "#777777", "6 4"}};
  const double legend_h = draw_legend(canvas, {area.x + font_px * 4.5, area.y + 2}, legend,
                                      font_px * 0.9, true, area.width - font_px * 4.5)
                              .y;
  Rect f1, f2;
  two_frames(area, font_px, legend_h, f1, f2);
  // Focal shift (um) against wavelength.
  std::vector<double> um;
  for (double v : shift.shift_mm) um.push_back(v * 1e3);
  double lo, hi;
  std::vector<double> range = um;
  range.push_back(0.5 * shift.diffraction_depth_mm * 1e3);
  range.push_back(-0.5 * shift.diffraction_depth_mm * 1e3);
  value_range(range, lo, hi, 1e-3);
  const double w_lo = shift.wavelengths_nm.empty() ? 400 : shift.wavelengths_nm.front();
  double w_hi = shift.wavelengths_nm.empty() ? 700 : shift.wavelengths_nm.back();
  if (!(w_hi > w_lo)) w_hi = w_lo + 1;
  const Axes a1(f1, w_lo, w_hi, lo, hi);
  AxesLabels l1;
  l1.title = fmt::format("chromatic focal shift (from {:.1f} nm)", shift.primary_nm);
  l1.x_label = "wavelength (nm)";
  l1.y_label = "focal shift (\u00b5m)";
  l1.zero_y = true;
  l1.font_px = font_px * 0.9;
  a1.draw_grid(canvas, l1);
  const double depth_um = 0.5 * shift.diffraction_depth_mm * 1e3;
  const Point d0 = a1.to_px(w_lo, depth_um), d1 = a1.to_px(w_hi, -depth_um);
  canvas.rect(d0, d1.x - d0.x, d1.y - d0.y, Style{"none", 0.0, "#9ecae1", 0.35});
  std::vector<Point> curve;
  for (std::size_t i = 0; i < um.size(); ++i)
    curve.push_back(a1.to_px(shift.wavelengths_nm[i], um[i]));
  canvas.polyline(curve, Style{"#222222", 1.8});
  for (std::size_t i = 0; i < um.size(); ++i)
    if (!shift.band || um.size() <= 3)
      canvas.circle(curve[i], 2.5, Style{"#222222", 1.0, "#222222"});
  a1.draw_frame(canvas, l1);

  // Lateral colour against field.
  const double hfov = lateral.field_deg.empty() ? 1.0 : std::max(1e-9, lateral.field_deg.back());
  std::vector<double> values = lateral.lateral_colour_um;
  values.push_back(lateral.airy_radius_um);
  values.push_back(-lateral.airy_radius_um);
  value_range(values, lo, hi, 1e-3);
  const Axes a2(f2, lo, hi, 0.0, hfov);
  AxesLabels l2;
  l2.title =
      fmt::format("lateral colour ({:.1f} less {:.1f} nm)", lateral.short_nm, lateral.long_nm);
  l2.x_label = "lateral colour (\u00b5m)";
  l2.y_label = "field angle (\u00b0)";
  l2.zero_x = true;
  l2.x_ticks = 4;
  l2.font_px = font_px * 0.9;
  a2.draw_grid(canvas, l2);
  for (double s : {-1.0, 1.0})
    canvas.polyline(
        {a2.to_px(s * lateral.airy_radius_um, 0.0), a2.to_px(s * lateral.airy_radius_um, hfov)},
        Style{"#777777", 1.2, "none", 1.0, "6 4"});
  std::vector<std::vector<Point>> runs(1);
  for (std::size_t h = 0; h < lateral.field_deg.size(); ++h) {
    if (!lateral.valid[h]) {
      if (!runs.back().empty()) runs.emplace_back();
      continue;
    }
    runs.back().push_back(a2.to_px(lateral.lateral_colour_um[h], lateral.field_deg[h]));
  }
  for (const auto& run : runs) canvas.polyline(run, Style{"#b03a2e", 1.8});
  a2.draw_frame(canvas, l2);
}

void draw_encircled_energy(Canvas& canvas, Rect area, const EncircledEnergy& ee, double primary_nm,
                           const std::vector<std::string>& field_labels, double font_px) {
  const double r_max = ee.radius_um.empty() ? 1.0 : std::max(1e-9, ee.radius_um.back());
  const Rect frame = area.inset(font_px * 4.5, font_px * 2.2, font_px * 14, font_px * 3.2);
  const Axes ax(frame, 0.0, r_max, 0.0, 1.0);
  AxesLabels labels;
  labels.title = "encircled energy about the centroid";
  labels.x_label = "radius (\u00b5m)";
  labels.y_label = "fraction of the energy";
  labels.font_px = font_px;
  ax.draw_grid(canvas, labels);
  std::vector<LegendEntry> legend;
  if (ee.airy_radius_um > 0) {
    std::vector<Point> ideal;
    for (int k = 0; k <= 200; ++k) {
      const double r = r_max * k / 200.0;
      ideal.push_back(ax.to_px(r, airy_encircled_energy(r, ee.airy_radius_um)));
    }
    canvas.polyline(ideal, Style{"#000000", 1.2});
    legend.push_back({fmt::format("diffraction limit {:.0f} nm", primary_nm), "#000000"});
  }
  const int count = static_cast<int>(ee.fields.size());
  for (int j = 0; j < count; ++j) {
    const FieldEncircledEnergy& f = ee.fields[j];
    const std::string colour = field_colour(j, count);
    std::vector<Point> g, d;
    for (std::size_t i = 0; i < ee.radius_um.size(); ++i) {
      g.push_back(ax.to_px(ee.radius_um[i], f.geometric[i]));
      if (i < f.diffraction.size()) d.push_back(ax.to_px(ee.radius_um[i], f.diffraction[i]));
    }
    const std::string name = j < static_cast<int>(field_labels.size())
                                 ? field_labels[j]
                                 : fmt::format("{:.1f}\u00b0", f.field_deg);
    if (!d.empty()) {
      canvas.polyline(d, Style{colour, 1.6});
      legend.push_back({name + " diffraction", colour});
    }
    canvas.polyline(g, Style{colour, 1.6, "none", 1.0, "6 4"});
    legend.push_back({name + " geometric", colour, "6 4"});
  }
  // Where the diffraction curves stop (half the PSF window), when it lies on the chart.
  const bool stops =
      !ee.fields.empty() && !ee.fields[0].diffraction.empty() && ee.diffraction_window_um < r_max;
  if (stops) {
    canvas.polyline(
        {ax.to_px(ee.diffraction_window_um, 0.0), ax.to_px(ee.diffraction_window_um, 1.0)},
        Style{"#777777", 1.0, "none", 1.0, "2 3"});
    legend.push_back({"PSF window", "#777777", "2 3"});
  }
  ax.draw_frame(canvas, labels);
  draw_legend(canvas, {frame.right() + font_px, frame.y}, legend, font_px * 0.9);
}

}  // namespace lensopt::plot
