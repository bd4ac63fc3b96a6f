// Limits on lens input that no real lens reaches, checked before the work that a hostile file
// could make unbounded (issue 34):
//   - nesting: toml++ and yaml-cpp descend recursively, one stack frame (a few hundred bytes) per
//     level, so about 30,000 levels (an 80 kB table header [a.a.a...]) overflow an 8 MB stack.
//     check_toml_nesting scans the text before the parser sees it (strings and comments honoured)
//     and refuses a file deeper than kMaxTomlNesting levels of arrays / tables / inline tables, or
//     with a dotted key of more than kMaxTomlKeyParts parts.
//   - YAML aliases: nodes are shared, but whatever walks the tree walks every expansion, so 330
//     bytes of nested aliases ("billion laughs", 9 levels of 10) expand to 10^9 nodes. The YAML
//     reader counts aliases and the expanded node count from the parser's events (linear in the
//     text) and refuses more than kMaxYamlAliases aliases, kMaxYamlNodes expanded nodes or
//     kMaxYamlNesting levels, naming the line.
//   - lens size: the readers refuse more than kMaxSurfaces surfaces, kMaxFields fields or
//     kMaxWavelengths wavelengths at the first one too many (a 5 MB file of 100,000 surfaces
//     otherwise makes analyze trace for minutes); validate_lens checks them too.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace lensopt {

inline constexpr int kMaxTomlNesting = 100;
inline constexpr int kMaxTomlKeyParts = 100;
inline constexpr int kMaxYamlNesting = 100;
inline constexpr std::size_t kMaxYamlAliases = 1000;
inline constexpr std::size_t kMaxYamlNodes = 100000;
// Real lenses have tens of surfaces (OpticStudio's sequential limit is far above any design, and
// its field and wavelength tables hold a few dozen entries).
inline constexpr std::size_t kMaxSurfaces = 1000;
inline constexpr std::size_t kMaxFields = 1000;
inline constexpr std::size_t kMaxWavelengths = 1000;

// Throws Error at file:line:column when `text` nests arrays, tables and inline tables deeper
// than kMaxTomlNesting or has a dotted key (a.b.c = ..., [a.b.c]) of more than kMaxTomlKeyParts
// parts. A lexical scan: strings (basic, literal, multi-line) and comments are skipped, so it
// never refuses a file for what its strings hold. Linear in the text; no allocation.
void check_toml_nesting(std::string_view text, const std::string& source_name);

}  // namespace lensopt
