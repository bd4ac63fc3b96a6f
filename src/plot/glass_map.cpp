// The glass map (plot/glass_map.h): axes vd (x, decreasing) and nd (y), a dot per glass.
#include "lensopt/plot/glass_map.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "lensopt/core/error.h"
#include "lensopt/plot/axes.h"
#include "lensopt/plot/canvas.h"
#include "lensopt/plot/style.h"

namespace lensopt::plot {

int write_glass_map(const std::filesystem::path& path,
                    const std::vector<std::shared_ptr<const Catalog>>& catalogs,
                    const std::vector<const Glass*>& glasses, const GlassMapOptions& options) {
  const auto wanted = [&](const Glass* g) {
    return glasses.empty() || std::find(glasses.begin(), glasses.end(), g) != glasses.end();
  };
  // The data range over the drawn glasses.
  double nd_lo = std::numeric_limits<double>::infinity(), nd_hi = -nd_lo;
  double vd_lo = nd_lo, vd_hi = -nd_lo;
  int count = 0;
  for (const auto& catalog : catalogs)
    for (const Glass& g : catalog->glasses) {
      if (!wanted(&g) || !(g.nd > 1.0) || !(g.vd > 0.0)) continue;
      nd_lo = std::min(nd_lo, g.nd);
      nd_hi = std::max(nd_hi, g.nd);
      vd_lo = std::min(vd_lo, g.vd);
      vd_hi = std::max(vd_hi, g.vd);
      ++count;
    }
  if (count == 0)
    throw Error(SourceLocation{path.string()},
                "no glass with nd and vd to draw (infrared materials have neither)");
  const double nd_pad = std::max(0.02, 0.05 * (nd_hi - nd_lo));
  const double vd_pad = std::max(2.0, 0.05 * (vd_hi - vd_lo));
  const double width = 900, height = 640;
  auto canvas = make_canvas(path, width, height);
  canvas->rect({0, 0}, width, height, Style{"none", 0.0, "#ffffff"});
  const Rect frame = Rect{0, 0, width, height}.inset(70, 40, 170, 55);
  // vd decreases to the right: the axes run from -vd_hi to -vd_lo and the labels are negated.
  const Axes axes(frame, -(vd_hi + vd_pad), -(vd_lo - vd_pad), nd_lo - nd_pad, nd_hi + nd_pad);
  AxesLabels labels;
  labels.title = options.title;
  labels.x_label = "Abbe number vd (decreasing to the right)";
  labels.y_label = "nd";
  labels.x_ticks = 0;  // drawn below with positive vd labels
  axes.draw_grid(*canvas, labels);
  std::vector<LegendEntry> legend;
  for (std::size_t c = 0; c < catalogs.size(); ++c) {
    // A categorical palette (12 distinct colours, then repeated).
    static const char* const kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e",
                                           "#9467bd", "#8c564b", "#e377c2", "#17becf",
                                           "#bcbd22", "#7f7f7f", "#393b79", "#637939"};
    const std::string colour = kPalette[c % (sizeof(kPalette) / sizeof(kPalette[0]))];
    std::vector<Point> dots;
    for (const Glass& g : catalogs[c]->glasses) {
      if (!wanted(&g) || !(g.nd > 1.0) || !(g.vd > 0.0)) continue;
      dots.push_back(axes.to_px(-g.vd, g.nd));
      if (options.label_glasses)
        canvas->text({dots.back().x + 4, dots.back().y - 3}, g.name,
                     TextStyle(9, Anchor::kStart, kTextColour));
    }
    if (dots.empty()) continue;
    canvas->dots(dots, 2.5, colour, 0.85);
    legend.emplace_back(fmt::format("{} ({})", catalogs[c]->name, dots.size()), colour, "", true);
  }
  axes.draw_frame(*canvas, labels);
  // x ticks: vd values (positive), the axis running on -vd.
  const double step = nice_step(vd_lo - vd_pad, vd_hi + vd_pad, 8);
  for (double vd : nice_ticks(vd_lo - vd_pad, vd_hi + vd_pad, 8)) {
    const Point p = axes.to_px(-vd, axes.y_lo());
    canvas->line(p, {p.x, p.y + 5}, Style{kTextColour, 1.0});
    canvas->text({p.x, p.y + 18}, format_tick(vd, step),
                 TextStyle(11, Anchor::kMiddle, kTextColour));
  }
  draw_legend(*canvas, {frame.right() + 12, frame.y}, legend, 11);
  canvas->save(path);
  return count;
}

}  // namespace lensopt::plot
