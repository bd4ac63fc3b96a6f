// Analysis in Python: analyze (the CLI's report and JSON), ray tracing with numpy arrays, spots,
// PSFs and the per-field distortion / relative-illumination data.
#include <limits>
#include <optional>
#include <vector>

#include "bindings.h"
#include "lensopt/analysis/afocal.h"
#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/chromatic.h"
#include "lensopt/analysis/encircled_energy.h"
#include "lensopt/analysis/field_optics.h"
#include "lensopt/analysis/field_sweep.h"
#include "lensopt/analysis/forms_image.h"
#include "lensopt/analysis/seidel.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/analysis/zernike.h"
#include "lensopt/core/error.h"
#include "lensopt/render/psf.h"

namespace lensopt::python {
namespace {

// The lens with an optional dispersion override, traced and prepared in its own spec mode, as
// the CLI prepares it (prepare_lens_system); a half field given (trace_pupil) traces the paper's
// mode with that field.
TraceSystem<double> system_of(const Lens& lens_in, const TraceOptions& options,
                              const std::string& dispersion, double half_field_deg = -1) {
  Lens lens = lens_in;
  if (dispersion == "abbe")
    lens.specs.dispersion = DispersionModel::kAbbe;
  else if (dispersion == "catalog")
    lens.specs.dispersion = DispersionModel::kCatalog;
  else if (!dispersion.empty())
    throw Error("dispersion must be 'abbe' or 'catalog', not '" + dispersion + "'");
  lens.validate();
  if (half_field_deg < 0) return prepare_lens_system(lens, options);
  return prepare_system(make_trace_lens(lens), lens.specs.focal_length_mm(), lens.specs.f_number,
                        half_field_deg, options);
}

// Wavelength index of the system: -1 the reference (587.6 nm), else 0..W-1.
int wavelength_index(const TraceSystem<double>& sys, int w) {
  const int count = static_cast<int>(sys.lens.wavelengths_nm.size());
  if (w < 0) w += count;
  if (w < 0 || w >= count)
    throw Error("wavelength index " + std::to_string(w) + " out of range (the lens has " +
                std::to_string(count - 1) + " wavelengths and the reference)");
  return w;
}

py::dict traced_arrays(RayBundle<double>& rays) {
  const std::size_t n = rays.size();
  std::vector<double> pos(n * 3), dir(n * 3);
  for (std::size_t i = 0; i < n; ++i) {
    pos[3 * i] = rays.x[i];
    pos[3 * i + 1] = rays.y[i];
    pos[3 * i + 2] = rays.z[i];
    dir[3 * i] = rays.l[i];
    dir[3 * i + 1] = rays.m[i];
    dir[3 * i + 2] = rays.n[i];
  }
  std::vector<std::uint8_t> status(rays.status.begin(), rays.status.end());
  std::vector<std::int32_t> surface(rays.failed_surface.begin(), rays.failed_surface.end());
  py::dict d;
  const auto rows = static_cast<py::ssize_t>(n);
  d["positions"] = to_numpy(std::move(pos), {rows, 3});
  d["directions"] = to_numpy(std::move(dir), {rows, 3});
  d["status"] = to_numpy(std::move(status), {rows});
  d["failed_surface"] = to_numpy(std::move(surface), {rows});
  return d;
}

// A lens as `lensopt analyze` would trace it with --mode and --dispersion.
// `what` names the function for the refusal of an afocal lens (each of these measures an image
// plane).
Lens report_lens(const Lens& lens_in, const std::string& mode, const std::string& dispersion,
                 std::string_view what) {
  refuse_afocal(lens_in, what);
  Lens lens = lens_in;
  if (mode == "paper")
    lens.specs.mode = SpecMode::kPaper;
  else if (mode == "as-written")
    lens.specs.mode = SpecMode::kAsWritten;
  else if (!mode.empty())
    throw Error("mode must be 'paper' or 'as-written', not '" + mode + "'");
  if (dispersion == "abbe")
    lens.specs.dispersion = DispersionModel::kAbbe;
  else if (dispersion == "catalog")
    lens.specs.dispersion = DispersionModel::kCatalog;
  else if (!dispersion.empty())
    throw Error("dispersion must be 'abbe' or 'catalog', not '" + dispersion + "'");
  lens.validate();
  return lens;
}

}  // namespace

void bind_analysis(py::module_& m) {
  py::class_<FieldReport>(m, "FieldReport", "One field of an analysis.")
      .def_readonly("field_deg", &FieldReport::field_deg)
      .def_readonly("rms_spot_um", &FieldReport::rms_spot_um, "None if no ray reached the image")
      .def_readonly("centroid_y_mm", &FieldReport::centroid_y_mm)
      .def_readonly("reference_y_mm", &FieldReport::reference_y_mm)
      .def_readonly("distortion_percent", &FieldReport::distortion_percent)
      .def_readonly("relative_illumination", &FieldReport::relative_illumination,
                    "None if an edge ray of the field or of the axis fails")
      .def_readonly("traced_rays", &FieldReport::traced_rays)
      .def_readonly("failed_rays", &FieldReport::failed_rays)
      .def_readonly("aiming_error", &FieldReport::aiming_error);

  py::class_<AnalysisReport>(
      m, "AnalysisReport",
      "The result of analyze(): first-order data and per-field spots, distortion, relative "
      "illumination and failures. to_json() is the text `lensopt analyze --json` prints (the same "
      "serializer); to_dict() parses it.")
      .def_readonly("lens_name", &AnalysisReport::lens_name)
      .def_readonly("source_path", &AnalysisReport::source_path)
      .def_readonly("scale", &AnalysisReport::scale)
      .def_readonly("efl_mm", &AnalysisReport::efl_mm)
      .def_readonly("bfl_mm", &AnalysisReport::bfl_mm)
      .def_readonly("f_number", &AnalysisReport::f_number)
      .def_readonly("epd_mm", &AnalysisReport::epd_mm)
      .def_readonly("entrance_pupil_z_mm", &AnalysisReport::entrance_pupil_z_mm)
      .def_readonly("stop_radius_mm", &AnalysisReport::stop_radius_mm)
      .def_readonly("total_track_mm", &AnalysisReport::total_track_mm)
      .def_readonly("rings", &AnalysisReport::rings)
      .def_readonly("rays_per_field_wavelength", &AnalysisReport::rays_per_field_wavelength)
      .def_readonly("wavelength_count", &AnalysisReport::wavelength_count)
      .def_readonly("ray_aiming", &AnalysisReport::ray_aiming)
      .def_readonly("dispersion", &AnalysisReport::dispersion)
      .def_readonly("fields", &AnalysisReport::fields)
      .def_readonly("mean_rms_spot_um", &AnalysisReport::mean_rms_spot_um)
      .def_readonly("ray_failures", &AnalysisReport::ray_failures)
      .def_readonly("failures_by_surface", &AnalysisReport::failures_by_surface)
      .def_readonly("max_aiming_error", &AnalysisReport::max_aiming_error)
      .def_readonly("image_distance_mm", &AnalysisReport::image_distance_mm,
                    "last vertex to the image plane (negative: a virtual image plane)")
      .def_readonly("virtual_image", &AnalysisReport::virtual_image,
                    "the paraxial image lies before the last vertex (BFL < 0)")
      .def_readonly("angular_magnification", &AnalysisReport::angular_magnification,
                    "paraxial chief-ray angle in image space over that in object space")
      .def_readonly("object_distance_mm", &AnalysisReport::object_distance_mm, "0: at infinity")
      .def_readonly("primary_wavelength_nm", &AnalysisReport::primary_wavelength_nm)
      .def_property_readonly(
          "wave",
          [](const AnalysisReport& r) -> py::object {
            if (!r.wave) return py::none();
            return py::module_::import("json").attr("loads")(format_wave_json(*r.wave));
          },
          "With analyze(wave=True) (or zernike_terms > 0): the wave section of `lensopt analyze "
          "--wave --json` as a dict (sampling, per field the RMS wavefront, Strehl ratio, MTFs "
          "and per wavelength the Zernike fit); else None.")
      .def_property_readonly(
          "zernike_waves",
          [](const AnalysisReport& r) -> py::object {
            if (!r.wave || r.wave->zernike_terms <= 0) return py::none();
            const WaveReport& w = *r.wave;
            const auto f = static_cast<py::ssize_t>(w.fields.size());
            const auto wl = static_cast<py::ssize_t>(w.wavelengths_nm.size());
            const auto n = static_cast<py::ssize_t>(w.zernike_terms);
            std::vector<double> c(static_cast<std::size_t>(f * wl * n),
                                  std::numeric_limits<double>::quiet_NaN());
            for (py::ssize_t h = 0; h < f; ++h)
              for (py::ssize_t k = 0;
                   k < wl && k < static_cast<py::ssize_t>(w.fields[h].mono.size()); ++k) {
                const std::vector<double>& z = w.fields[h].mono[k].zernike_waves;
                for (py::ssize_t j = 0; j < n && j < static_cast<py::ssize_t>(z.size()); ++j)
                  c[static_cast<std::size_t>((h * wl + k) * n + j)] = z[j];
              }
            return to_numpy(std::move(c), {f, wl, n});
          },
          "With a Zernike fit (analyze(zernike_terms=J)): the coefficients in waves, "
          "[field, wavelength, term] (term 0 = Z1 of the ordering; NaN where a wavefront could "
          "not be fitted); else None.")
      .def("to_json", &format_report_json, "The JSON text of `lensopt analyze --json`.")
      .def("to_text", &format_report_text, "The table `lensopt analyze` prints.")
      .def("to_dict",
           [](const AnalysisReport& r) {
             return py::module_::import("json").attr("loads")(format_report_json(r));
           })
      .def("__str__", &format_report_text);

  py::class_<AfocalFirstOrder>(m, "AfocalFirstOrder",
                               "The paraxial first-order data of an afocal lens "
                               "(analysis/afocal.h).")
      .def_readonly("angular_magnification", &AfocalFirstOrder::angular_magnification,
                    "M = u'_c / u_c of the paraxial chief ray")
      .def_readonly("entrance_pupil_diameter_mm", &AfocalFirstOrder::entrance_pupil_diameter_mm)
      .def_readonly("entrance_pupil_z_mm", &AfocalFirstOrder::entrance_pupil_z_mm,
                    "from the first vertex")
      .def_readonly("exit_pupil_diameter_mm", &AfocalFirstOrder::exit_pupil_diameter_mm)
      .def_readonly("exit_pupil_z_mm", &AfocalFirstOrder::exit_pupil_z_mm,
                    "from the last vertex (positive: after it)")
      .def_readonly("residual_power_diopters", &AfocalFirstOrder::residual_power_diopters,
                    "1000 / EFL (0: exactly afocal)")
      .def_readonly("marginal_output_slope", &AfocalFirstOrder::marginal_output_slope)
      .def_readonly("image_space_index", &AfocalFirstOrder::image_space_index);

  py::class_<AfocalField>(m, "AfocalField", "One field of an afocal analysis.")
      .def_readonly("field_deg", &AfocalField::field_deg)
      .def_readonly("field_value", &AfocalField::field_value)
      .def_readonly("weight", &AfocalField::weight)
      .def_readonly("traced_rays", &AfocalField::traced_rays)
      .def_readonly("failed_rays", &AfocalField::failed_rays)
      .def_readonly("vignetted_rays", &AfocalField::vignetted_rays)
      .def_readonly("chief_ok", &AfocalField::chief_ok)
      .def_readonly("output_chief_angle_deg", &AfocalField::output_chief_angle_deg)
      .def_readonly("paraxial_output_angle_deg", &AfocalField::paraxial_output_angle_deg)
      .def_readonly("angular_distortion_percent", &AfocalField::angular_distortion_percent)
      .def_readonly("rms_angular_spot_mrad", &AfocalField::rms_angular_spot_mrad,
                    "None if no ray arrived")
      .def_readonly("rms_wavefront_waves", &AfocalField::rms_wavefront_waves)
      .def_readonly("pv_wavefront_waves", &AfocalField::pv_wavefront_waves)
      .def_readonly("strehl", &AfocalField::strehl)
      .def_readonly("zernike_waves", &AfocalField::zernike_waves);

  py::class_<AfocalReport>(
      m, "AfocalReport",
      "What analyze() returns for an afocal lens (image space in angle, analysis/afocal.h): "
      "angular magnification, pupils, per field the output chief-ray angle, angular distortion, "
      "RMS angular spot and plane-wave wavefront. to_json() is the text `lensopt analyze --json` "
      "prints for the lens (the same serializer); to_dict() parses it.")
      .def_readonly("lens_name", &AfocalReport::lens_name)
      .def_readonly("source_path", &AfocalReport::source_path)
      .def_readonly("first_order", &AfocalReport::first_order)
      .def_property_readonly(
          "angular_magnification",
          [](const AfocalReport& r) { return r.first_order.angular_magnification; })
      .def_readonly("fields", &AfocalReport::fields)
      .def_readonly("mean_rms_angular_spot_mrad", &AfocalReport::mean_rms_angular_spot_mrad,
                    "field-weighted; None if a field has no ray")
      .def_readonly("object_distance_mm", &AfocalReport::object_distance_mm, "0: at infinity")
      .def_readonly("primary_wavelength_nm", &AfocalReport::primary_wavelength_nm)
      .def_readonly("wavelength_count", &AfocalReport::wavelength_count)
      .def_readonly("rays_per_field_wavelength", &AfocalReport::rays_per_field_wavelength)
      .def_readonly("rings", &AfocalReport::rings)
      .def_readonly("ray_failures", &AfocalReport::ray_failures)
      .def_readonly("vignetted_rays", &AfocalReport::vignetted_rays)
      .def("to_json", &format_afocal_json, "The JSON text of `lensopt analyze --json`.")
      .def("to_text", &format_afocal_text, "The table `lensopt analyze` prints.")
      .def("to_dict",
           [](const AfocalReport& r) {
             return py::module_::import("json").attr("loads")(format_afocal_json(r));
           })
      .def("__str__", &format_afocal_text);

  m.def(
      "analyze",
      [](const Lens& lens_in, std::optional<int> rings, std::optional<int> fields, bool ray_aiming,
         bool scale_to_spec, const std::string& dispersion, std::optional<int> threads, bool wave,
         std::optional<std::vector<double>> mtf_frequencies, std::optional<int> pupil_samples,
         const std::vector<double>& wavelength_weights, int zernike_terms,
         const std::string& zernike_order, const std::string& mode) {
        // `lensopt analyze`'s options: AnalyzeOptions' defaults (the CLI's), then the arguments
        // given (None: not given).
        AnalyzeOptions o;
        if (rings) o.trace.rings = *rings;
        if (fields) o.trace.fields = *fields;
        if (threads) o.trace.threads = *threads;
        o.trace.ray_aiming = ray_aiming;
        o.trace.scale_to_spec = scale_to_spec;
        o.trace.validate();
        o.wave = wave || zernike_terms > 0;
        if (mtf_frequencies) o.mtf_frequencies_cyc_mm = *mtf_frequencies;
        if (pupil_samples) o.wave_options.pupil_samples = *pupil_samples;
        o.wave_options.wavelength_weights = wavelength_weights;
        o.wave_options.zernike_terms = zernike_terms;
        o.wave_options.zernike_ordering = parse_zernike_ordering(zernike_order);
        o.wave_options.threads = o.trace.threads;
        if (dispersion == "abbe")
          o.dispersion = DispersionModel::kAbbe;
        else if (dispersion == "catalog")
          o.dispersion = DispersionModel::kCatalog;
        else if (!dispersion.empty())
          throw Error("dispersion must be 'abbe' or 'catalog', not '" + dispersion + "'");
        Lens lens = lens_in;
        if (mode == "paper")
          lens.specs.mode = SpecMode::kPaper;
        else if (mode == "as-written")
          lens.specs.mode = SpecMode::kAsWritten;
        else if (!mode.empty())
          throw Error("mode must be 'paper' or 'as-written', not '" + mode + "'");
        if (lens.specs.afocal) {
          // As `lensopt analyze` (cmd_analyze.cpp run_afocal): measured in angle, with the
          // plane-wave wavefront; an image-plane MTF does not exist for it.
          if (mtf_frequencies)
            throw Error(SourceLocation{lens.source_path.empty() ? lens.name : lens.source_path},
                        "mtf_frequencies does not apply to an afocal lens (image space in angle: "
                        "no image-plane MTF); analyze reports its plane-wave wavefront and "
                        "Strehl ratio");
          AfocalReport report;
          {
            py::gil_scoped_release release;
            report = analyze_afocal_lens(lens, o);  // the CLI's call (cmd_analyze.cpp)
          }
          return py::cast(std::move(report));
        }
        AnalysisReport report;
        {
          py::gil_scoped_release release;
          report = analyze_lens(lens, o);
        }
        // As the CLI: a lens that forms no image is an error, not a report of nulls.
        check_forms_image(report);
        return py::cast(std::move(report));
      },
      py::arg("lens"), py::kw_only(), py::arg("rings") = py::none(), py::arg("fields") = py::none(),
      py::arg("ray_aiming") = true, py::arg("scale_to_spec") = true, py::arg("dispersion") = "",
      py::arg("threads") = py::none(), py::arg("wave") = false,
      py::arg("mtf_frequencies") = py::none(), py::arg("pupil_samples") = py::none(),
      py::arg("wavelength_weights") = std::vector<double>{}, py::arg("zernike_terms") = 0,
      py::arg("zernike_order") = "fringe", py::arg("mode") = "",
      "`lensopt analyze`: EFL, BFL, pupil, RMS spot per field, distortion, relative illumination, "
      "ray failures and ray-aiming error, with the CLI's defaults (AnalyzeOptions: 32 rings, 21 "
      "fields, 128 pupil samples, MTF at 10, 30, 50 cycles/mm); None keeps a default. mode "
      "(`--mode`): 'paper' or 'as-written' overrides the lens's spec mode. wave=True "
      "(`--wave`) adds the wave optics (AnalysisReport.wave): RMS wavefront, Strehl ratio and "
      "diffraction and geometric MTF at mtf_frequencies (cycles/mm, `--mtf-freqs`) on a "
      "pupil_samples grid (`--pupil-samples`), wavelengths weighted by wavelength_weights (one "
      "per spec wavelength; empty: the lens's own, else equal). zernike_terms = J > 0 "
      "(`--zernike`, implies wave) fits each wavefront with J Zernike terms in zernike_order "
      "'fringe' (unnormalized, J <= 37) or 'standard' (Noll, unit RMS) "
      "(AnalysisReport.zernike_waves). An afocal lens (its image at infinity: [system] afocal = "
      "true, a .zmx afocal flag) returns an AfocalReport, measured in angle as `lensopt "
      "analyze` measures it; a lens that forms no image raises LensoptError.");

  m.def(
      "trace_rays",
      [](const Lens& lens, py::array_t<double, py::array::c_style | py::array::forcecast> positions,
         py::array_t<double, py::array::c_style | py::array::forcecast> directions, int wavelength,
         bool scale_to_spec, const std::string& dispersion) {
        if (positions.ndim() != 2 || positions.shape(1) != 3 || directions.ndim() != 2 ||
            directions.shape(1) != 3 || directions.shape(0) != positions.shape(0))
          throw Error("positions and directions must be N x 3 arrays of the same N");
        TraceOptions o;
        o.ray_aiming = false;
        o.fields = 1;
        o.rings = 1;
        o.scale_to_spec = scale_to_spec;
        const TraceSystem<double> sys = system_of(lens, o, dispersion);
        const int w = wavelength_index(sys, wavelength);
        RayBundle<double> rays;
        const auto n = static_cast<std::size_t>(positions.shape(0));
        rays.resize(n);
        auto p = positions.unchecked<2>();
        auto d = directions.unchecked<2>();
        for (std::size_t i = 0; i < n; ++i) {
          const auto k = static_cast<py::ssize_t>(i);
          rays.x[i] = p(k, 0);
          rays.y[i] = p(k, 1);
          rays.z[i] = p(k, 2);
          const double norm = std::sqrt(d(k, 0) * d(k, 0) + d(k, 1) * d(k, 1) + d(k, 2) * d(k, 2));
          rays.l[i] = d(k, 0) / norm;
          rays.m[i] = d(k, 1) / norm;
          rays.n[i] = d(k, 2) / norm;
        }
        {
          py::gil_scoped_release release;
          trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                       static_cast<RayRecord<double>*>(nullptr));
        }
        return traced_arrays(rays);
      },
      py::arg("lens"), py::arg("positions"), py::arg("directions"), py::kw_only(),
      py::arg("wavelength") = -1, py::arg("scale_to_spec") = true, py::arg("dispersion") = "",
      "Traces rays through the lens to the image plane. positions (N x 3, mm, relative to the "
      "first vertex; z < 0 is in front of it) and directions (N x 3, normalized here) are the "
      "rays in object space; wavelength indexes Specs.wavelengths_nm (-1: 587.6 nm). Returns a "
      "dict of numpy arrays: positions (N x 3, on the image plane, z = 0), directions (N x 3), "
      "status (N, uint8: 0 ok, 1 missed a surface, 2 total internal reflection, 3 backwards) and "
      "failed_surface (N, -1: none). With scale_to_spec the lens is first scaled to the spec "
      "focal length (as analyze).");

  m.def(
      "trace_pupil",
      [](const Lens& lens, double field_deg,
         py::array_t<double, py::array::c_style | py::array::forcecast> pupil, int wavelength,
         bool ray_aiming, bool scale_to_spec, const std::string& dispersion) {
        if (pupil.ndim() != 2 || pupil.shape(1) != 2)
          throw Error("pupil must be an N x 2 array of normalized pupil coordinates");
        if (!(field_deg >= 0) || field_deg > 89) throw Error("field_deg must be in [0, 89]");
        TraceOptions o;
        o.rings = 1;
        o.fields = 2;  // fields 0 and field_deg: the pupil map of index 1
        o.ray_aiming = ray_aiming;
        o.scale_to_spec = scale_to_spec;
        const TraceSystem<double> sys = system_of(lens, o, dispersion, field_deg);
        const int w = wavelength_index(sys, wavelength);
        PupilSamples samples;
        auto p = pupil.unchecked<2>();
        for (py::ssize_t i = 0; i < pupil.shape(0); ++i) {
          samples.x.push_back(p(i, 0));
          samples.y.push_back(p(i, 1));
        }
        RayBundle<double> rays;
        {
          py::gil_scoped_release release;
          start_rays(sys, 1, w, rays, &samples);
          trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                       static_cast<RayRecord<double>*>(nullptr));
        }
        return traced_arrays(rays);
      },
      py::arg("lens"), py::arg("field_deg"), py::arg("pupil"), py::kw_only(),
      py::arg("wavelength") = -1, py::arg("ray_aiming") = true, py::arg("scale_to_spec") = true,
      py::arg("dispersion") = "",
      "Traces rays of one field angle (deg, in the y-z plane) through normalized entrance-pupil "
      "coordinates (N x 2, x and y in [-1, 1]) under the aimed pupil, to the image plane. "
      "Returns the dict of trace_rays.");

  m.def(
      "spots",
      [](const Lens& lens, int rings, int fields, bool ray_aiming, bool scale_to_spec,
         const std::string& dispersion, int threads) {
        refuse_afocal(lens, "lensopt.spots");
        const TraceOptions o = trace_options(rings, fields, ray_aiming, scale_to_spec, threads);
        const TraceSystem<double> sys = system_of(lens, o, dispersion);
        SpotResult<double> s;
        {
          py::gil_scoped_release release;
          s = evaluate_spots(sys, threads);
        }
        py::dict d;
        // None for a field no ray reaches (and then for the mean), as `lensopt analyze --json`
        // writes null: a spot of 0 would be a number the lens does not have.
        py::list um;
        bool all_traced = true;
        for (std::size_t h = 0; h < s.rms_spot_mm.size(); ++h) {
          if (s.traced_rays[h] > 0) {
            um.append(s.rms_spot_mm[h] * 1000.0);
          } else {
            um.append(py::none());
            all_traced = false;
          }
        }
        d["field_values"] = sys.field_values;
        d["fields_deg"] = sys.fields_deg;
        d["rms_spot_um"] = um;
        if (all_traced)
          d["mean_rms_spot_um"] = s.mean_rms_spot_mm * 1000.0;
        else
          d["mean_rms_spot_um"] = py::none();
        d["centroid_y_mm"] = s.centroid_y_mm;
        d["traced_rays"] = s.traced_rays;
        d["failed_rays"] = s.failed_rays;
        return d;
      },
      py::arg("lens"), py::kw_only(), py::arg("rings") = 32, py::arg("fields") = 21,
      py::arg("ray_aiming") = true, py::arg("scale_to_spec") = true, py::arg("dispersion") = "",
      py::arg("threads") = 0,
      "RMS spot radius per field (um), centroids, traced and failed rays (a dict).");

  m.def(
      "psfs",
      [](const Lens& lens, int rings, int fields, int grid_size, double bin_um, double sigma_bins,
         int support_bins, bool ray_aiming, int threads) {
        refuse_afocal(lens, "lensopt.psfs");
        const TraceOptions o = trace_options(rings, fields, ray_aiming, true, threads);
        PsfOptions po;
        po.grid_size = grid_size;
        po.bin_um = bin_um;
        po.sigma_bins = sigma_bins;
        po.support_bins = support_bins;
        po.validate();
        const TraceSystem<double> sys = system_of(lens, o, "");
        PsfSet<double> set;
        {
          py::gil_scoped_release release;
          set = compute_psfs(sys, lens.specs.wavelength_channels, po, threads);
        }
        const int f = static_cast<int>(set.fields.size());
        const std::size_t cells = static_cast<std::size_t>(grid_size) * grid_size;
        std::vector<double> grid(static_cast<std::size_t>(f) * kColourChannels * cells);
        std::vector<double> centroid;
        for (int h = 0; h < f; ++h) {
          for (int c = 0; c < kColourChannels; ++c)
            std::copy(set.fields[h].psf[c].begin(), set.fields[h].psf[c].end(),
                      grid.begin() + (static_cast<std::size_t>(h) * kColourChannels + c) * cells);
          centroid.push_back(set.fields[h].centroid_y_mm);
        }
        py::dict d;
        d["fields_deg"] = set.fields_deg;
        d["centroid_y_mm"] = centroid;
        d["psf"] = to_numpy(std::move(grid), {f, kColourChannels, grid_size, grid_size});
        d["bin_um"] = bin_um;
        return d;
      },
      py::arg("lens"), py::kw_only(), py::arg("rings") = 32, py::arg("fields") = 21,
      py::arg("grid_size") = 65, py::arg("bin_um") = 4.0, py::arg("sigma_bins") = 0.5,
      py::arg("support_bins") = 2, py::arg("ray_aiming") = true, py::arg("threads") = 0,
      "The geometric PSFs the renderer uses: psf[field, channel (R, G, B), row, column], a "
      "grid_size^2 grid of bin_um bins centred on each field's centroid (rows along -y), each "
      "channel summing to 1; with fields_deg and centroid_y_mm.");

  m.def(
      "field_data",
      [](const Lens& lens, int rings, int fields, bool ray_aiming, int threads) {
        refuse_afocal(lens, "lensopt.field_data");
        const TraceOptions o = trace_options(rings, fields, ray_aiming, true, threads);
        const TraceSystem<double> sys = system_of(lens, o, "");
        FieldOpticsOptions fo;
        fo.threads = threads;
        FieldOptics<double> f;
        {
          py::gil_scoped_release release;
          f = measure_fields(sys, fo);
        }
        // The relative illumination where it is known, None where an edge ray fails (as
        // `lensopt analyze --json` writes null there).
        py::list ri;
        for (std::size_t h = 0; h < f.size(); ++h) {
          if (f.relative_illumination_known[h])
            ri.append(f.relative_illumination[h]);
          else
            ri.append(py::none());
        }
        py::dict d;
        d["fields_deg"] = f.fields_deg;
        d["field_values"] = f.field_values;
        d["reference_y_mm"] = f.reference_y_mm;
        d["centroid_y_mm"] = f.spots.centroid_y_mm;
        d["distortion"] = f.distortion;
        d["relative_illumination"] = ri;
        return d;
      },
      py::arg("lens"), py::kw_only(), py::arg("rings") = 32, py::arg("fields") = 21,
      py::arg("ray_aiming") = true, py::arg("threads") = 0,
      "Per field: paraxial chief-ray height y_ref, polychromatic centroid ybar, distortion "
      "D = (ybar - y_ref) / y_ref,last (a fraction) and relative illumination (a dict).");

  // The designer's reports (analysis/seidel.h, chromatic.h, encircled_energy.h, field_sweep.h):
  // each returns the JSON object `lensopt analyze` writes for it, as a dict.
  auto json_loads = [](const std::string& text) {
    return py::module_::import("json").attr("loads")(text);
  };
  m.def(
      "prescription",
      [json_loads](const Lens& lens_in, const std::string& mode, const std::string& dispersion) {
        const Lens lens = report_lens(lens_in, mode, dispersion, "lensopt.prescription");
        std::string text;
        {
          py::gil_scoped_release release;
          const TraceSystem<double> sys = prepare_lens_system(lens, TraceOptions{});
          text = format_prescription_json(lens, sys, seidel_report(sys));
        }
        return json_loads(text);
      },
      py::arg("lens"), py::kw_only(), py::arg("mode") = "", py::arg("dispersion") = "",
      "`lensopt analyze --prescription`'s \"prescription\": the surface table, first-order data "
      "and Seidel sums per surface with primary colour (dict).");
  m.def(
      "chromatic_focal_shift",
      [json_loads](const Lens& lens_in, std::optional<std::vector<double>> band, int samples,
                   const std::string& mode, const std::string& dispersion) {
        const Lens lens = report_lens(lens_in, mode, dispersion, "lensopt.chromatic_focal_shift");
        if (band && band->size() != 2) throw Error("band must be (lo_nm, hi_nm)");
        std::string text;
        {
          py::gil_scoped_release release;
          const TraceSystem<double> sys = prepare_lens_system(lens, TraceOptions{});
          text = format_focal_shift_json(
              band ? chromatic_focal_shift(lens, sys, (*band)[0], (*band)[1], samples)
                   : chromatic_focal_shift(lens, sys));
        }
        return json_loads(text);
      },
      py::arg("lens"), py::kw_only(), py::arg("band") = py::none(), py::arg("samples") = 41,
      py::arg("mode") = "", py::arg("dispersion") = "",
      "Paraxial focus at each wavelength less the primary's (um, `shift_um`), at the spec "
      "wavelengths or `samples` wavelengths across band=(lo_nm, hi_nm), with the maximum range "
      "and the diffraction-limited depth 4 lambda N_w^2 (dict; analyze --prescription's "
      "\"chromatic_focal_shift\").");
  m.def(
      "lateral_colour",
      [json_loads](const Lens& lens_in, const std::string& mode, const std::string& dispersion) {
        const Lens lens = report_lens(lens_in, mode, dispersion, "lensopt.lateral_colour");
        std::string text;
        {
          py::gil_scoped_release release;
          text = format_lateral_colour_json(lateral_colour(prepare_lens_system(lens, {})));
        }
        return json_loads(text);
      },
      py::arg("lens"), py::kw_only(), py::arg("mode") = "", py::arg("dispersion") = "",
      "Real chief-ray image height per field and spec wavelength less the primary's, and short "
      "less long wavelength (um) (dict; analyze --prescription's \"lateral_colour\").");
  m.def(
      "encircled_energy",
      [json_loads](const Lens& lens_in, std::vector<int> fields, int radii, double max_radius_um,
                   bool diffraction, int pupil_samples, const std::string& mode,
                   const std::string& dispersion, std::optional<int> threads) {
        const Lens lens = report_lens(lens_in, mode, dispersion, "lensopt.encircled_energy");
        EncircledEnergyOptions o;
        o.field_indices = std::move(fields);
        o.radii = radii;
        o.max_radius_um = max_radius_um;
        o.diffraction = diffraction;
        o.wave.pupil_samples = pupil_samples;
        TraceOptions t;
        if (threads) t.threads = o.wave.threads = *threads;
        o.validate();
        std::string text;
        {
          py::gil_scoped_release release;
          const TraceSystem<double> sys = prepare_lens_system(lens, t);
          o.wave.wavelength_weights = lens_wavelength_weights(lens, sys.wavelength_count);
          text = format_encircled_energy_json(encircled_energy(sys, o));
        }
        return json_loads(text);
      },
      py::arg("lens"), py::kw_only(), py::arg("fields") = std::vector<int>{},
      py::arg("radii") = 101, py::arg("max_radius_um") = 0.0, py::arg("diffraction") = true,
      py::arg("pupil_samples") = 128, py::arg("mode") = "", py::arg("dispersion") = "",
      py::arg("threads") = py::none(),
      "Encircled energy about each field's centroid (fields: indices into analyze's fields; "
      "empty: all): `radius_um` and per field the `geometric` and `diffraction` curves with the "
      "radii holding 50/80/90 % (dict; analyze --encircled-energy's \"encircled_energy\").");
  m.def(
      "field_sweep",
      [json_loads](const Lens& lens_in, int fields, std::vector<double> frequencies, bool mtf,
                   int pupil_samples, const std::string& mode, const std::string& dispersion,
                   std::optional<int> threads) {
        const Lens lens = report_lens(lens_in, mode, dispersion, "lensopt.field_sweep");
        TraceOptions t;
        WaveOptions wave;
        wave.pupil_samples = pupil_samples;
        if (threads) t.threads = wave.threads = *threads;
        std::string text;
        {
          py::gil_scoped_release release;
          const TraceSystem<double> sys = prepare_lens_system(lens, t);
          wave.wavelength_weights = lens_wavelength_weights(lens, sys.wavelength_count);
          const TraceSystem<double> swept =
              fields > 0 ? field_sweep_system(lens, sys, t, fields) : sys;
          text = format_field_sweep_json(field_sweep(swept, wave, frequencies, mtf));
        }
        return json_loads(text);
      },
      py::arg("lens"), py::kw_only(), py::arg("fields") = 11,
      py::arg("frequencies") = std::vector<double>{10, 30, 50}, py::arg("mtf") = true,
      py::arg("pupil_samples") = 128, py::arg("mode") = "", py::arg("dispersion") = "",
      py::arg("threads") = py::none(),
      "RMS spot, distortion and the diffraction MTF (mtf_t, mtf_s: [frequency][field]) against "
      "field at `fields` angles from the axis to the largest field (the mtf-field plot's data; "
      "fields=0: analyze's own fields) (dict).");
}

}  // namespace lensopt::python
