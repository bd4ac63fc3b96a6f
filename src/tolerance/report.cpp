// Tolerancing output: per-trial CSV, text summary, JSON and the histogram (SVG).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "lensopt/plot/svg.h"
#include "lensopt/tolerance/tolerance.h"

namespace lensopt {
namespace {

// Shortest text that reads back to the same double.
std::string exact(double v) {
  return fmt::format("{}", v);
}

std::string compensator_text(FocusCompensator c) {
  switch (c) {
    case FocusCompensator::kParaxial:
      return "paraxial image solve (last thickness = BFL + nominal defocus)";
    case FocusCompensator::kBestRms:
      return "best-RMS refocus (last thickness minimizing the mean spot)";
    case FocusCompensator::kNone:
      return "none (last thickness fixed)";
  }
  return "?";
}

std::string distribution_text(ToleranceDistribution d) {
  return d == ToleranceDistribution::kUniform
             ? "uniform within +-tolerance"
             : "normal, sigma = tolerance / 2, truncated at +-tolerance";
}

std::string tolerance_line(const Tolerances& t) {
  auto value = [](double v, const char* unit) {
    return v > 0 ? fmt::format("+-{:g}{}", v, unit) : std::string("off");
  };
  std::string text = fmt::format(
      "curvature {}, glass thickness {}, airspace {}, nd {}, vd {}, element decenter {}, "
      "element tilt {}",
      value(t.curvature_pct, " %"), value(t.glass_thickness_mm, " mm"),
      value(t.air_thickness_mm, " mm"), value(t.nd, ""), value(t.vd_pct, " %"),
      value(t.decenter_mm, " mm"), value(t.tilt_arcmin, " arcmin"));
  if (t.surface_decenter_mm > 0 || t.surface_tilt_arcmin > 0)  // named when either is on
    text +=
        fmt::format(", surface decenter {}, surface tilt {}", value(t.surface_decenter_mm, " mm"),
                    value(t.surface_tilt_arcmin, " arcmin"));
  return text;
}

}  // namespace

std::string format_trials_csv(const ToleranceReport& report) {
  std::string out =
      "trial,valid,mean_spot_um,efl_mm,max_abs_distortion_pct,ray_failures,"
      "image_distance_mm,elements_intersect,min_edge_gap_mm";
  for (double f : report.fields_deg) out += fmt::format(",spot_um_{:g}deg", f);
  for (const ToleranceParameter& p : report.parameters) out += "," + p.column;
  // The compensators' moves beyond focus (only with such compensators: the columns of a run
  // without them are as before).
  for (const std::string& name : report.compensation_names) {
    out += ',';
    out += name;
  }
  out += "\n";
  for (const TrialResult& r : report.trials) {
    out += fmt::format("{},{}", r.index, r.valid ? 1 : 0);
    if (r.valid) {
      out += fmt::format(",{},{},{},{},{},{},{}", exact(r.mean_spot_um), exact(r.efl_mm),
                         exact(r.max_abs_distortion_pct), r.ray_failures,
                         exact(r.image_distance_mm), r.collision ? 1 : 0, exact(r.min_edge_gap_mm));
      for (double s : r.rms_spot_um) {
        out += ',';
        out += exact(s);
      }
    } else {
      out += fmt::format(",,,,{},,{},{}", r.ray_failures, r.collision ? 1 : 0,
                         exact(r.min_edge_gap_mm));
      for (std::size_t h = 0; h < r.rms_spot_um.size(); ++h) out += ",";
    }
    for (double d : r.perturbations) {
      out += ',';
      out += exact(d);
    }
    for (std::size_t i = 0; i < report.compensation_names.size(); ++i) {
      out += ',';
      if (r.valid && i < r.compensation.size()) out += exact(r.compensation[i]);
    }
    out += "\n";
  }
  return out;
}

std::string format_tolerance_text(const ToleranceReport& r, int sensitivity_rows) {
  std::string out;
  auto line = [&](const std::string& s) { out += s + "\n"; };
  const ToleranceOptions& o = r.options;
  line(fmt::format("Tolerancing: {}{}", r.lens_name,
                   r.source_path.empty() ? "" : fmt::format(" ({})", r.source_path)));
  if (r.scaled_to_spec)
    line(fmt::format(
        "  prescription scaled by {:.6f} to f = {:.4f} mm; tolerances apply to the scaled lens",
        r.scale, r.spec_focal_length_mm));
  else
    line("  traced as written (not scaled); tolerances apply to the prescription");
  line(fmt::format("  tolerances: {}", tolerance_line(o.tolerances)));
  line(fmt::format("  {} trials, seed {}, {}; compensator: {}", o.trials, o.seed,
                   distribution_text(o.distribution), compensator_text(o.compensator)));
  if (o.image_shift || !o.decenter_compensators.empty()) {
    std::string extra;
    if (o.image_shift) extra = "lateral image shift";
    for (int k : o.decenter_compensators)
      extra += fmt::format("{}decenter x, y of group {}", extra.empty() ? "" : ", ", k);
    line(fmt::format("  compensators beyond focus: {} (solved per trial)", extra));
    // The largest move of each over the valid trials.
    std::string moves;
    for (std::size_t i = 0; i < r.compensation_names.size(); ++i) {
      double largest = 0.0;
      for (const TrialResult& t : r.trials)
        if (t.valid && i < t.compensation.size())
          largest = std::max(largest, std::abs(t.compensation[i]));
      moves +=
          fmt::format("{}{} {:.4g}", moves.empty() ? "" : ", ", r.compensation_names[i], largest);
    }
    line(fmt::format("  largest compensator moves (mm): {}", moves));
  }
  if (o.spot_reference == SpotReference::kNominal)
    line("  spot reference: the nominal image point of each field (a displaced image counts)");
  line(
      fmt::format("  sampling: {} fields x {} wavelengths x {} pupil rays ({} rings), ray "
                  "aiming {}",
                  r.fields_deg.size(), r.wavelength_count, r.rays_per_field_wavelength, o.rings,
                  o.ray_aiming ? "on" : "off"));
  line(fmt::format("  {:.2f} s on {} threads, {:.3f} ms per trial", r.elapsed_s, r.threads,
                   r.ms_per_trial));
  line("");
  line("  mean RMS spot (um)");
  line(fmt::format("    nominal {:9.3f}   mean {:9.3f}   std {:8.3f}", r.nominal.mean_spot_um,
                   r.spot.mean, r.spot.std));
  line(
      fmt::format("    p50     {:9.3f}   p90  {:9.3f}   p95 {:8.3f}   p99 {:8.3f}   worst "
                  "{:8.3f}",
                  r.spot.p50, r.spot.p90, r.spot.p95, r.spot.p99, r.spot.worst));
  if (r.yield) {
    line(fmt::format("    yield (mean spot <= {:g} um): {:.2f} %", *o.max_spot_um,
                     100.0 * *r.yield));
  } else {
    line("    yield: give --max-spot-um (or max_spot_um in [tolerance])");
  }
  line(fmt::format("  EFL (mm): nominal {:.4f}, mean {:.4f}, std {:.4f}, range {:.4f} .. {:.4f}",
                   r.nominal.efl_mm, r.efl_mean_mm, r.efl_std_mm, r.efl_min_mm, r.efl_max_mm));
  line(fmt::format("  max |distortion| (%): nominal {:.4f}, mean {:.4f}, worst {:.4f}",
                   r.nominal.max_abs_distortion_pct, r.distortion_mean_pct,
                   r.distortion_worst_pct));
  line(fmt::format("  image distance (mm): nominal {:.4f}", r.nominal.image_distance_mm));
  line(fmt::format("  ray failures: nominal {}; {} trials with failures; {} trials untraceable",
                   r.nominal.ray_failures, r.trials_with_failures, r.invalid_trials));
  line(fmt::format("  intersecting elements (an edge gap below 0): {} trials{}",
                   r.trials_with_collisions,
                   r.trials_with_collisions > 0 ? " (failures in the yield)" : ""));
  if (!r.sensitivity.empty()) {
    line("");
    line("  Sensitivity: each tolerance alone at its limits, change in mean RMS spot (um);");
    line("  ranked by the larger |change|: tighten from the top");
    const bool inverse = r.options.inverse_drop_um.has_value();
    if (inverse)
      line(
          fmt::format("  inverse: the magnitude of the tolerance alone that raises the mean RMS "
                      "spot by {:g} um (the worse sign)",
                      *r.options.inverse_drop_um));
    line(inverse ? "  rank  param   tolerance     +limit     -limit      inverse   what"
                 : "  rank  param   tolerance     +limit     -limit   what");
    const int rows = std::min<int>(sensitivity_rows, static_cast<int>(r.sensitivity.size()));
    for (int i = 0; i < rows; ++i) {
      const SensitivityRow& s = r.sensitivity[i];
      const ToleranceParameter& p = r.parameters[s.parameter];
      auto num = [](double v) {
        return std::isfinite(v) ? fmt::format("{:+10.4f}", v) : std::string("    failed");
      };
      const bool degrees = p.kind == ToleranceParameter::Kind::kTiltX ||
                           p.kind == ToleranceParameter::Kind::kTiltY ||
                           p.kind == ToleranceParameter::Kind::kSurfaceTiltX ||
                           p.kind == ToleranceParameter::Kind::kSurfaceTiltY;
      const bool millimetres = p.kind == ToleranceParameter::Kind::kThickness ||
                               p.kind == ToleranceParameter::Kind::kDecenterX ||
                               p.kind == ToleranceParameter::Kind::kDecenterY ||
                               p.kind == ToleranceParameter::Kind::kSurfaceDecenterX ||
                               p.kind == ToleranceParameter::Kind::kSurfaceDecenterY;
      const std::string inverse_text =
          !inverse           ? std::string()
          : !s.inverse_limit ? fmt::format("  {:>11}", "none")
          : degrees          ? fmt::format("  {:>11}", fmt::format("{:.4g}'", *s.inverse_limit))
          : millimetres      ? fmt::format("  {:>11}", fmt::format("{:.4g} mm", *s.inverse_limit))
          : (p.kind == ToleranceParameter::Kind::kCurvature ||
             p.kind == ToleranceParameter::Kind::kVd)
              ? fmt::format("  {:>11}", fmt::format("{:.4g} %", 100.0 * *s.inverse_limit))
              : fmt::format("  {:>11.4g}", *s.inverse_limit);
      line(fmt::format("  {:4d}  {:<6}  {:>9}  {}  {}{}   {}", i + 1, p.name, p.limit_text,
                       num(s.plus_um), num(s.minus_um), inverse_text, p.description));
    }
    if (rows < static_cast<int>(r.sensitivity.size()))
      line(fmt::format("  ({} more rows in --json)", r.sensitivity.size() - rows));
  }
  return out;
}

std::string format_tolerance_json(const ToleranceReport& r) {
  using nlohmann::json;
  auto num = [](double v) { return std::isfinite(v) ? json(v) : json(nullptr); };
  auto trial_json = [&](const TrialResult& t) {
    json j;
    j["trial"] = t.index;
    j["valid"] = t.valid;
    j["mean_rms_spot_um"] = t.valid ? num(t.mean_spot_um) : json(nullptr);
    json spots = json::array();
    for (double s : t.rms_spot_um) spots.push_back(t.valid ? num(s) : json(nullptr));
    j["rms_spot_um"] = spots;
    j["efl_mm"] = num(t.efl_mm);
    j["max_abs_distortion_pct"] = t.valid ? num(t.max_abs_distortion_pct) : json(nullptr);
    j["ray_failures"] = t.ray_failures;
    j["image_distance_mm"] = num(t.image_distance_mm);
    json d = json::array();
    for (double v : t.perturbations) d.push_back(num(v));
    j["perturbations"] = d;
    if (!r.compensation_names.empty()) {
      json c = json::object();
      for (std::size_t i = 0; i < r.compensation_names.size(); ++i)
        c[r.compensation_names[i]] =
            t.valid && i < t.compensation.size() ? num(t.compensation[i]) : json(nullptr);
      j["compensation"] = c;
    }
    return j;
  };
  const ToleranceOptions& o = r.options;
  json j;
  j["lens"] = r.lens_name;
  j["source"] = r.source_path;
  j["scale"] = num(r.scale);
  j["scaled_to_spec"] = r.scaled_to_spec;
  if (r.scaled_to_spec) j["spec_focal_length_mm"] = num(r.spec_focal_length_mm);
  j["trials"] = o.trials;
  j["seed"] = o.seed;
  j["distribution"] = to_string(o.distribution);
  j["distribution_note"] = distribution_text(o.distribution);
  j["compensator"] = to_string(o.compensator);
  j["spot_reference"] = to_string(o.spot_reference);
  if (o.image_shift || !o.decenter_compensators.empty()) {
    j["image_shift_compensator"] = o.image_shift;
    j["decenter_compensators"] = o.decenter_compensators;
  }
  j["tolerances"] = {{"curvature_pct", o.tolerances.curvature_pct},
                     {"glass_thickness_mm", o.tolerances.glass_thickness_mm},
                     {"air_thickness_mm", o.tolerances.air_thickness_mm},
                     {"nd", o.tolerances.nd},
                     {"vd_pct", o.tolerances.vd_pct},
                     {"decenter_mm", o.tolerances.decenter_mm},
                     {"tilt_arcmin", o.tolerances.tilt_arcmin},
                     {"surface_decenter_mm", o.tolerances.surface_decenter_mm},
                     {"surface_tilt_arcmin", o.tolerances.surface_tilt_arcmin}};
  if (o.inverse_drop_um) j["inverse_drop_um"] = *o.inverse_drop_um;
  j["sampling"] = {{"rings", o.rings},
                   {"fields", r.fields_deg.size()},
                   {"wavelengths", r.wavelength_count},
                   {"rays_per_field_wavelength", r.rays_per_field_wavelength},
                   {"ray_aiming", o.ray_aiming}};
  j["fields_deg"] = r.fields_deg;
  json params = json::array();
  for (const ToleranceParameter& p : r.parameters) {
    params.push_back({{"name", p.name},
                      {"column", p.column},
                      {"description", p.description},
                      {"limit", num(p.limit)},
                      {"tolerance", p.limit_text}});
  }
  j["parameters"] = params;
  j["nominal"] = trial_json(r.nominal);
  json summary;
  summary["valid_trials"] = r.spot.count;
  summary["invalid_trials"] = r.invalid_trials;
  summary["trials_with_ray_failures"] = r.trials_with_failures;
  summary["trials_with_intersecting_elements"] = r.trials_with_collisions;
  summary["nominal_um"] = num(r.nominal.mean_spot_um);
  summary["mean_um"] = num(r.spot.mean);
  summary["std_um"] = num(r.spot.std);
  summary["p50_um"] = num(r.spot.p50);
  summary["p90_um"] = num(r.spot.p90);
  summary["p95_um"] = num(r.spot.p95);
  summary["p99_um"] = num(r.spot.p99);
  summary["best_um"] = num(r.spot.best);
  summary["worst_um"] = num(r.spot.worst);
  // The yield limit and the yield only when a limit is given (no null in an output).
  if (o.max_spot_um) summary["max_spot_um"] = num(*o.max_spot_um);
  if (r.yield) summary["yield"] = num(*r.yield);
  summary["efl_mm"] = {{"nominal", num(r.nominal.efl_mm)},
                       {"mean", num(r.efl_mean_mm)},
                       {"std", num(r.efl_std_mm)},
                       {"min", num(r.efl_min_mm)},
                       {"max", num(r.efl_max_mm)}};
  summary["max_abs_distortion_pct"] = {{"nominal", num(r.nominal.max_abs_distortion_pct)},
                                       {"mean", num(r.distortion_mean_pct)},
                                       {"worst", num(r.distortion_worst_pct)}};
  j["summary"] = summary;
  json sens = json::array();
  for (std::size_t i = 0; i < r.sensitivity.size(); ++i) {
    const SensitivityRow& s = r.sensitivity[i];
    const ToleranceParameter& p = r.parameters[s.parameter];
    sens.push_back({{"rank", i + 1},
                    {"parameter", p.name},
                    {"description", p.description},
                    {"tolerance", p.limit_text},
                    {"limit", num(p.limit)},
                    {"delta_spot_plus_um", num(s.plus_um)},
                    {"delta_spot_minus_um", num(s.minus_um)},
                    {"delta_efl_plus_mm", num(s.efl_plus_mm)},
                    {"delta_efl_minus_mm", num(s.efl_minus_mm)},
                    {"score_um", num(s.score_um)}});
    if (o.inverse_drop_um) {
      sens.back()["inverse_limit"] = s.inverse_limit ? num(*s.inverse_limit) : json(nullptr);
      sens.back()["inverse_delta_spot_um"] =
          s.inverse_limit ? num(s.inverse_spot_um) : json(nullptr);
    }
  }
  j["sensitivity"] = sens;
  j["timing"] = {{"threads", r.threads},
                 {"trials_s", num(r.elapsed_s)},
                 {"ms_per_trial", num(r.ms_per_trial)},
                 {"sensitivity_s", num(r.sensitivity_s)}};
  // The trials last, one compact object per line (10,000 trials stay a few MB and greppable).
  std::string out = j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
  out.erase(out.find_last_of('}'));
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  out += ",\n  \"trial_results\": [";
  for (std::size_t i = 0; i < r.trials.size(); ++i)
    out += (i == 0 ? "\n    " : ",\n    ") +
           trial_json(r.trials[i]).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  out += r.trials.empty() ? "]\n}" : "\n  ]\n}";
  return out;
}

namespace {

plot::Style style(const std::string& stroke, double width, const std::string& fill = "none",
                  const std::string& dash = "") {
  plot::Style s;
  s.stroke = stroke;
  s.stroke_width = width;
  s.fill = fill;
  s.dash = dash;
  return s;
}

// A "nice" tick step (1, 2 or 5 times a power of ten) for about `count` ticks over `span`.
double nice_step(double span, int count) {
  const double raw = span / std::max(1, count);
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / power;
  return (f <= 1.0 ? 1.0 : f <= 2.0 ? 2.0 : f <= 5.0 ? 5.0 : 10.0) * power;
}

}  // namespace

std::string format_tolerance_histogram_svg(const ToleranceReport& r, int bins) {
  using plot::Point;
  using plot::Style;
  bins = std::max(1, bins);
  std::vector<double> values;
  for (const TrialResult& t : r.trials)
    if (t.valid) values.push_back(t.mean_spot_um);
  const double nominal = r.nominal.mean_spot_um;
  double lo = nominal, hi = nominal;
  for (double v : values) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  const std::optional<double> limit = r.options.max_spot_um;
  if (limit && *limit >= lo - (hi - lo) && *limit <= hi + (hi - lo)) {
    lo = std::min(lo, *limit);
    hi = std::max(hi, *limit);
  }
  if (!(hi - lo > 1e-9 * std::max(1.0, std::abs(hi)))) {
    const double pad = std::max(1e-3, 0.01 * std::abs(hi));
    lo -= pad;
    hi += pad;
  } else {
    const double pad = 0.02 * (hi - lo);
    lo -= pad;
    hi += pad;
  }
  std::vector<int> counts(bins, 0);
  for (double v : values) {
    int b = static_cast<int>((v - lo) / (hi - lo) * bins);
    counts[std::clamp(b, 0, bins - 1)]++;
  }
  const int max_count = std::max(1, *std::max_element(counts.begin(), counts.end()));

  const double width = 780, height = 470;
  const double left = 70, right = 200, top = 50, bottom = 60;
  const double pw = width - left - right, ph = height - top - bottom;
  plot::SvgDocument svg(width, height);
  auto x_of = [&](double v) { return left + (v - lo) / (hi - lo) * pw; };
  const double y_step = nice_step(max_count, 5);
  const double y_max = std::ceil(max_count / y_step) * y_step;
  auto y_of = [&](double c) { return top + ph - c / y_max * ph; };

  svg.rect({0, 0}, width, height, style("none", 0, "#ffffff"));
  svg.text({left + pw / 2, 24},
           fmt::format("Monte-Carlo tolerancing: {} ({} trials, {}, compensator {})", r.lens_name,
                       r.options.trials, to_string(r.options.distribution),
                       to_string(r.options.compensator)),
           14, "middle");
  // Grid and axes.
  const Style grid = style("#dddddd", 1);
  const Style axis = style("#000000", 1);
  for (double c = 0; c <= y_max + 1e-9; c += y_step) {
    svg.line({left, y_of(c)}, {left + pw, y_of(c)}, grid);
    svg.text({left - 6, y_of(c) + 4}, fmt::format("{:g}", c), 11, "end");
  }
  const double x_step = nice_step(hi - lo, 8);
  for (double v = std::ceil(lo / x_step) * x_step; v <= hi + 1e-12; v += x_step) {
    svg.line({x_of(v), top + ph}, {x_of(v), top + ph + 5}, axis);
    svg.text({x_of(v), top + ph + 18}, fmt::format("{:g}", std::abs(v) < 1e-12 ? 0.0 : v), 11,
             "middle");
  }
  // Bars.
  const Style bar = style("#3b6ea5", 0.5, "#6a9fd4");
  for (int b = 0; b < bins; ++b) {
    if (counts[b] == 0) continue;
    const double x0 = x_of(lo + (hi - lo) * b / bins);
    const double x1 = x_of(lo + (hi - lo) * (b + 1) / bins);
    svg.rect({x0, y_of(counts[b])}, x1 - x0, y_of(0) - y_of(counts[b]), bar);
  }
  svg.line({left, top + ph}, {left + pw, top + ph}, axis);
  svg.line({left, top}, {left, top + ph}, axis);
  svg.text({left + pw / 2, height - 18}, "mean RMS spot (µm)", 12, "middle");
  svg.text({20, top + ph / 2}, "trials", 12, "middle", "#000000", -90);

  // Marker lines and legend.
  struct Marker {
    std::string label;
    double value;
    std::string colour;
    std::string dash;
  };
  std::vector<Marker> markers = {{"nominal", nominal, "#1b9e77", "6 3"}};
  if (!values.empty()) {
    markers.push_back({"mean", r.spot.mean, "#444444", "2 2"});
    markers.push_back({"p90", r.spot.p90, "#e6ab02", ""});
    markers.push_back({"p99", r.spot.p99, "#d95f02", ""});
  }
  if (limit) markers.push_back({"max spot", *limit, "#c00000", "8 2 2 2"});
  double legend_y = top + 10;
  const double legend_x = left + pw + 20;
  for (const Marker& m : markers) {
    const Style s = style(m.colour, 2, "none", m.dash);
    const bool inside = m.value >= lo && m.value <= hi;
    if (inside) svg.line({x_of(m.value), top}, {x_of(m.value), top + ph}, s);
    svg.line({legend_x, legend_y}, {legend_x + 24, legend_y}, s);
    svg.text({legend_x + 30, legend_y + 4},
             fmt::format("{} {:.3f} µm{}", m.label, m.value, inside ? "" : " (off scale)"), 11);
    legend_y += 20;
  }
  legend_y += 10;
  svg.text({legend_x, legend_y}, fmt::format("std {:.3f} µm", r.spot.std), 11);
  if (r.yield) {
    legend_y += 18;
    svg.text({legend_x, legend_y}, fmt::format("yield {:.2f} %", 100.0 * *r.yield), 11);
  }
  legend_y += 18;
  svg.text({legend_x, legend_y}, fmt::format("{} of {} traced", values.size(), r.trials.size()),
           11);
  return svg.str();
}

}  // namespace lensopt
