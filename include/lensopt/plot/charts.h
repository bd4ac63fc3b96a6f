// Drawing the analysis charts (plot_data.h) on a Canvas: spot diagrams, ray fans, field
// curvature and distortion. Each draws into a rectangle of the page, so the report page and the
// single-kind pages share the same code.
#pragma once

#include <vector>

#include "lensopt/plot/axes.h"
#include "lensopt/plot/plot_data.h"

namespace lensopt::plot {

// A spot box width (um) for every row: on the fine_ceil ladder above 2.1 x the largest (over
// fields) radius that holds 99% of a field's points.
double auto_spot_box_um(const std::vector<const SpotData*>& rows);

// Spot diagrams: one row per lens (all on one scale: each box is `box_um` wide), one box per
// field, points coloured by wavelength, the RMS radius as a circle and in numbers, a scale bar.
void draw_spots(Canvas& canvas, Rect area, const std::vector<const SpotData*>& rows, double box_um,
                double font_px = 12);

// Ray fans: per field a tangential (e_y vs P_y) and a sagittal (e_x vs P_x) panel, one curve per
// colour channel; a compared lens dashed.
void draw_fans(Canvas& canvas, Rect area, const FanData& fans, const FanData* compare = nullptr,
               double font_px = 12);

// Field curvature (tangential solid, sagittal dashed, per channel) and distortion against field.
void draw_field_curves(Canvas& canvas, Rect area, const FieldCurveData& data,
                       const FieldCurveData* compare = nullptr, double font_px = 12);

}  // namespace lensopt::plot
