// The [optimize] table of a lens TOML or search description: one parser for `lensopt optimize`
// and `lensopt search`, so both accept the same keys with the same checks. An internal header of
// the optimize module (src/, not installed; included as "optimize/optimize_table.h" by search/ and
// the CLI): it takes toml++ nodes, which stay out of the public headers.
#pragma once

#include <toml++/toml.h>

#include <string>

#include "lensopt/core/error.h"
#include "lensopt/optimize/optimizer.h"

namespace lensopt {

// parse_glass_search, glass_search_name and parse_merit are declared in optimizer.h.

// Applies one key of an [optimize] table to `options`. Returns false for an unknown key (the
// caller may know keys of its own); throws Error at `where` for a value of the wrong type or
// out of range.
bool apply_optimize_key(const std::string& key, const toml::node& node, const SourceLocation& where,
                        OptimizeOptions& options);

// Applies the [optimize] table of a lens (its TOML source file, else Lens::extra_toml) to
// `options`; an unknown key or a bad value throws Error with file:line:column.
void apply_optimize_table(const Lens& lens, OptimizeOptions& options);

// The keys apply_optimize_key knows, comma-separated, for error messages.
const char* optimize_table_keys();

}  // namespace lensopt
