#include "lensopt/render/export.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/image_plugin.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"

namespace lensopt {
namespace {

namespace fs = std::filesystem;

// Peak-normalized, gamma 1/2.2 copy of a tile's values (for viewing).
float view_value(float v, float peak) {
  return peak > 0 ? std::pow(std::clamp(v / peak, 0.0f, 1.0f), 1.0f / 2.2f) : 0.0f;
}

// Draws a label; false if no font could be found.
bool label(FloatImage& img, int x, int y, const std::string& text, int size) {
  const float white[4] = {0.9f, 0.9f, 0.9f, 0.9f};
  if (img.channels < 1 || img.channels > 4) return false;
  return image_plugin("the PSF sheet's labels (text through OpenImageIO)")
      .render_text(img.pixels.data(), img.width, img.height, img.channels, x, y, text, size,
                   "DejaVuSans", white, false);
}

// psf/field_NN.exr (the field PSFs, G x G, RGB) and psf_sheet.png (peak-normalized, gamma 1/2.2,
// labelled with the field angle).
// `suffix` ("" or "_diffraction") names the files of `psfs` (the model's, or its diffraction
// PSFs).
void write_field_psfs(const ImagingModel& model, const PsfSet<double>& psfs,
                      const std::string& suffix, const fs::path& dir, ExportSummary& summary) {
  auto wrote = [&](const fs::path& p) { summary.files.push_back(p); };
  const int g = psfs.options.grid_size;
  const int field_count = static_cast<int>(model.fields_deg.size());
  constexpr int kScale = 3, kColumns = 7, kMargin = 8, kLabel = 22;
  const int tile = g * kScale;
  const int rows = (field_count + kColumns - 1) / kColumns;
  FloatImage sheet(kMargin + kColumns * (tile + kMargin),
                   kMargin + rows * (tile + kLabel + kMargin), 3, 0.0f);
  summary.labels_drawn = true;
  for (int h = 0; h < field_count; ++h) {
    const FieldPsf<double>& f = psfs.fields[h];
    FloatImage img(g, g, 3);
    float peak = 0;
    for (int c = 0; c < 3; ++c)
      for (int i = 0; i < g * g; ++i) {
        img.pixels[static_cast<std::size_t>(i) * 3 + c] = static_cast<float>(f.psf[c][i]);
        peak = std::max(peak, static_cast<float>(f.psf[c][i]));
      }
    const fs::path path = dir / "psf" / fmt::format("field_{:02d}{}.exr", h, suffix);
    write_float_image(path, img);
    wrote(path);
    const int x0 = kMargin + (h % kColumns) * (tile + kMargin);
    const int y0 = kMargin + (h / kColumns) * (tile + kLabel + kMargin) + kLabel;
    for (int y = 0; y < tile; ++y)
      for (int x = 0; x < tile; ++x)
        for (int c = 0; c < 3; ++c)
          sheet.at(x0 + x, y0 + y, c) = view_value(img.at(x / kScale, y / kScale, c), peak);
    summary.labels_drawn &=
        label(sheet, x0, y0 - 6, fmt::format("{:.2f} deg", model.fields_deg[h]), 15);
  }
  const fs::path sheet_path = dir / fmt::format("psf_sheet{}.png", suffix);
  write_image(sheet_path, sheet);
  wrote(sheet_path);
}

// psf_grid.exr (the 9 x 9 patch kernels at the pixel pitch, each centred in a tile of the
// largest kernel's size) and psf_grid.png (each tile peak-normalized for viewing).
void write_psf_grid(const PsfGrid& grid, const fs::path& dir, ExportSummary& summary) {
  auto wrote = [&](const fs::path& p) { summary.files.push_back(p); };
  const int k = 2 * grid.max_radius + 1;
  const int n = PsfGrid::kPatches;
  summary.kernel_size = k;
  summary.pitch_um = grid.geometry.pitch_mm * 1000.0;
  const int view_scale = std::max(1, (96 + k - 1) / k);  // tiles of about 100 px
  FloatImage grid_img(n * k, n * k, 3, 0.0f);
  FloatImage grid_view(n * (k * view_scale + 2), n * (k * view_scale + 2), 3, 0.0f);
  for (int q = 0; q < n * n; ++q) {
    const int tx = (q % n) * k, ty = (q / n) * k;
    float peak = 0;
    for (int c = 0; c < 3; ++c) {
      const PixelKernel& kernel = grid.kernels[q][c];
      for (int dy = -kernel.radius; dy <= kernel.radius; ++dy)
        for (int dx = -kernel.radius; dx <= kernel.radius; ++dx) {
          const float v = kernel.at(dx, dy);
          grid_img.at(tx + grid.max_radius + dx, ty + grid.max_radius + dy, c) = v;
          peak = std::max(peak, v);
        }
    }
    const int vx = (q % n) * (k * view_scale + 2) + 1, vy = (q / n) * (k * view_scale + 2) + 1;
    for (int y = 0; y < k * view_scale; ++y)
      for (int x = 0; x < k * view_scale; ++x)
        for (int c = 0; c < 3; ++c)
          grid_view.at(vx + x, vy + y, c) =
              view_value(grid_img.at(tx + x / view_scale, ty + y / view_scale, c), peak);
  }
  write_float_image(dir / "psf_grid.exr", grid_img);
  wrote(dir / "psf_grid.exr");
  write_image(dir / "psf_grid.png", grid_view);
  wrote(dir / "psf_grid.png");
}

// distortion.exr: per pixel the warp's source offset (dx, dy, pixels) and D(r) at the undistorted
// height; only if the map is invertible (returned).
bool write_distortion_map(const ImagingModel& model, const ExportOptions& options,
                          const SensorGeometry& geo, const fs::path& dir, ExportSummary& summary) {
  auto wrote = [&](const fs::path& p) { summary.files.push_back(p); };
  FloatImage distortion(options.width, options.height, 3, 0.0f);
  const bool invertible = [&] {
    try {
      undistorted_radius_mm(model, 0.0);
      return true;
    } catch (const Error&) {
      return false;
    }
  }();
  if (invertible) {
    for (int j = 0; j < options.height; ++j)
      for (int i = 0; i < options.width; ++i) {
        const double dx = i + 0.5 - geo.axis_x, dy = j + 0.5 - geo.axis_y;
        const double r_out = geo.radius_mm(i, j);
        const double r_in = undistorted_radius_mm(model, r_out);
        const double scale = r_out > 1e-12 ? r_in / r_out : 1.0;
        distortion.at(i, j, 0) = static_cast<float>(dx * scale - dx);
        distortion.at(i, j, 1) = static_cast<float>(dy * scale - dy);
        distortion.at(i, j, 2) = static_cast<float>(distortion_at(model, r_in));
      }
    write_float_image(dir / "distortion.exr", distortion, {"dx", "dy", "D"});
    wrote(dir / "distortion.exr");
  }
  return invertible;
}

// relative_illumination.exr: the Renderer's factor R(r) per pixel.
void write_relative_illumination(const ImagingModel& model, const ExportOptions& options,
                                 const fs::path& dir, ExportSummary& summary) {
  RenderOptions ro;
  ro.res_factor = options.res_factor;
  const Renderer renderer(model, ro);
  FloatImage ri(options.width, options.height, 1, 1.0f);
  renderer.apply_relative_illumination(ri);
  write_float_image(dir / "relative_illumination.exr", ri);
  summary.files.push_back(dir / "relative_illumination.exr");
}

// fields.json: the per-field values, the PSF sampling and the grid's layout.
void write_fields_json(const ImagingModel& model, const ExportOptions& options, const PsfGrid& grid,
                       bool invertible, const DiffractionPsfs* diffraction, const fs::path& dir,
                       ExportSummary& summary) {
  const PsfOptions& popt = model.psfs.options;
  const int g = popt.grid_size;
  const int field_count = static_cast<int>(model.fields_deg.size());
  const int n = PsfGrid::kPatches;
  const int k = 2 * grid.max_radius + 1;
  const SensorGeometry& geo = grid.geometry;
  using nlohmann::json;
  json fields = json::array();
  for (int h = 0; h < field_count; ++h) {
    const FieldPsf<double>& f = model.psfs.fields[h];
    fields.push_back(
        {{"field_deg", model.fields_deg[h]},
         {"reference_y_mm", model.reference_y_mm[h]},
         {"centroid_y_mm", model.centroid_y_mm[h]},
         {"distortion_shift", model.distortion[h]},
         {"distortion_percent", 100.0 * model.distortion[h]},
         {"relative_illumination", model.relative_illumination[h]},
         {"energy_share_rgb", {f.energy_share[0], f.energy_share[1], f.energy_share[2]}},
         {"traced_rays_rgb", {f.traced_rays[0], f.traced_rays[1], f.traced_rays[2]}},
         {"failed_rays", f.failed_rays},
         {"psf", fmt::format("psf/field_{:02d}.exr", h)}});
    if (diffraction) {
      const FieldPsf<double>& d = diffraction->psfs.fields[h];
      json& o = fields.back();
      o["psf_diffraction"] = fmt::format("psf/field_{:02d}_diffraction.exr", h);
      o["strehl"] = diffraction->strehl[h];
      o["diffraction_energy_share_rgb"] = {d.energy_share[0], d.energy_share[1], d.energy_share[2]};
    }
  }
  json patches = json::array();
  for (int q = 0; q < n * n; ++q) {
    json weights = json::object();
    for (int h = 0; h < field_count; ++h)
      if (grid.field_weights[q][h] > 0) weights[fmt::format("{}", h)] = grid.field_weights[q][h];
    patches.push_back(
        {{"column", q % n},
         {"row", q / n},
         {"x", {grid.bounds_x[q % n], grid.bounds_x[q % n + 1]}},
         {"y", {grid.bounds_y[q / n], grid.bounds_y[q / n + 1]}},
         {"azimuth_deg", grid.azimuth_rad[q] * 180.0 / kPi},
         {"field_weights", weights},
         {"kernel_radius_rgb",
          {grid.kernels[q][0].radius, grid.kernels[q][1].radius, grid.kernels[q][2].radius}}});
  }
  const json j = {{"lens", model.lens_name},
                  {"sensor_diagonal_mm", model.sensor_diagonal_mm},
                  {"psf",
                   {{"grid_size", g},
                    {"bin_um", popt.bin_um},
                    {"sigma_um", popt.sigma_um()},
                    {"rings", model.trace.rings},
                    {"rays_per_field_wavelength", 2 * model.trace.rings * model.trace.rings}}},
                  {"fields", fields},
                  {"image",
                   {{"width", options.width},
                    {"height", options.height},
                    {"res_factor", options.res_factor},
                    {"pitch_um", summary.pitch_um},
                    {"axis_px", {geo.axis_x, geo.axis_y}},
                    {"psf_grid_tile_px", k},
                    {"distortion_invertible", invertible}}},
                  {"patches", patches}};
  write_file_atomic(dir / "fields.json",
                    j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
  summary.files.push_back(dir / "fields.json");
}

}  // namespace

void ExportOptions::validate() const {
  if (output_dir.empty()) throw Error("export: no output directory given (-o DIR)");
  if (width < 18 || height < 18 || width > 65536 || height > 65536)
    throw Error(
        fmt::format("image size {}x{} must be within 18..65536 in each direction", width, height));
  if (res_factor != 1 && res_factor != 2)
    throw Error(fmt::format("resolution factor {} must be 1 or 2", res_factor));
}

ExportSummary export_imaging_model(const ImagingModel& model, const ExportOptions& options,
                                   const DiffractionPsfs* diffraction) {
  options.validate();
  require_relative_illumination(model);  // written below; checked before any file
  ExportSummary summary;
  const fs::path& dir = options.output_dir;
  std::error_code ec;
  fs::create_directories(dir / "psf", ec);
  if (ec) {
    throw Error(SourceLocation{dir.string()},
                fmt::format("cannot create the output directory: {}", ec.message()));
  }
  write_field_psfs(model, model.psfs, "", dir, summary);
  if (diffraction) write_field_psfs(model, diffraction->psfs, "_diffraction", dir, summary);
  const PsfGrid grid = make_psf_grid(model, options.width, options.height, options.res_factor);
  write_psf_grid(grid, dir, summary);
  const bool invertible = write_distortion_map(model, options, grid.geometry, dir, summary);
  write_relative_illumination(model, options, dir, summary);
  write_fields_json(model, options, grid, invertible, diffraction, dir, summary);
  return summary;
}

}  // namespace lensopt
