// Internal helpers of the .zmx reader and writer (formats/zmx.h): the file's lines and fields,
// and the exact decimal texts of numbers and wavelengths.
//
// Exact numbers. Curvatures, thicknesses, semi-diameters, the F/# and the field are written with
// fmt "{}", the shortest decimal that reads back to the same double, and read with from_chars
// (correctly rounded). Wavelengths go in micrometres as the nm decimal with its point moved three
// places ("584.1" nm -> "0.5841"), and are read back by moving it again, so they are exact too.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace lensopt::zmx_detail {

// Colour channel letters by index (0 R, 1 G, 2 B), as lensopt notes write them.
inline constexpr std::array<char, 3> kChannelLetters = {'R', 'G', 'B'};

// ASCII upper case.
std::string upper(std::string_view text);

// A decimal field, or nothing when it is not one.
std::optional<double> parse_double(std::string_view text);

bool is_blank(char ch);

// One line of the file: its blank-separated fields and their 1-based columns.
struct Line {
  int number = 0;
  std::string_view text;  // the whole line, without its line end
  std::vector<std::string_view> fields;
  std::vector<int> columns;

  // The text from field i to the end of the line ("" past the last field).
  std::string_view rest(std::size_t i) const;
};

// The lines of a text (LF or CRLF), numbered from 1; they view `text`, which must outlive them.
std::vector<Line> split_lines(std::string_view text);

// A wavelength written in micrometres, in nm: the decimal with its point moved three places right
// ("0.5875618" -> 587.5618), read correctly rounded, so the nm value is the double nearest the
// file's decimal (fl(um * 1000) can be an ulp off); exponent forms use um * 1000.
double micrometres_to_nm(std::string_view text, double um);

// The shortest decimal reading back as x.
std::string number_text(double x);

// The micrometre text of a wavelength: the shortest decimal of nm with its point moved three
// places left ("584.1" -> "0.5841"), so micrometres_to_nm reads nm back exactly.
std::string micrometre_text(double nm);

}  // namespace lensopt::zmx_detail
