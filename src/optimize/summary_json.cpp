// OptimizeSummary: from an OptimizeResult, and to and from JSON (optimize/summary_json.h).
#include "summary_json.h"

#include <fmt/format.h>

#include <cmath>
#include <limits>

#include "core/json_number.h"

namespace lensopt {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

double finite_or_inf(double um) {
  return std::isfinite(um) ? um : kInf;
}

double spot_from_json(const nlohmann::json& j) {
  return j.is_number() ? j.get<double>() : kInf;
}

}  // namespace

std::string failing_constraints(const ConstraintReport& report) {
  std::string out;
  for (const ConstraintReport::Row& r : report.rows)
    if (!r.pass)
      out += fmt::format("{}{} = {:.4f} ({} {})", out.empty() ? "" : "; ", r.name, r.value,
                         r.is_lower ? ">=" : "<=", r.bound);
  if (report.ray_failures > 0)
    out += fmt::format("{}{} failing rays", out.empty() ? "" : "; ", report.ray_failures);
  return out;
}

OptimizeSummary summarize(const OptimizeResult& result) {
  OptimizeSummary s;
  s.start_spot_um = finite_or_inf(result.start_spot_um);
  s.final_spot_um = finite_or_inf(result.final_spot_um);
  s.afocal = result.afocal;
  s.start_angular_spot_mrad = finite_or_inf(result.start_angular_spot_mrad);
  s.final_angular_spot_mrad = finite_or_inf(result.final_angular_spot_mrad);
  s.constraints_met = result.final_constraints.all_pass() &&
                      std::isfinite(s.afocal ? s.final_angular_spot_mrad : s.final_spot_um);
  s.failing = failing_constraints(result.final_constraints);
  s.glasses = result.glasses;
  s.iterations = result.iterations;
  s.loss_evaluations = result.loss_evaluations;
  s.kept_start = result.kept_start;
  s.seconds = result.seconds;
  return s;
}

void add_summary_json(nlohmann::json& j, const OptimizeSummary& s) {
  if (s.afocal) {
    // No image plane: the merit in angle (analysis/afocal.h).
    j["afocal"] = true;
    j["start_mean_rms_angular_spot_mrad"] = finite_or_null(s.start_angular_spot_mrad);
    j["final_mean_rms_angular_spot_mrad"] = finite_or_null(s.final_angular_spot_mrad);
  } else {
    j["start_mean_rms_spot_um"] = finite_or_null(s.start_spot_um);
    j["final_mean_rms_spot_um"] = finite_or_null(s.final_spot_um);
  }
  j["constraints_met"] = s.constraints_met;
  j["failing_constraints"] = s.failing;
  j["glasses"] = s.glasses;
  j["iterations"] = s.iterations;
  j["loss_evaluations"] = s.loss_evaluations;
  j["kept_start"] = s.kept_start;
  j["seconds"] = s.seconds;
}

OptimizeSummary summary_from_json(const nlohmann::json& j) {
  OptimizeSummary s;
  s.afocal = j.contains("afocal") && j.at("afocal").get<bool>();
  if (s.afocal) {
    s.start_spot_um = s.final_spot_um = kInf;
    s.start_angular_spot_mrad = spot_from_json(j.at("start_mean_rms_angular_spot_mrad"));
    s.final_angular_spot_mrad = spot_from_json(j.at("final_mean_rms_angular_spot_mrad"));
  } else {
    s.start_spot_um = spot_from_json(j.at("start_mean_rms_spot_um"));
    s.final_spot_um = spot_from_json(j.at("final_mean_rms_spot_um"));
  }
  s.constraints_met = j.at("constraints_met").get<bool>();
  s.failing = j.at("failing_constraints").get<std::string>();
  s.glasses = j.at("glasses").get<std::vector<std::string>>();
  s.iterations = j.at("iterations").get<int>();
  s.loss_evaluations = j.at("loss_evaluations").get<int>();
  s.kept_start = j.at("kept_start").get<bool>();
  s.seconds = j.at("seconds").get<double>();
  return s;
}

}  // namespace lensopt
