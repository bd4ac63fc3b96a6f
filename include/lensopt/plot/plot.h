// `lensopt plot`: one page per kind (layout, spot, fan, field, psf) or a report page combining
// them, for a lens and optionally a second lens to compare, written as SVG or PNG by extension.
// Every page is drawn once on a Canvas (canvas.h); the backend decides the format.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "lensopt/lens/lens.h"
#include "lensopt/plot/canvas.h"
#include "lensopt/plot/plot_data.h"

namespace lensopt::plot {

enum class PlotKind {
  kLayout,
  kSpot,
  kFan,
  kField,
  kPsf,
  kReport,
  kMtf,              // diffraction MTF against frequency (wave optics, analysis/wave.h)
  kThroughFocus,     // MTF at one frequency against focus
  kWavefront,        // OPD maps
  kPsfDiffraction,   // polychromatic diffraction PSFs
  kMtfField,         // MTF at chosen frequencies and RMS spot against field (field_sweep.h)
  kChromatic,        // chromatic focal shift and lateral colour (analysis/chromatic.h)
  kEncircledEnergy,  // diffraction and geometric encircled energy (encircled_energy.h)
};

// "layout", "spot", "fan", "field", "psf", "report", "mtf", "through-focus", "wavefront",
// "psf-diffraction", "mtf-field", "chromatic", "encircled-energy".
const std::vector<std::string>& plot_kind_names();
// Throws Error naming the valid kinds for anything else.
PlotKind parse_plot_kind(const std::string& name);
std::string plot_kind_name(PlotKind kind);

struct PlotOptions {
  PlotKind kind = PlotKind::kReport;
  double spot_box_um = 0;   // width of each spot-diagram box; 0: fit the largest spot
  double width_px = 0;      // page width; 0: the kind's default
  TraceOptions trace;       // analysis sampling (defaults: 21 fields, 32 rings, ray aiming)
  int pupil_samples = 128;  // wave-optics kinds: pupil grid across the diameter
  double mtf_frequency_cyc_mm = 30;  // through-focus: the frequency
  double max_frequency_cyc_mm = 0;   // mtf: the axis's end (0: the cutoff 1 / (lambda_min N))
  double focus_range_mm = 0;         // through-focus: shifts in [-range, range] (0: 8 lambda N^2)
  std::vector<double> mtf_frequencies_cyc_mm{10, 30, 50};  // mtf-field: the frequencies
  int sweep_fields = 11;  // mtf-field and chromatic: field angles from 0 to the largest field
  double band_lo_nm = 0, band_hi_nm = 0;  // chromatic: the band (0, 0: the spec wavelengths')

  // Throws Error for out-of-range values.
  void validate() const;
};

struct PlotSummary {
  std::filesystem::path output;
  OutputFormat format = OutputFormat::kSvg;
  double width_px = 0;
  double height_px = 0;
  double spot_box_um = 0;  // the spot scale used (0 if the page has no spots)
  // The unit of spot_box_um as drawn: "um" on an image plane, "urad" for an afocal lens's
  // spots in angle (plot/afocal_plot).
  std::string spot_box_unit = "um";
  std::vector<std::string> warnings;
};

// Draws a page on a new canvas of the format of `output` and writes it atomically.
PlotSummary write_plot(const Lens& lens, const Lens* compare, const PlotOptions& options,
                       const std::filesystem::path& output);

// The page drawn onto a canvas made by `make` (width, height) -> canvas, without writing it;
// for tests and for callers that want the canvas.
using CanvasFactory = std::function<std::unique_ptr<Canvas>(double, double)>;
std::unique_ptr<Canvas> draw_plot(const PlotContext& lens, const PlotContext* compare,
                                  const PlotOptions& options, const CanvasFactory& make,
                                  PlotSummary* summary = nullptr);

}  // namespace lensopt::plot
