#include "lensopt/plot/charts.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "lensopt/plot/style.h"

namespace lensopt::plot {
namespace {

// Channel legend entries "R 584-666 nm" with the middle wavelength's colour.
std::vector<LegendEntry> wavelength_legend(const SpotData& spots) {
  std::vector<LegendEntry> out;
  for (int c = 0; c < 3; ++c) {
    std::vector<double> nm;
    for (std::size_t w = 0; w < spots.wavelengths_nm.size(); ++w)
      if (w < spots.wavelength_channel.size() && spots.wavelength_channel[w] == c)
        nm.push_back(spots.wavelengths_nm[w]);
    if (nm.empty()) continue;
    std::sort(nm.begin(), nm.end());
    const std::string range = nm.size() == 1
                                  ? fmt::format("{:.0f} nm", nm[0])
                                  : fmt::format("{:.0f}\u2013{:.0f} nm", nm.front(), nm.back());
    out.push_back({fmt::format("{} {}", channel_name(c), range),
                   wavelength_colour(nm[nm.size() / 2]), "", true});
  }
  return out;
}

// Splits a curve at invalid samples into drawable runs.
std::vector<std::vector<Point>> valid_runs(const Axes& ax, const std::vector<double>& xs,
                                           const std::vector<double>& ys,
                                           const std::vector<char>& valid) {
  std::vector<std::vector<Point>> runs(1);
  for (std::size_t i = 0; i < xs.size(); ++i) {
    if (!valid[i]) {
      if (!runs.back().empty()) runs.emplace_back();
      continue;
    }
    runs.back().push_back(ax.to_px(xs[i], ys[i]));
  }
  return runs;
}

}  // namespace

double auto_spot_box_um(const std::vector<const SpotData*>& rows) {
  // The radius holding 99% of each field's points (a thin flare may fall outside; the plot
  // counts it), largest over fields.
  double r = 0;
  for (const SpotData* s : rows)
    for (const SpotField& f : s->fields) {
      std::vector<double> d(f.x_um.size());
      for (std::size_t i = 0; i < d.size(); ++i) d[i] = std::hypot(f.x_um[i], f.y_um[i]);
      if (d.empty()) continue;
      const std::size_t k = std::min(d.size() - 1, static_cast<std::size_t>(0.99 * d.size()));
      std::nth_element(d.begin(), d.begin() + k, d.end());
      r = std::max(r, d[k]);
    }
  return fine_ceil(std::max(1.0, 2.1 * r));
}

void draw_spots(Canvas& canvas, Rect area, const std::vector<const SpotData*>& rows, double box_um,
                double font_px) {
  if (rows.empty()) return;
  const int nf = static_cast<int>(rows[0]->fields.size());
  const double top_band = font_px * 2.4;
  const double bottom_band = font_px * 2.6;
  const double row_title = font_px * 1.7, field_label = font_px * 1.5, rms_label = font_px * 1.7;
  const double gap = font_px * 1.2;
  const int nr = static_cast<int>(rows.size());
  const double avail_h = area.height - top_band - bottom_band;
  const double per_row_text = row_title + field_label + rms_label;
  const double side =
      std::max(20.0, std::min((area.width - gap * (nf - 1) - 8) / nf, avail_h / nr - per_row_text));
  const double row_h = side + per_row_text;
  const double total_w = nf * side + (nf - 1) * gap;
  const double x0 = area.x + (area.width - total_w) / 2;
  const double px_per_um = side / box_um;
  const char* unit = rows[0]->unit.c_str();  // the rows share one scale and so one unit

  // Top band: wavelength legend and the box size.
  const std::vector<LegendEntry> legend = wavelength_legend(*rows[0]);
  const Point lsize = legend_size(legend, font_px * 0.9, true);
  draw_legend(canvas, {x0, area.y + 2}, legend, font_px * 0.9, true);
  canvas.text({x0 + lsize.x + 14, area.y + 2 + lsize.y * 0.5 + font_px * 0.35},
              fmt::format("each box {} {} wide; circle: RMS radius; centred on the centroid",
                          format_tick(box_um, box_um), unit),
              TextStyle{font_px * 0.9, Anchor::kStart, "#444444"});

  for (int r = 0; r < nr; ++r) {
    const SpotData& spots = *rows[r];
    const double ry = area.y + top_band + r * row_h;
    TextStyle title{font_px, Anchor::kStart, kTextColour};
    title.bold = true;
    canvas.text(
        {x0, ry + font_px * 1.1},
        fmt::format("{}   mean RMS spot {:.1f} {} ({} field{})", spots.lens_name, spots.mean_rms_um,
                    unit, spots.analyzed_fields, spots.analyzed_fields == 1 ? "" : "s"),
        title);
    for (int j = 0; j < static_cast<int>(spots.fields.size()) && j < nf; ++j) {
      const SpotField& f = spots.fields[j];
      const double bx = x0 + j * (side + gap);
      const double by = ry + row_title + field_label;
      const Point c{bx + side / 2, by + side / 2};
      canvas.text({c.x, by - font_px * 0.45},
                  !f.position_label.empty()
                      ? fmt::format("{}  ({})", f.label, f.position_label)
                      : fmt::format("{}  (y {:.2f} mm)", f.label,
                                    std::abs(f.centroid_y_mm) < 0.005 ? 0.0 : f.centroid_y_mm),
                  TextStyle{font_px * 0.9, Anchor::kMiddle, "#333333"});
      canvas.rect({bx, by}, side, side, Style{"#b5b5b5", 1.0, "#ffffff"});
      const Style cross{"#e4e4e4", 0.8};
      canvas.line({bx, c.y}, {bx + side, c.y}, cross);
      canvas.line({c.x, by}, {c.x, by + side}, cross);
      // Points by wavelength, long wavelengths first.
      std::vector<int> order(spots.wavelengths_nm.size());
      for (std::size_t w = 0; w < order.size(); ++w) order[w] = static_cast<int>(w);
      std::sort(order.begin(), order.end(),
                [&](int a, int b) { return spots.wavelengths_nm[a] > spots.wavelengths_nm[b]; });
      std::vector<std::vector<Point>> by_wavelength(order.size());
      int outside = 0;
      const double half = side / 2 - 1;
      for (std::size_t i = 0; i < f.x_um.size(); ++i) {
        const double dx = f.x_um[i] * px_per_um, dy = -f.y_um[i] * px_per_um;
        if (std::abs(dx) > half || std::abs(dy) > half) {
          ++outside;
          continue;
        }
        by_wavelength[f.wavelength[i]].push_back({c.x + dx, c.y + dy});
      }
      for (int w : order)
        canvas.dots(by_wavelength[w], 0.85, wavelength_colour(spots.wavelengths_nm[w]), 0.6);
      const double rms_px = f.rms_um * px_per_um;
      if (rms_px <= half) canvas.circle(c, std::max(rms_px, 0.5), Style{"#111111", 1.2});
      if (outside > 0)
        canvas.text({bx + side - 3, by + side - 4}, fmt::format("{} outside", outside / 2),
                    TextStyle{font_px * 0.75, Anchor::kEnd, "#b03a2e"});
      TextStyle rms{font_px, Anchor::kMiddle, kTextColour};
      rms.bold = true;
      canvas.text({c.x, by + side + font_px * 1.25}, fmt::format("RMS {:.1f} {}", f.rms_um, unit),
                  rms);
    }
  }
  // Scale bar under the first box.
  const double bar_um = nice_step(0, box_um, 4);
  draw_scale_bar(canvas, {x0, area.y + top_band + nr * row_h + bottom_band * 0.45},
                 bar_um * px_per_um, fmt::format("{} {}", format_tick(bar_um, bar_um), unit),
                 font_px * 0.9);
}

void draw_fans(Canvas& canvas, Rect area, const FanData& fans, const FanData* cmp, double font_px) {
  const int nf = static_cast<int>(fans.fields.size());
  if (nf == 0) return;
  double max_abs = fans.max_abs_um;
  if (cmp) max_abs = std::max(max_abs, cmp->max_abs_um);
  const double y_lim = fine_ceil(std::max(1e-3, max_abs * 1.05));

  // Legend: channels (and the compared lens).
  std::vector<LegendEntry> legend;
  for (const FanCurve& c : fans.fields[0].tangential)
    legend.push_back({fmt::format("{} {:.1f} nm", channel_name(c.channel), c.wavelength_nm),
                      channel_colour(c.channel)});
  if (cmp) {
    legend.push_back({fans.lens_name + " (solid)", "#444444"});
    legend.push_back({cmp->lens_name + " (dashed)", "#444444", "5 3"});
  }
  const std::string note = "errors from the 587.6 nm chief ray";
  const double note_w = text_width_px(note, font_px * 0.9) + 24;
  const Point lsize = draw_legend(canvas, {area.x + font_px * 4.5, area.y + 2}, legend,
                                  font_px * 0.9, true, area.width - font_px * 4.5 - note_w);
  const double legend_h = lsize.y;
  canvas.text({area.x + font_px * 4.5 + lsize.x + 14, area.y + 2 + lsize.y / 2 + font_px * 0.3},
              note, TextStyle{font_px * 0.9, Anchor::kStart, "#444444"});

  const double left = font_px * 4.8, right = 6, bottom = font_px * 3.2;
  const double top = legend_h + font_px * 2.2;
  const double col_gap = font_px * 1.6, row_gap = font_px * 5.0;
  const double pw = (area.width - left - right - col_gap * (nf - 1)) / nf;
  const double ph = (area.height - top - bottom - row_gap) / 2;
  for (int row = 0; row < 2; ++row) {
    for (int j = 0; j < nf; ++j) {
      const Rect frame{area.x + left + j * (pw + col_gap), area.y + top + row * (ph + row_gap), pw,
                       ph};
      const Axes ax(frame, -1.0, 1.0, -y_lim, y_lim);
      AxesLabels labels;
      labels.title =
          fmt::format("{} {}", fans.fields[j].label, row == 0 ? "tangential" : "sagittal");
      labels.x_ticks = 2;
      labels.y_ticks = 4;
      labels.zero_x = labels.zero_y = true;
      labels.font_px = font_px * 0.9;
      labels.x_label = row == 0 ? "pupil Py" : "pupil Px";
      if (j == 0) labels.y_label = row == 0 ? "ey (\u00b5m)" : "ex (\u00b5m)";
      labels.y_tick_labels = j == 0;
      ax.draw_grid(canvas, labels);
      auto draw_set = [&](const FanData& data, bool dashed) {
        if (j >= static_cast<int>(data.fields.size())) return;
        const FanField& f = data.fields[j];
        for (const FanCurve& c : row == 0 ? f.tangential : f.sagittal) {
          Style s{channel_colour(c.channel), dashed ? 1.2 : 1.6};
          if (dashed) s.dash = "5 3";
          for (const auto& run : valid_runs(ax, c.pupil, c.error_um, c.valid))
            canvas.polyline(run, s);
        }
      };
      if (cmp) draw_set(*cmp, true);
      draw_set(fans, false);
      ax.draw_frame(canvas, labels);
    }
  }
}

void draw_field_curves(Canvas& canvas, Rect area, const FieldCurveData& data,
                       const FieldCurveData* cmp, double font_px) {
  const double hfov = data.field_deg.empty() ? 1.0 : data.field_deg.back();
  double max_dz = 0, max_d = 0;
  auto scan = [&](const FieldCurveData& d) {
    for (const FocusCurve& c : d.focus)
      for (std::size_t i = 0; i < c.valid.size(); ++i)
        if (c.valid[i])
          max_dz = std::max({max_dz, std::abs(c.tangential_mm[i]), std::abs(c.sagittal_mm[i])});
    for (double v : d.distortion_percent) max_d = std::max(max_d, std::abs(v));
    for (double v : d.sweep_distortion_percent) max_d = std::max(max_d, std::abs(v));
  };
  scan(data);
  if (cmp) scan(*cmp);
  const double dz_lim = fine_ceil(std::max(1e-3, max_dz * 1.1));
  const double d_lim = fine_ceil(std::max(1e-2, max_d * 1.1));
  const double y_hi = cmp && !cmp->field_deg.empty() ? std::max(hfov, cmp->field_deg.back()) : hfov;

  std::vector<LegendEntry> legend;
  for (const FocusCurve& c : data.focus)
    legend.push_back({fmt::format("{} {:.1f} nm", channel_name(c.channel), c.wavelength_nm),
                      channel_colour(c.channel)});
  legend.push_back({"tangential", "#444444"});
  legend.push_back({"sagittal", "#444444", "6 4"});
  if (cmp) legend.push_back({cmp->lens_name + " (faint)", "#aaaaaa"});
  const double legend_h = draw_legend(canvas, {area.x + font_px * 4.5, area.y + 2}, legend,
                                      font_px * 0.9, true, area.width - font_px * 4.5)
                              .y;

  const double left = font_px * 4.8, bottom = font_px * 3.4, gap = font_px * 5;
  const double top = legend_h + font_px * 2.2;
  const double pw = (area.width - left - gap - 8) / 2;
  const double ph = area.height - top - bottom;
  const Rect f1{area.x + left, area.y + top, pw, ph};
  const Rect f2{f1.right() + gap, area.y + top, pw, ph};

  // Field curvature.
  const Axes a1(f1, -dz_lim, dz_lim, 0.0, y_hi);
  AxesLabels l1;
  l1.title = "field curvature";
  l1.x_label = "focus shift from the image plane (mm)";
  l1.y_label = "field angle (\u00b0)";
  l1.zero_x = true;
  l1.x_ticks = 4;
  l1.font_px = font_px * 0.9;
  a1.draw_grid(canvas, l1);
  auto draw_focus = [&](const FieldCurveData& d, double opacity, double width) {
    for (const FocusCurve& c : d.focus) {
      Style t{channel_colour(c.channel), width, "none", opacity};
      Style s = t;
      s.dash = "6 4";
      for (const auto& run : valid_runs(a1, c.tangential_mm, d.field_deg, c.valid))
        canvas.polyline(run, t);
      for (const auto& run : valid_runs(a1, c.sagittal_mm, d.field_deg, c.valid))
        canvas.polyline(run, s);
    }
  };
  if (cmp) draw_focus(*cmp, 0.35, 1.2);
  draw_focus(data, 1.0, 1.6);
  a1.draw_frame(canvas, l1);

  // Distortion.
  const Axes a2(f2, -d_lim, d_lim, 0.0, y_hi);
  AxesLabels l2;
  l2.title = "distortion";
  l2.x_label = "distortion (%)";
  l2.y_label = "field angle (\u00b0)";
  l2.zero_x = true;
  l2.x_ticks = 4;
  l2.font_px = font_px * 0.9;
  a2.draw_grid(canvas, l2);
  // The curve over the focus curves' field grid; analyze's own fields as dots on it.
  auto draw_distortion = [&](const FieldCurveData& d, const Style& s) {
    if (d.sweep_distortion_percent.size() == d.field_deg.size() && !d.field_deg.empty()) {
      const std::vector<char> valid(d.field_deg.size(), 1);
      for (const auto& run : valid_runs(a2, d.sweep_distortion_percent, d.field_deg, valid))
        canvas.polyline(run, s);
    } else {
      const std::vector<char> valid(d.distortion_field_deg.size(), 1);
      for (const auto& run : valid_runs(a2, d.distortion_percent, d.distortion_field_deg, valid))
        canvas.polyline(run, s);
    }
    for (std::size_t i = 0; i < d.distortion_percent.size(); ++i)
      canvas.circle(a2.to_px(d.distortion_percent[i], d.distortion_field_deg[i]), 2.5,
                    Style{s.stroke, 1.0, s.stroke, s.opacity});
  };
  if (cmp) draw_distortion(*cmp, Style{"#aaaaaa", 1.4});
  draw_distortion(data, Style{"#222222", 1.8});
  a2.draw_frame(canvas, l2);
}

}  // namespace lensopt::plot
