// Lines, fields and exact number texts of .zmx files (zmx_text.h).
#include "zmx_text.h"

#include <fmt/format.h>

#include <cctype>
#include <charconv>
#include <cmath>

namespace lensopt::zmx_detail {

std::string upper(std::string_view text) {
  std::string out(text);
  for (char& ch : out) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  return out;
}

std::optional<double> parse_double(std::string_view text) {
  double value = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(value))
    return std::nullopt;
  return value;
}

bool is_blank(char ch) {
  return ch == ' ' || ch == '\t' || ch == '\r' || ch == '\f' || ch == '\v';
}

std::string_view Line::rest(std::size_t i) const {
  if (i >= fields.size()) return {};
  std::string_view out = text.substr(static_cast<std::size_t>(columns[i] - 1));
  while (!out.empty() && is_blank(out.back())) out.remove_suffix(1);
  return out;
}

std::vector<Line> split_lines(std::string_view text) {
  std::vector<Line> lines;
  int number = 0;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    ++number;
    std::string_view raw = text.substr(start, end - start);
    if (!raw.empty() && raw.back() == '\r') raw.remove_suffix(1);
    Line line;
    line.number = number;
    line.text = raw;
    std::size_t i = 0;
    while (i < raw.size()) {
      while (i < raw.size() && is_blank(raw[i])) ++i;
      const std::size_t field_start = i;
      while (i < raw.size() && !is_blank(raw[i])) ++i;
      if (i > field_start) {
        line.fields.push_back(raw.substr(field_start, i - field_start));
        line.columns.push_back(static_cast<int>(field_start) + 1);
      }
    }
    lines.push_back(std::move(line));
    if (end == text.size()) break;
    start = end + 1;
  }
  return lines;
}

double micrometres_to_nm(std::string_view text, double um) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  if (text.empty() || text.find_first_not_of("0123456789.") != std::string_view::npos)
    return um * 1000.0;
  const std::size_t point = text.find('.');
  std::string integer(text.substr(0, point));
  std::string fraction = point == std::string_view::npos ? "" : std::string(text.substr(point + 1));
  while (fraction.size() < 3) fraction += '0';
  const std::string shifted = integer + fraction.substr(0, 3) + "." + fraction.substr(3) + "0";
  double nm = 0.0;
  const auto [end, ec] = std::from_chars(shifted.data(), shifted.data() + shifted.size(), nm);
  return ec == std::errc() ? nm : um * 1000.0;
}

std::string number_text(double x) {
  return fmt::format("{}", x);
}

std::string micrometre_text(double nm) {
  const std::string text = number_text(nm);
  if (text.find_first_of("eEn") != std::string::npos || text.front() == '-')
    return number_text(nm / 1000.0);
  const std::size_t point = text.find('.');
  std::string integer = text.substr(0, point);
  const std::string fraction = point == std::string::npos ? "" : text.substr(point + 1);
  if (integer.size() < 4) integer = std::string(4 - integer.size(), '0') + integer;
  std::string out = integer.substr(0, integer.size() - 3);
  std::string decimals = integer.substr(integer.size() - 3) + fraction;
  while (!decimals.empty() && decimals.back() == '0') decimals.pop_back();
  return decimals.empty() ? out : out + "." + decimals;
}

}  // namespace lensopt::zmx_detail
