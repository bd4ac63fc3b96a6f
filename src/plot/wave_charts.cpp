#include "lensopt/plot/wave_charts.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "lensopt/plot/style.h"

namespace lensopt::plot {
namespace {

// Diverging colour map for signed values in [-1, 1]: blue, white, red.
void diverging(double v, float rgb[3]) {
  v = std::clamp(v, -1.0, 1.0);
  if (v < 0) {
    rgb[0] = rgb[1] = static_cast<float>(1.0 + v * 0.85);
    rgb[2] = 1.f;
  } else {
    rgb[0] = 1.f;
    rgb[1] = rgb[2] = static_cast<float>(1.0 - v * 0.85);
  }
}

}  // namespace

namespace {

// The legend name of field j: its label, else its angle.
std::string field_name(const std::vector<std::string>& labels, std::size_t j, double field_deg) {
  return j < labels.size() ? labels[j] : fmt::format("{:.1f}\u00b0", field_deg);
}

}  // namespace

void draw_mtf_curves(Canvas& canvas, Rect area, const WaveReport& mtf, const std::string& title,
                     double font_px, const std::vector<std::string>& field_labels) {
  const double cutoff = mtf.frequencies_cyc_mm.empty() ? 1.0 : mtf.frequencies_cyc_mm.back();
  const Rect frame = area.inset(font_px * 4.5, font_px * 2.2, font_px * 12, font_px * 3.2);
  const Axes ax(frame, 0.0, cutoff, 0.0, 1.0);
  AxesLabels labels;
  labels.title = title;
  labels.x_label = "spatial frequency (cycles/mm)";
  labels.y_label = "MTF";
  labels.font_px = font_px;
  ax.draw_grid(canvas, labels);
  canvas.set_clip(frame.x, frame.y, frame.width, frame.height);
  std::vector<Point> ideal;
  for (int k = 0; k <= 100; ++k) {
    const double nu = cutoff * k / 100.0;
    ideal.push_back(ax.to_px(nu, diffraction_limited_mtf(nu / mtf.cutoff_cyc_mm)));
  }
  canvas.polyline(ideal, Style{"#000000", 1.2});
  std::vector<LegendEntry> legend{{"diffraction limit", "#000000"}};
  const int count = static_cast<int>(mtf.fields.size());
  for (int j = 0; j < count; ++j) {
    const WaveField& f = mtf.fields[j];
    const std::string colour = field_colour(j, count);
    std::vector<Point> t, s;
    for (std::size_t k = 0; k < mtf.frequencies_cyc_mm.size(); ++k) {
      t.push_back(ax.to_px(mtf.frequencies_cyc_mm[k], f.mtf_t[k]));
      s.push_back(ax.to_px(mtf.frequencies_cyc_mm[k], f.mtf_s[k]));
    }
    canvas.polyline(t, Style{colour, 1.6});
    canvas.polyline(s, Style{colour, 1.6, "none", 1.0, "6 4"});
    const std::string name = field_name(field_labels, j, f.field_deg);
    legend.push_back({name + " T", colour});
    legend.push_back({name + " S", colour, "6 4"});
  }
  canvas.clear_clip();
  ax.draw_frame(canvas, labels);
  draw_legend(canvas, {frame.right() + font_px, frame.y}, legend, font_px * 0.9);
}

void draw_through_focus(Canvas& canvas, Rect area, const ThroughFocus& data, double font_px,
                        const std::vector<std::string>& field_labels) {
  const double lo = data.focus_shift_mm.front() * 1e3, hi = data.focus_shift_mm.back() * 1e3;
  const Rect frame = area.inset(font_px * 4.5, font_px * 2.2, font_px * 12, font_px * 3.2);
  const Axes ax(frame, lo, hi, 0.0, 1.0);
  AxesLabels labels;
  labels.title = fmt::format("through-focus MTF at {:g} cycles/mm", data.frequency_cyc_mm);
  labels.x_label = "focus shift (\u00b5m)";
  labels.y_label = "MTF";
  labels.zero_x = true;
  labels.font_px = font_px;
  ax.draw_grid(canvas, labels);
  std::vector<LegendEntry> legend;
  const int count = static_cast<int>(data.field_deg.size());
  for (int j = 0; j < count; ++j) {
    const std::string colour = field_colour(j, count);
    std::vector<Point> t, s;
    for (std::size_t k = 0; k < data.focus_shift_mm.size(); ++k) {
      t.push_back(ax.to_px(data.focus_shift_mm[k] * 1e3, data.mtf_t[j][k]));
      s.push_back(ax.to_px(data.focus_shift_mm[k] * 1e3, data.mtf_s[j][k]));
    }
    canvas.polyline(t, Style{colour, 1.6});
    canvas.polyline(s, Style{colour, 1.6, "none", 1.0, "6 4"});
    const std::string name = field_name(field_labels, j, data.field_deg[j]);
    legend.push_back({name + " T", colour});
    legend.push_back({name + " S", colour, "6 4"});
  }
  ax.draw_frame(canvas, labels);
  draw_legend(canvas, {frame.right() + font_px, frame.y}, legend, font_px * 0.9);
}

void draw_wavefront_maps(Canvas& canvas, Rect area, const std::vector<WavefrontPanel>& panels,
                         double font_px) {
  if (panels.empty()) return;
  const int count = static_cast<int>(panels.size());
  const double gap = font_px * 1.5;
  const double side = std::min((area.width - gap * (count + 1)) / count, area.height - font_px * 6);
  const TextStyle label{font_px, Anchor::kMiddle, kTextColour};
  for (int j = 0; j < count; ++j) {
    const WavefrontPanel& p = panels[j];
    // Symmetric colour scale: the panel's largest |W|.
    double peak = 0;
    for (double v : p.opd_waves)
      if (std::isfinite(v)) peak = std::max(peak, std::abs(v));
    if (!(peak > 0)) peak = 1;
    RgbImage image(p.n, p.n);
    for (int r = 0; r < p.n; ++r)
      for (int c = 0; c < p.n; ++c) {
        const double v = p.opd_waves[static_cast<std::size_t>(r) * p.n + c];
        float* px = image.at(c, r);
        if (!std::isfinite(v)) {
          px[0] = px[1] = px[2] = 0.92f;
          continue;
        }
        diverging(v / peak, px);
      }
    const double x = area.x + gap + j * (side + gap);
    const double y = area.y + font_px * 1.6;
    canvas.text({x + side / 2, area.y + font_px * 1.1}, p.label, label);
    canvas.image({x, y}, side, side, image, true);
    canvas.rect({x, y}, side, side, Style{"#666666", 1.0});
    canvas.text({x + side / 2, y + side + font_px * 1.4},
                fmt::format("RMS {:.3f} waves  P-V {:.3f}  (colour scale +/-{:.3g} waves)",
                            p.rms_waves, p.pv_waves, peak),
                TextStyle{font_px * 0.9, Anchor::kMiddle, kTextColour});
  }
}

void draw_diffraction_psfs(Canvas& canvas, Rect area, const std::vector<PsfPanel>& panels,
                           double spacing_um, double font_px) {
  if (panels.empty()) return;
  const int count = static_cast<int>(panels.size());
  const double gap = font_px * 1.5;
  const double side = std::min((area.width - gap * (count + 1)) / count, area.height - font_px * 6);
  const TextStyle label{font_px, Anchor::kMiddle, kTextColour};
  for (int j = 0; j < count; ++j) {
    const PsfPanel& p = panels[j];
    RgbImage image(p.pixels, p.pixels);
    for (int r = 0; r < p.pixels; ++r)
      for (int c = 0; c < p.pixels; ++c) {
        // Log scale over 4 decades.
        const double v = p.psf[static_cast<std::size_t>(r) * p.pixels + c];
        const float g =
            static_cast<float>(std::clamp(1.0 + std::log10(std::max(v, 1e-6)) / 4.0, 0.0, 1.0));
        float* px = image.at(c, r);
        px[0] = g;
        px[1] = g;
        px[2] = g;
      }
    const double x = area.x + gap + j * (side + gap);
    const double y = area.y + font_px * 1.6;
    canvas.text({x + side / 2, area.y + font_px * 1.1}, p.label, label);
    canvas.image({x, y}, side, side, image, false);
    canvas.text({x + side / 2, y + side + font_px * 1.4},
                fmt::format("{:.1f} \u00b5m wide, log scale (4 decades)", p.pixels * spacing_um),
                TextStyle{font_px * 0.9, Anchor::kMiddle, kTextColour});
  }
}

}  // namespace lensopt::plot
