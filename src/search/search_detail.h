// Internals shared by the search's source files.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "lensopt/lens/lens.h"
#include "lensopt/optimize/optimizer.h"

namespace lensopt::detail {

// The image distance (mm) of a rebuilt lens that keeps an old defocus: BFL_new + defocus_old
// (paraxial, 587.6 nm); the lens's own last thickness if it has no finite BFL.
double rebuilt_image_mm(const Lens& rebuilt, double old_defocus_mm);

// Last thickness minus the paraxial BFL (587.6 nm), mm; 0 without a finite BFL.
double lens_defocus_mm(const Lens& lens);

// FNV-1a, 64 bit, of a text.
uint64_t fnv1a64(const std::string& text, uint64_t hash = 14695981039346656037ull);

// The optimizer settings that change results (not threads or verbosity), for fingerprints and
// search.json.
nlohmann::json optimize_settings_json(const OptimizeOptions& options, bool paper_then_strict);

}  // namespace lensopt::detail
