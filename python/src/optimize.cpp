// Optimization in Python: the paper's lens variables (Parameterization), the design loss with
// its exact gradient, Levenberg-Marquardt optimization and Monte-Carlo tolerancing.
#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include "bindings.h"
#include "lensopt/analysis/afocal.h"
#include "lensopt/core/error.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/tolerance/tolerance.h"

namespace lensopt::python {
namespace {

using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

// The catalog given, else the one `lensopt optimize` takes glasses from (optimizer.h).
std::string group_catalog(const Lens& lens, const std::string& catalog) {
  if (!catalog.empty()) return catalog;
  return glass_catalog_for(lens);
}

// "spot" or "wavefront" (optimize --merit).
DesignMerit merit_of(const std::string& name) {
  return parse_merit(name, SourceLocation{"merit"});
}

}  // namespace

GlassMode parse_glass_mode(const std::string& s) {
  if (s == "quantized") return GlassMode::kQuantized;
  if (s == "continuous") return GlassMode::kContinuous;
  if (s == "fixed") return GlassMode::kFixed;
  throw Error("glass mode must be 'quantized', 'continuous' or 'fixed', not '" + s + "'");
}

std::vector<double> vector_of(const DoubleArray& x, int size) {
  if (x.ndim() != 1 || x.shape(0) != size)
    throw Error("expected " + std::to_string(size) + " lens variables, got an array of shape (" +
                std::to_string(x.ndim() ? x.shape(0) : 0) + (x.ndim() > 1 ? ", ...)" : ")"));
  return std::vector<double>(x.data(), x.data() + size);
}

void bind_optimize(py::module_& m) {
  py::class_<LensParameterization>(
      m, "Parameterization",
      "The paper's lens variables x of a lens structure: normalized curvatures c' = c f, "
      "spacings s' = t / f (the last one the defocus from the paraxial image), and whitened "
      "glass variables g (two per glass) of the catalog; the last curvature is solved for the "
      "focal length.")
      .def(py::init([](const Lens& lens, const std::string& catalog, bool paraxial_image_solve) {
             auto p = std::make_unique<LensParameterization>(
                 lens, GlassSpace(*load_catalog(group_catalog(lens, catalog))));
             p->set_paraxial_image_solve(paraxial_image_solve);
             return p;
           }),
           py::arg("lens"), py::kw_only(), py::arg("catalog") = "",
           py::arg("paraxial_image_solve") = true)
      .def_property_readonly("size", &LensParameterization::size)
      .def("__len__", &LensParameterization::size)
      .def_property_readonly(
          "names",
          [](const LensParameterization& p) {
            std::vector<std::string> out;
            for (const LensVariable& v : p.variables()) out.push_back(v.name);
            return out;
          },
          "'c1', 's3', 'defocus', 'g2.0', ... (1-based surfaces)")
      .def_property_readonly(
          "groups",
          [](const LensParameterization& p) {
            std::vector<std::string> out;
            for (const LensVariable& v : p.variables()) out.push_back(v.group);
            return out;
          },
          "'curvatures', 'spacings' or 'glasses' per variable")
      .def_property_readonly("focal_length_mm", &LensParameterization::focal_length_mm)
      .def(
          "from_lens",
          [](const LensParameterization& p, const Lens& lens) {
            std::vector<double> x = p.from_lens(lens);
            const auto n = static_cast<py::ssize_t>(x.size());
            return to_numpy(std::move(x), {n});
          },
          py::arg("lens"), "The variables of a lens of this structure (numpy float64).")
      .def(
          "to_lens",
          [](const LensParameterization& p, const DoubleArray& x, const std::string& mode) {
            const std::vector<double> v = vector_of(x, p.size());
            return p.to_lens(v.data(), parse_glass_mode(mode), p.nearest_glasses(v.data()));
          },
          py::arg("x"), py::arg("glass_mode") = "quantized",
          "The lens of variables x (catalog glasses when quantized, model glasses when "
          "continuous).")
      .def(
          "glasses",
          [](const LensParameterization& p, const DoubleArray& x) {
            const std::vector<double> v = vector_of(x, p.size());
            std::vector<std::string> out;
            for (int j : p.nearest_glasses(v.data())) out.push_back(p.glass_space().name(j));
            return out;
          },
          py::arg("x"), "The nearest catalog glass of each glass variable pair.")
      .def(
          "select",
          [](const LensParameterization& p, const std::vector<std::string>& names) {
            return p.select(names);
          },
          py::arg("names"), "Indices of the variables named (or of the groups named).")
      .def(
          "design_loss",
          [](const LensParameterization& p, const DoubleArray& x, std::optional<double> weight_spot,
             std::optional<double> weight_ray_path, std::optional<double> weight_ray_angle,
             std::optional<double> weight_glass, std::optional<int> rings,
             std::optional<int> fields, const std::string& mode, bool paper_penalties,
             bool gradient, const std::string& merit, std::optional<int> wavefront_pupil_samples) {
            const std::vector<double> v = vector_of(x, p.size());
            // Unset arguments keep the optimizer's defaults (OptimizeOptions, DesignLossOptions).
            const OptimizeOptions defaults;
            const TraceOptions sampling =
                trace_options(rings.value_or(defaults.sampling.rings),
                              fields.value_or(defaults.sampling.fields), true, false, 0);
            DesignLossOptions o;
            if (weight_spot) o.weight_spot = *weight_spot;
            if (weight_ray_path) o.weight_ray_path = *weight_ray_path;
            if (weight_ray_angle) o.weight_ray_angle = *weight_ray_angle;
            if (weight_glass) o.weight_glass = *weight_glass;
            o.paper_penalties = paper_penalties;
            o.merit = merit_of(merit);
            if (wavefront_pupil_samples) o.wavefront_pupil_samples = *wavefront_pupil_samples;
            o.validate();
            const GlassMode gm = parse_glass_mode(mode);
            const std::vector<int> fixed = p.nearest_glasses(v.data());
            DesignValueGradient r;
            {
              py::gil_scoped_release release;
              if (gradient) {
                r = design_loss_gradient(p, v, gm, fixed, sampling, o);
              } else {
                r.finite = evaluate_design<double>(p, v.data(), gm, fixed, sampling, o, nullptr,
                                                   nullptr, &r.loss);
              }
            }
            py::dict d;
            d["spot_mm"] = r.loss.spot_mm;
            d["ray_path_mm"] = r.loss.ray_path_mm;
            d["ray_angle"] = r.loss.ray_angle;
            d["glass"] = r.loss.glass;
            d["total"] = r.loss.total;
            d["field_rms_mm"] = r.loss.field_rms_mm;
            d["merit"] = merit;
            if (o.merit == DesignMerit::kWavefront) {
              d["wavefront_waves"] = r.loss.wavefront_waves;
              d["field_wavefront_waves"] = r.loss.field_wavefront_waves;
            }
            d["failed_rays"] = r.loss.failed_rays;
            d["finite"] = r.finite;
            if (gradient) {
              const auto n = static_cast<py::ssize_t>(r.gradient.size());
              d["gradient"] = to_numpy(std::move(r.gradient), {n});
            }
            return d;
          },
          py::arg("x"), py::kw_only(), py::arg("weight_spot") = py::none(),
          py::arg("weight_ray_path") = py::none(), py::arg("weight_ray_angle") = py::none(),
          py::arg("weight_glass") = py::none(), py::arg("rings") = py::none(),
          py::arg("fields") = py::none(), py::arg("glass_mode") = "quantized",
          py::arg("paper_penalties") = false, py::arg("gradient") = true, py::arg("merit") = "spot",
          py::arg("wavefront_pupil_samples") = py::none(),
          "The paper's l_lens = w_S l_S + w_RP l_RP + w_RA l_RA + w_GV l_GV at x (a dict of the "
          "terms: spot_mm, ray_path_mm, ray_angle, glass, total) and, with gradient, d total / dx "
          "exactly (forward-mode Jets). Weights must be >= 0; None keeps the optimizer's default "
          "(1, 100, 100, 0.01; rings 8, fields 11, wavefront_pupil_samples 8). merit='wavefront' "
          "(optimize "
          "--merit wavefront): l_S is replaced by the mean RMS wavefront (waves, piston and tilt "
          "removed) on a wavefront_pupil_samples grid across the pupil, given as wavefront_waves "
          "and field_wavefront_waves.");

  py::class_<OptimizeResult>(m, "OptimizeResult", "The result of optimize().")
      .def_readonly("lens", &OptimizeResult::lens)
      .def_readonly("start_spot_um", &OptimizeResult::start_spot_um)
      .def_readonly("final_spot_um", &OptimizeResult::final_spot_um)
      .def_readonly("start_field_spot_um", &OptimizeResult::start_field_spot_um)
      .def_readonly("final_field_spot_um", &OptimizeResult::final_field_spot_um)
      .def_readonly("start_wavefront_waves", &OptimizeResult::start_wavefront_waves,
                    "With merit='wavefront': the mean RMS wavefront (waves, piston and tilt "
                    "removed) at full sampling before optimizing; 0 with the spot merit.")
      .def_readonly("final_wavefront_waves", &OptimizeResult::final_wavefront_waves,
                    "The same after optimizing.")
      .def_readonly("afocal", &OptimizeResult::afocal,
                    "An afocal lens ([system] afocal = true): the merit is the mean RMS angular "
                    "spot (mrad, as analyze reports it); the spots in um are then 0 and empty.")
      .def_readonly("start_angular_spot_mrad", &OptimizeResult::start_angular_spot_mrad,
                    "An afocal lens: the mean RMS angular spot (mrad) at full sampling before "
                    "optimizing; 0 otherwise.")
      .def_readonly("final_angular_spot_mrad", &OptimizeResult::final_angular_spot_mrad,
                    "The same after optimizing.")
      .def_readonly("start_field_angular_spot_mrad", &OptimizeResult::start_field_angular_spot_mrad)
      .def_readonly("final_field_angular_spot_mrad", &OptimizeResult::final_field_angular_spot_mrad)
      .def_readonly("glasses", &OptimizeResult::glasses)
      .def_readonly("iterations", &OptimizeResult::iterations)
      .def_readonly("loss_evaluations", &OptimizeResult::loss_evaluations)
      .def_readonly("seconds", &OptimizeResult::seconds)
      .def_readonly("termination", &OptimizeResult::termination)
      .def_readonly("interrupted", &OptimizeResult::interrupted)
      .def_readonly("kept_start", &OptimizeResult::kept_start)
      .def_readonly("log", &OptimizeResult::log)
      .def_property_readonly("constraints_pass",
                             [](const OptimizeResult& r) { return r.final_constraints.all_pass(); })
      .def_property_readonly(
          "targets",
          [](const OptimizeResult& r) {
            // One dict per target: what `lensopt optimize --json` reports under "targets".
            py::list out;
            for (std::size_t i = 0; i < r.final_targets.rows.size(); ++i) {
              const TargetRow& row = r.final_targets.rows[i];
              const DesignTarget& t = row.target;
              py::dict d;
              d["target"] = target_text(t);
              d["quantity"] = target_quantity_name(t.quantity);
              d["relation"] = t.relation == TargetRelation::kEqual    ? "="
                              : t.relation == TargetRelation::kAtMost ? "<="
                                                                      : ">=";
              d["bound"] = t.value;
              d["weight"] = t.weight;
              d["field"] = t.field > 0 ? py::object(py::int_(t.field)) : py::object(py::none());
              d["default"] = t.is_default;
              if (t.quantity == TargetQuantity::kMtf) {
                d["frequency_cpmm"] = t.frequency_cpmm;
                d["orientation"] = mtf_orientation_name(t.orientation);
              }
              const bool has_start = i < r.start_targets.rows.size();
              d["start"] = has_start && std::isfinite(r.start_targets.rows[i].value)
                               ? py::object(py::float_(r.start_targets.rows[i].value))
                               : py::object(py::none());
              d["start_pass"] = has_start && r.start_targets.rows[i].pass;
              d["final"] = std::isfinite(row.value) ? py::object(py::float_(row.value))
                                                    : py::object(py::none());
              d["pass"] = row.pass;
              out.append(d);
            }
            return out;
          },
          "Every target (with an as-written lens's default efl_mm) as a dict: target, quantity, "
          "relation, bound, weight, field, start, start_pass, final, pass.")
      .def_property_readonly("targets_pass",
                             [](const OptimizeResult& r) { return r.final_targets.all_pass(); });

  m.def(
      "optimize",
      [](const Lens& lens, std::optional<int> max_iterations, std::optional<int> max_rounds,
         const std::vector<std::string>& freeze, std::optional<std::string> glass_search,
         std::optional<int> rings, std::optional<int> fields, std::optional<bool> paper_penalties,
         bool verbose, std::optional<std::string> merit, std::optional<int> wavefront_pupil_samples,
         const std::string& bounds, std::optional<std::vector<std::string>> vary,
         std::optional<bool> soft_start, std::optional<int> neighbours, std::optional<int> threads,
         std::optional<double> weight_ray_path, std::optional<double> weight_ray_angle,
         std::optional<double> weight_glass, std::optional<double> min_air_mm,
         std::optional<double> min_glass_mm, std::optional<double> max_glass_mm,
         std::optional<double> min_image_clearance_mm, std::optional<double> max_ray_angle_deg,
         const std::vector<std::string>& targets, std::optional<bool> focus_only,
         std::optional<double> min_virtual_image_mm, std::optional<double> max_virtual_image_mm) {
        // The CLI's resolution (optimizer.h): defaults, bounds for the lens, its [optimize]
        // table, then the arguments given (None: not given).
        OptimizeOverrides v;
        v.bounds = parse_bounds_mode(bounds, SourceLocation{"bounds"});
        v.paper_penalties = paper_penalties;
        if (merit) v.merit = parse_merit(*merit, SourceLocation{"merit"});
        v.wavefront_pupil_samples = wavefront_pupil_samples;
        if (glass_search)
          v.glass_search = parse_glass_search(*glass_search, SourceLocation{"glass_search"});
        v.freeze = freeze;
        v.vary = vary;
        v.soft_start = soft_start;
        v.rings = rings;
        v.fields = fields;
        v.threads = threads;
        v.max_iterations = max_iterations;
        v.max_rounds = max_rounds;
        v.glass_neighbours = neighbours;
        v.weight_ray_path = weight_ray_path;
        v.weight_ray_angle = weight_ray_angle;
        v.weight_glass = weight_glass;
        v.min_air_mm = min_air_mm;
        v.min_glass_mm = min_glass_mm;
        v.max_glass_mm = max_glass_mm;
        v.min_image_clearance_mm = min_image_clearance_mm;
        v.max_ray_angle_deg = max_ray_angle_deg;
        v.min_virtual_image_mm = min_virtual_image_mm;
        v.max_virtual_image_mm = max_virtual_image_mm;
        v.verbose = verbose;
        for (const std::string& t : targets)
          v.targets.push_back(parse_target(t, SourceLocation{"targets"}));
        v.focus_only = focus_only;
        OptimizeResult r;
        {
          InterruptScope interrupt(InterruptScope::Signals::kInterruptOnly);
          {
            py::gil_scoped_release release;
            OptimizeOptions o = resolve_optimize_options(lens, v).options;
            o.interrupt = interrupt.flag();
            r = optimize_lens(lens, o);
          }
          if (interrupt.interrupted()) {
            PyErr_SetNone(PyExc_KeyboardInterrupt);
            throw py::error_already_set();
          }
        }
        return r;
      },
      py::arg("lens"), py::kw_only(), py::arg("max_iterations") = py::none(),
      py::arg("max_rounds") = py::none(), py::arg("freeze") = std::vector<std::string>{},
      py::arg("glass_search") = py::none(), py::arg("rings") = py::none(),
      py::arg("fields") = py::none(), py::arg("paper_penalties") = py::none(),
      py::arg("verbose") = false, py::arg("merit") = py::none(),
      py::arg("wavefront_pupil_samples") = py::none(), py::arg("bounds") = "auto",
      py::arg("vary") = py::none(), py::arg("soft_start") = py::none(),
      py::arg("neighbours") = py::none(), py::arg("threads") = py::none(),
      py::arg("weight_ray_path") = py::none(), py::arg("weight_ray_angle") = py::none(),
      py::arg("weight_glass") = py::none(), py::arg("min_air_mm") = py::none(),
      py::arg("min_glass_mm") = py::none(), py::arg("max_glass_mm") = py::none(),
      py::arg("min_image_clearance_mm") = py::none(), py::arg("max_ray_angle_deg") = py::none(),
      py::arg("targets") = std::vector<std::string>{}, py::arg("focus_only") = py::none(),
      py::arg("min_virtual_image_mm") = py::none(), py::arg("max_virtual_image_mm") = py::none(),
      "`lensopt optimize`: Levenberg-Marquardt on the paper's design loss, with the options "
      "resolved as the CLI resolves them (one function, optimize/optimizer.h "
      "resolve_optimize_options): the defaults, the bounds `bounds` selects ('auto': the "
      "paper's for the paper's lenses, else derived from the lens, as `--bounds`), the lens's "
      "[optimize] table, then every argument given (None: not given). The same lens gives the "
      "same result as `lensopt optimize`. paper_penalties=True is `--constraints paper`, "
      "soft_start=False `--no-soft-start`, merit='wavefront' `--merit wavefront` (the mean RMS "
      "wavefront error, piston and tilt removed, on a wavefront_pupil_samples grid). targets: "
      "design targets as `--target` writes them ('efl_mm=100', 'distortion_percent<=1', "
      "'rms_spot_um<=5,field=2,weight=3'), replacing the lens's [[optimize.targets]] entry of "
      "the same quantity and field; focus_only=True is `--focus-only`; min_virtual_image_mm= and "
      "max_virtual_image_mm= are `--min-virtual-image-mm` and `--max-virtual-image-mm` (a "
      "diverging lens's virtual image). freeze= and vary= are "
      "`--freeze` and `--vary`: they override the lens's per-surface vary flags (Surface.vary); "
      "pickups and solves (Surface.pickup_curvature, pickup_thickness, solve) are never "
      "free; OptimizeResult.log says which variables were free and why. Ctrl-C stops it "
      "(KeyboardInterrupt).");

  py::class_<ToleranceReport>(m, "ToleranceReport", "The result of tolerance().")
      .def_readonly("lens_name", &ToleranceReport::lens_name)
      .def_property_readonly("nominal_spot_um",
                             [](const ToleranceReport& r) { return r.nominal.mean_spot_um; })
      .def_property_readonly("trial_spots_um",
                             [](const ToleranceReport& r) {
                               std::vector<double> out;
                               for (const TrialResult& t : r.trials) out.push_back(t.mean_spot_um);
                               return out;
                             })
      .def_property_readonly("spot_p90_um", [](const ToleranceReport& r) { return r.spot.p90; })
      .def_property_readonly("spot_mean_um", [](const ToleranceReport& r) { return r.spot.mean; })
      .def_readonly("yield_fraction", &ToleranceReport::yield)
      .def_readonly("invalid_trials", &ToleranceReport::invalid_trials)
      .def("to_json", &format_tolerance_json, "The JSON of `lensopt tolerance --json`.")
      .def("to_text", [](const ToleranceReport& r) { return format_tolerance_text(r); })
      .def("trials_csv", &format_trials_csv)
      .def("to_dict", [](const ToleranceReport& r) {
        return py::module_::import("json").attr("loads")(format_tolerance_json(r));
      });

  m.def(
      "tolerance",
      [](const Lens& lens, std::optional<int> trials, std::optional<std::uint64_t> seed,
         std::optional<int> rings, std::optional<int> fields,
         std::optional<std::string> distribution, std::optional<std::string> compensator,
         bool sensitivity, std::optional<double> max_spot_um, std::optional<int> threads,
         std::optional<int> jobs, std::optional<std::map<std::string, double>> tolerances,
         std::optional<double> inverse_drop_um, std::optional<std::string> spot_reference) {
        refuse_afocal(lens, "lensopt.tolerance",
                      "tolerancing measures the change of the image-plane spot and MTF, and an "
                      "afocal tolerance criterion (angular spot, plane-wave wavefront) is not "
                      "implemented");
        // The CLI's start (tolerance.h): the defaults and the lens's [tolerance] table, then the
        // arguments given (None: not given).
        ToleranceOptions o = tolerance_options_for(lens);
        if (trials) o.trials = *trials;
        if (seed) o.seed = *seed;
        if (rings) o.rings = *rings;
        if (fields) o.fields = *fields;
        if (distribution) o.distribution = parse_tolerance_distribution(*distribution);
        // A compensator list as the CLI's --compensator: the focus it names (else paraxial) and
        // the compensators beyond focus.
        if (compensator) {
          const CompensatorList list = parse_compensators(*compensator);
          o.compensator = FocusCompensator::kParaxial;
          o.apply(list);
        }
        if (spot_reference) o.spot_reference = parse_spot_reference(*spot_reference);
        o.sensitivity = sensitivity;
        if (max_spot_um) o.max_spot_um = *max_spot_um;
        if (inverse_drop_um) o.inverse_drop_um = *inverse_drop_um;
        // tolerances={'decenter_mm': 0.01, 'surface_tilt_arcmin': 1, ...}: as the CLI's
        // --decenter-mm etc., by the [tolerance] table's names.
        if (tolerances) {
          const std::vector<std::string>& names = tolerance_names();
          double* slots[] = {&o.tolerances.curvature_pct,
                             &o.tolerances.glass_thickness_mm,
                             &o.tolerances.air_thickness_mm,
                             &o.tolerances.nd,
                             &o.tolerances.vd_pct,
                             &o.tolerances.asphere_sag_um,
                             &o.tolerances.decenter_mm,
                             &o.tolerances.tilt_arcmin,
                             &o.tolerances.surface_decenter_mm,
                             &o.tolerances.surface_tilt_arcmin};
          static_assert(sizeof(slots) / sizeof(slots[0]) == 10);
          for (const auto& [name, value] : *tolerances) {
            const auto it = std::find(names.begin(), names.end(), name);
            if (it == names.end())
              throw Error("tolerance: unknown tolerance '" + name +
                          "' (known: the [tolerance] "
                          "table's names, e.g. decenter_mm, surface_tilt_arcmin)");
            *slots[it - names.begin()] = value;
          }
        }
        // threads= as the CLI's --threads (jobs=: its old name, as --jobs).
        if (threads && jobs && *threads != *jobs)
          throw Error("tolerance: threads = " + std::to_string(*threads) + " and jobs = " +
                      std::to_string(*jobs) + " differ; give threads (jobs is its old name)");
        o.jobs = threads ? *threads : jobs ? *jobs : 0;
        o.validate();
        py::gil_scoped_release release;
        return run_tolerance(lens, o);
      },
      py::arg("lens"), py::kw_only(), py::arg("trials") = py::none(), py::arg("seed") = py::none(),
      py::arg("rings") = py::none(), py::arg("fields") = py::none(),
      py::arg("distribution") = py::none(), py::arg("compensator") = py::none(),
      py::arg("sensitivity") = true, py::arg("max_spot_um") = py::none(),
      py::arg("threads") = py::none(), py::arg("jobs") = py::none(),
      py::arg("tolerances") = py::none(), py::arg("inverse_drop_um") = py::none(),
      py::arg("spot_reference") = py::none(),
      "`lensopt tolerance`: Monte-Carlo trials of manufacturing errors, with the sensitivity "
      "table. The options start where the CLI's do (tolerance_options_for: the defaults, 10000 "
      "trials, seed 1, 16 rings, 11 fields, with the lens's [tolerance] table applied); an "
      "argument given (not None) overrides them. threads: threads over trials (0: all cores), as "
      "the CLI's --threads (jobs: its old name). tolerances: a dict of tolerance limits by the "
      "[tolerance] table's names (curvature_pct, ..., decenter_mm, tilt_arcmin, "
      "surface_decenter_mm, surface_tilt_arcmin), as the CLI's --curvature-pct etc.; "
      "inverse_drop_um: as --inverse-drop-um (the sensitivity rows' inverse_limit); compensator: "
      "a list as --compensator (\"best-rms,image-shift\", \"decenter:element=2\"); "
      "spot_reference: as --spot-reference (centroid or nominal).");
}

}  // namespace lensopt::python
