// OptimizeSummary <-> JSON: the one serializer of an optimization's result, shared by
// `lensopt optimize --json` (cli) and `lensopt search`'s result files and leaderboard (search).
// Internal: nlohmann::json stays out of the public headers.
//
// Keys: start_mean_rms_spot_um, final_mean_rms_spot_um (um, null when rays fail),
// constraints_met, failing_constraints, glasses, iterations, loss_evaluations, kept_start,
// seconds (wall time, the one non-deterministic field); for an afocal lens afocal = true and
// start_mean_rms_angular_spot_mrad, final_mean_rms_angular_spot_mrad in place of the spots.
#pragma once

#include <nlohmann/json.hpp>

#include "lensopt/optimize/optimizer.h"

namespace lensopt {

// Adds the summary's keys to the object `j`.
void add_summary_json(nlohmann::json& j, const OptimizeSummary& summary);

// Reads the summary's keys from `j`; throws nlohmann::json::exception on a missing key or a
// wrong type (the caller names the file).
OptimizeSummary summary_from_json(const nlohmann::json& j);

}  // namespace lensopt
