// Numbers in lensopt's JSON outputs: JSON has no NaN or infinity, so a non-finite value is written
// as null (header-only; internal: nlohmann::json stays out of the public headers).
#pragma once

#include <cmath>
#include <nlohmann/json.hpp>

namespace lensopt {

// v, or null when v is NaN or infinite.
inline nlohmann::json finite_or_null(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

}  // namespace lensopt
