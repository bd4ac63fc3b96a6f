// The sampled PSFs of a few fields as an RGB strip, from the render module's kernel-density PSFs
// (render/psf.h: 65 x 65 bins of 4 um centred on each field's polychromatic centroid, one grid per
// colour channel, each summing to 1).
// Display: tile pixel (r, i) = (R, G, B) = (p_R, p_G, p_B)(r, i) / peak, peak the largest bin of
// the tile's three channels, then a display gamma v^(1/gamma) so faint halos show; every tile
// spans the same 260 um, so a sharper lens has smaller, brighter cores.
#pragma once

#include <string>
#include <vector>

#include "lensopt/plot/axes.h"
#include "lensopt/plot/plot_data.h"

namespace lensopt::plot {

struct PsfTile {
  int field = 0;
  double field_deg = 0;
  std::string label;        // field_label
  RgbImage image;           // grid_size x grid_size, row 0 = sensor +y
  double peak = 0;          // largest bin value (fraction of a channel's energy)
  double energy_share = 0;  // smallest channel's share of energy inside the grid
};

struct PsfStrip {
  std::string lens_name;
  double bin_um = 0;
  int grid_size = 0;
  double gamma = 2.0;
  std::vector<PsfTile> tiles;
};

struct PsfStripOptions {
  std::vector<double> field_fractions{0.0, 0.25, 0.5, 0.75, 1.0};
  double gamma = 2.0;  // displayed value v^(1/gamma)
  void validate() const;
};

PsfStrip compute_psf_strip(const PlotContext& ctx, const PsfStripOptions& options = {});

// One strip per lens (one row each), tiles side by side on black, with field labels, the tile
// size and a scale bar.
void draw_psf_strips(Canvas& canvas, Rect area, const std::vector<const PsfStrip*>& rows,
                     double font_px = 12);

}  // namespace lensopt::plot
