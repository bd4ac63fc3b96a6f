// The plots' shared colours: one palette so every page reads the same way.
#pragma once

#include <string>

#include "lensopt/plot/svg.h"

namespace lensopt::plot {

inline constexpr const char* kGlassFill = "#dce8f5";
inline constexpr const char* kLensStroke = "#1b2a3a";
inline constexpr const char* kCompareStroke = "#b03a2e";
inline constexpr const char* kTextColour = "#222222";

// Field j of n: blue (on axis) through green and orange to red (full field).
std::string field_colour(int j, int n);

// Colour channel c (0 R, 1 G, 2 B).
inline std::string channel_colour(int c) {
  static const char* rgb[] = {"#d1342b", "#2a9d3a", "#1f5fbf"};
  return rgb[c < 0 || c > 2 ? 1 : c];
}

inline const char* channel_name(int c) {
  static const char* names[] = {"R", "G", "B"};
  return names[c < 0 || c > 2 ? 1 : c];
}

}  // namespace lensopt::plot
