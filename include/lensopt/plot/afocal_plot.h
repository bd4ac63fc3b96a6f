// `lensopt plot --kind spot` of an afocal lens (Specs::afocal, analysis/afocal.h): the spot
// diagram in angle. Each field's exit rays are drawn at their angles from the field's centroid
// direction (AngularSpot: gnomonic projection on the plane normal to it), in microradians, with
// the RMS angular radius as a circle, and the output chief-ray angle under the field's name.
// The other kinds measure an image plane, which an afocal lens does not have: they are refused.
#pragma once

#include <filesystem>

#include "lensopt/lens/lens.h"
#include "lensopt/plot/plot.h"
#include "lensopt/plot/plot_data.h"

namespace lensopt::plot {

// The spot data of an afocal lens in microradians (SpotData::unit), every field of the lens
// (at most `max_fields`, spread over them), points from the analysis's own rays.
SpotData afocal_spot_data(const Lens& lens, const TraceOptions& trace, int max_fields = 5);

// The page of write_plot for an afocal lens: options.kind must be kSpot (or kReport, which is
// the spot page for an afocal lens); a compared lens must be afocal too.
PlotSummary write_afocal_plot(const Lens& lens, const Lens* compare, const PlotOptions& options,
                              const std::filesystem::path& output);

}  // namespace lensopt::plot
