// Helpers shared by the lens readers (TOML, paper YAML); not part of the public API.
#pragma once

#include <span>
#include <string>
#include <string_view>

#include "lensopt/core/text.h"

namespace lensopt::detail {

using lensopt::edit_distance;  // core/text.h

// The known key closest to `key` when it is close enough to be a likely typo or a missing unit
// suffix (d <= 2, or d <= |known| / 3), else "".
std::string closest_key(std::string_view key, std::span<const std::string_view> known_keys);

// " (did you mean 'x'?)" for closest_key, or "" when nothing is close.
std::string did_you_mean(std::string_view key, std::span<const std::string_view> known_keys);

}  // namespace lensopt::detail
