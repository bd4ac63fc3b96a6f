// The per-lens imaging model, the sensor geometry and the radial interpolations.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "lensopt/analysis/afocal.h"
#include "lensopt/analysis/field_optics.h"
#include "lensopt/core/error.h"
#include "lensopt/core/interpolate.h"
#include "lensopt/render/render.h"

namespace lensopt {

void RenderOptions::validate() const {
  if (res_factor != 1 && res_factor != 2)
    throw Error(fmt::format("resolution factor {} must be 1 or 2", res_factor));
  if (threads < 0 || threads > 1024)
    throw Error(fmt::format("threads = {} must be in [0, 1024]", threads));
}

int colour_channel_count(int channels) {
  return channels >= 3 ? 3 : 1;
}

ImagingModel build_imaging_model(const Lens& lens, const TraceOptions& trace,
                                 const PsfOptions& psf) {
  trace.validate();
  psf.validate();
  validate_wavelength_channels(lens.specs.wavelength_channels,
                               static_cast<int>(lens.specs.wavelengths_nm.size()));
  // An afocal lens (Specs::afocal) has no image plane: its image is at infinity, measured in
  // angle (analysis/afocal.h). A render puts a sensor at the image: refused (the one policy,
  // refuse_afocal), saying what does measure the lens.
  refuse_afocal(lens, "render");
  // One prepared system and one trace: the spot, centroids, distortion and relative illumination
  // (analysis/field_optics.h, the numbers `lensopt analyze` prints) and the geometric PSFs come
  // from the same rays.
  auto sys_ptr = std::make_shared<const TraceSystem<double>>(
      prepare_system(make_trace_lens(lens), lens_setup(lens, trace), trace));
  const TraceSystem<double>& sys = *sys_ptr;
  FieldOpticsOptions field_options;
  field_options.threads = trace.threads;
  PsfRayCollector<double> rays(sys);
  const FieldOptics<double> measured = measure_fields(sys, field_options, rays);

  ImagingModel model;
  model.lens_name = lens.name;
  model.sensor_diagonal_mm = lens.specs.sensor_diagonal_mm;
  model.trace = trace;
  model.system = sys_ptr;
  model.ray_failures = measured.spots.total_failed;
  model.psfs =
      psfs_from_rays(sys, measured.spots, rays, lens.specs.wavelength_channels, psf, trace.threads);
  const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
  // The PSF window's energy share E_k (psf.h): below 99 % the rays outside the G x D um grid are
  // lost and the kernel, renormalized, is sharper than the spot.
  constexpr double kWindowShare = 0.99;
  int short_fields = 0, worst_field = -1, worst_channel = 0;
  double worst_share = 1.0;
  for (std::size_t h = 0; h < model.psfs.fields.size(); ++h) {
    bool short_field = false;
    for (int k = 0; k < kColourChannels; ++k) {
      const FieldPsf<double>& f = model.psfs.fields[h];
      if (f.traced_rays[k] == 0 || !(f.energy_share[k] < kWindowShare)) continue;
      short_field = true;
      if (f.energy_share[k] < worst_share) {
        worst_share = f.energy_share[k];
        worst_field = static_cast<int>(h);
        worst_channel = k;
      }
    }
    short_fields += short_field;
  }
  if (worst_field >= 0)
    model.warnings.push_back(fmt::format(
        "{}: the geometric PSF window ({} x {:g} um = {:g} um) holds {:.1f} % of the traced rays' "
        "energy at field {:.2f} deg ({}), and less than {:.0f} % at {} of {} fields: the blur "
        "outside it is cut off, so the image there is sharper than the lens",
        where, psf.grid_size, psf.bin_um, psf.grid_size * psf.bin_um, 100.0 * worst_share,
        sys.fields_deg[worst_field], "RGB"[worst_channel], 100.0 * kWindowShare, short_fields,
        model.psfs.fields.size()));
  for (std::size_t h = 0; h < measured.size(); ++h) {
    if (measured.spots.traced_rays[h] == 0) {
      throw Error(SourceLocation{where},
                  fmt::format("cannot render: no ray of field {:.2f} deg reaches the image",
                              measured.fields_deg[h]));
    }
    model.fields_deg.push_back(measured.fields_deg[h]);
    model.reference_y_mm.push_back(measured.reference_y_mm[h]);
    model.centroid_y_mm.push_back(measured.spots.centroid_y_mm[h]);
    model.distortion.push_back(measured.distortion[h]);
    if (!measured.relative_illumination_known[h] && model.unknown_relative_illumination.empty())
      model.unknown_relative_illumination =
          Error(SourceLocation{where},
                fmt::format("the relative illumination of field {:.2f} deg is unknown ({}): "
                            "render with --no-relative-illumination",
                            measured.fields_deg[h], measured.relative_illumination_unknown[h]))
              .what();
    model.relative_illumination.push_back(
        measured.relative_illumination_known[h] ? measured.relative_illumination[h] : 0.0);
  }
  // A lens with one field (fields are distinct radial heights, lens_setup), usually on axis
  // only: its PSF for the whole image, no distortion (the warp is the identity,
  // render/distortion_warp.h) and R = 1. Rendered, as one would judge an on-axis design, but
  // saying what is not known.
  if (model.fields_deg.size() == 1)
    model.warnings.push_back(fmt::format(
        "{}: the lens has one field ({:.2f} deg): the render uses its PSF everywhere, without "
        "distortion or relative illumination; the blur, distortion and illumination elsewhere "
        "in the field are unknown (add fields to the lens to render them)",
        where, model.fields_deg[0]));
  // A diverging lens's image is virtual and upright: its paraxial image heights go negative
  // with the field. The renderer maps a scene onto the image of a converging lens only.
  if (model.reference_y_mm.size() > 1 && model.reference_y_mm.back() < 0.0)
    throw Error(SourceLocation{where},
                fmt::format("cannot render: the lens diverges (EFL {:.6g} mm): its image is "
                            "virtual and upright (paraxial image height {:.6g} mm at {:.2f} "
                            "deg), and lensopt renders the real image of a converging lens; "
                            "analyze and plot measure it",
                            sys.efl_mm, model.reference_y_mm.back(), model.fields_deg.back()));
  for (std::size_t h = 1; h < model.reference_y_mm.size(); ++h) {
    if (!(model.reference_y_mm[h] > model.reference_y_mm[h - 1])) {
      throw Error(SourceLocation{where},
                  "cannot render: the paraxial image heights do not increase with the field");
    }
  }
  return model;
}

SensorGeometry SensorGeometry::make(int width, int height, int res_factor,
                                    double sensor_diagonal_mm) {
  SensorGeometry g;
  g.width = width;
  g.height = height;
  g.res_factor = res_factor;
  const double diagonal_px = std::hypot(static_cast<double>(width), static_cast<double>(height));
  g.pitch_mm = sensor_diagonal_mm / (res_factor * diagonal_px);
  g.axis_x = res_factor == 1 ? 0.5 * width : static_cast<double>(width);
  g.axis_y = res_factor == 1 ? 0.5 * height : static_cast<double>(height);
  return g;
}

double SensorGeometry::radius_mm(int i, int j) const {
  // sqrt rather than std::hypot (no overflow to guard against here): 20x faster, and the
  // PSF grid's field weights evaluate it at every pixel of the image.
  const double dx = i + 0.5 - axis_x, dy = j + 0.5 - axis_y;
  return pitch_mm * std::sqrt(dx * dx + dy * dy);
}

void require_relative_illumination(const ImagingModel& model) {
  if (!model.unknown_relative_illumination.empty())
    throw Error(model.unknown_relative_illumination);
}

double relative_illumination_at(const ImagingModel& model, double radius_mm) {
  return interpolate_linear(model.reference_y_mm, model.relative_illumination, radius_mm, false);
}

double distortion_at(const ImagingModel& model, double radius_mm) {
  return interpolate_linear(model.reference_y_mm, model.distortion, radius_mm, true);
}

double undistorted_radius_mm(const ImagingModel& model, double distorted_radius_mm) {
  const std::vector<double>& ybar = model.centroid_y_mm;
  if (ybar.size() < 2) return distorted_radius_mm;  // on axis only: no distortion known
  for (std::size_t h = 1; h < ybar.size(); ++h) {
    if (!(ybar[h] > ybar[h - 1])) {
      throw Error(
          fmt::format("cannot apply distortion: the image heights of fields {:.2f} and "
                      "{:.2f} deg do not increase ({:.6f}, {:.6f} mm); render with "
                      "--no-distortion",
                      model.fields_deg[h - 1], model.fields_deg[h], ybar[h - 1], ybar[h]));
    }
  }
  return interpolate_linear(ybar, model.reference_y_mm, distorted_radius_mm, true);
}

}  // namespace lensopt
