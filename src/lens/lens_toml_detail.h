// Internal: what the TOML lens reader (lens_toml.cpp) and writer (lens_toml_write.cpp) share: the
// names of enumerations (indices follow the enums of lens/lens.h) and the text of extra tables.
#pragma once

#include <toml++/toml.h>

#include <array>
#include <string>
#include <string_view>

namespace lensopt::detail {

// ApertureType and FieldType by index.
inline constexpr std::array<std::string_view, 4> kApertureNames = {"f-number", "epd", "object-na",
                                                                   "float-by-stop"};
inline constexpr std::array<std::string_view, 4> kFieldTypeNames = {
    "angle", "object-height", "paraxial-image-height", "real-image-height"};
// Colour channels 0, 1, 2.
inline constexpr std::array<char, 3> kChannelLetters = {'R', 'G', 'B'};

// TOML text of the tables a lens file carries for other modules ([optimize], ...), from toml++'s
// parsed tree, every float as its shortest exact decimal (lens_toml_write.cpp).
std::string format_extra_toml(const toml::table& root);

}  // namespace lensopt::detail
