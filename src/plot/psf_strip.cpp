#include "lensopt/plot/psf_strip.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "lensopt/core/error.h"
#include "lensopt/plot/style.h"
#include "lensopt/render/psf.h"

namespace lensopt::plot {

void PsfStripOptions::validate() const {
  if (field_fractions.empty()) throw Error("PSF strip: no field fractions given");
  for (double f : field_fractions)
    if (!(f >= 0.0 && f <= 1.0))
      throw Error(fmt::format("PSF strip: field fraction {} is outside [0, 1]", f));
  if (!(gamma >= 1.0 && gamma <= 4.0)) throw Error("PSF strip: gamma must be in [1, 4]");
}

PsfStrip compute_psf_strip(const PlotContext& ctx, const PsfStripOptions& options) {
  options.validate();
  const PsfOptions psf_options;  // the paper's grid, as the renderer uses
  psf_options.validate();
  validate_wavelength_channels(ctx.wavelength_channel, ctx.sys.wavelength_count);
  PsfStrip strip;
  strip.lens_name = ctx.lens.name;
  strip.bin_um = psf_options.bin_um;
  strip.grid_size = psf_options.grid_size;
  strip.gamma = options.gamma;
  const int g = psf_options.grid_size;
  RayBundle<double> rays;
  for (int h : field_indices(ctx, options.field_fractions)) {
    const FieldPsf<double> psf = field_psf(ctx.sys, h, ctx.wavelength_channel, psf_options, rays);
    PsfTile tile;
    tile.field = h;
    tile.field_deg = ctx.sys.fields_deg[h];
    tile.label = field_label(ctx.sys, h);
    tile.energy_share = 1.0;
    for (int k = 0; k < kColourChannels; ++k) {
      for (double v : psf.psf[k]) tile.peak = std::max(tile.peak, v);
      tile.energy_share = std::min(tile.energy_share, psf.energy_share[k]);
    }
    tile.image = RgbImage(g, g);
    const double inv = tile.peak > 0 ? 1.0 / tile.peak : 0.0;
    for (int r = 0; r < g; ++r)
      for (int i = 0; i < g; ++i)
        for (int k = 0; k < kColourChannels; ++k) {
          const double v = psf.psf[k][static_cast<std::size_t>(r) * g + i] * inv;
          tile.image.at(i, r)[k] =
              static_cast<float>(std::pow(std::clamp(v, 0.0, 1.0), 1.0 / options.gamma));
        }
    strip.tiles.push_back(std::move(tile));
  }
  return strip;
}

void draw_psf_strips(Canvas& canvas, Rect area, const std::vector<const PsfStrip*>& rows,
                     double font_px) {
  if (rows.empty() || rows[0]->tiles.empty()) return;
  const int n = static_cast<int>(rows[0]->tiles.size());
  const int nr = static_cast<int>(rows.size());
  const double top = font_px * 2.2, bottom = font_px * 2.4;
  const double title_h = font_px * 1.7, label_h = font_px * 1.4, below_h = font_px * 1.5;
  const double gap = font_px * 1.2;
  const double per_row_text = title_h + label_h + below_h;
  const double side = std::max(16.0, std::min((area.width - gap * (n - 1) - 8) / n,
                                              (area.height - top - bottom) / nr - per_row_text));
  const double total_w = n * side + (n - 1) * gap;
  const double x0 = area.x + (area.width - total_w) / 2;
  const PsfStrip& first = *rows[0];
  const double tile_um = first.bin_um * first.grid_size;
  canvas.text({x0, area.y + font_px * 1.2},
              fmt::format("each tile {:.0f} \u00b5m ({} x {} bins of {:.0f} \u00b5m), centred on "
                          "the centroid; R, G, B channels; scaled to its peak, gamma {:.1f}",
                          tile_um, first.grid_size, first.grid_size, first.bin_um, first.gamma),
              TextStyle{font_px * 0.9, Anchor::kStart, "#444444"});
  for (int r = 0; r < nr; ++r) {
    const PsfStrip& strip = *rows[r];
    const double ry = area.y + top + r * (side + per_row_text);
    TextStyle title{font_px, Anchor::kStart, kTextColour};
    title.bold = true;
    canvas.text({x0, ry + font_px * 1.1}, strip.lens_name, title);
    for (int j = 0; j < static_cast<int>(strip.tiles.size()) && j < n; ++j) {
      const PsfTile& t = strip.tiles[j];
      const double bx = x0 + j * (side + gap);
      const double by = ry + title_h + label_h;
      canvas.text({bx + side / 2, by - font_px * 0.45}, t.label,
                  TextStyle{font_px * 0.9, Anchor::kMiddle, "#333333"});
      canvas.image({bx, by}, side, side, t.image, true);
      canvas.rect({bx, by}, side, side, Style{"#777777", 1.0});
      canvas.text({bx + side / 2, by + side + font_px * 1.15},
                  fmt::format("brightest bin {:.1f}%{}", 100 * t.peak,
                              t.energy_share < 0.995
                                  ? fmt::format(", {:.0f}% in the tile", 100 * t.energy_share)
                                  : std::string()),
                  TextStyle{font_px * 0.8, Anchor::kMiddle, "#555555"});
    }
  }
  // Scale bar: 50 um (or a nice fraction of the tile).
  const double bar_um = nice_step(0, tile_um, 5);
  const double px_per_um = side / tile_um;
  draw_scale_bar(canvas, {x0, area.y + top + nr * (side + per_row_text) + bottom * 0.4},
                 bar_um * px_per_um, fmt::format("{} \u00b5m", format_tick(bar_um, bar_um)),
                 font_px * 0.9);
}

}  // namespace lensopt::plot
