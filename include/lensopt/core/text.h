// Text decoding shared by the readers of vendor files (AGF catalogs, Zemax .zmx lenses), which
// OpticStudio writes as UTF-16 LE with a byte-order mark, as ASCII / UTF-8, or as ISO-8859-1
// (Latin-1, e.g. a lens NAME with an "é" or a glass name with a "ö").
//
// Detection, in order: a UTF-16 LE / BE byte-order mark -> UTF-16; a UTF-8 BOM -> UTF-8; bytes
// that are valid UTF-8 -> UTF-8; anything else -> ISO-8859-1 (every byte is the code point of its
// value). The result is always valid UTF-8, so no JSON writer can fail on it.
//
// UTF-16: a code unit u outside [0xD800, 0xDFFF] is the code point u; a surrogate pair (hi, lo)
// is 0x10000 + ((hi - 0xD800) << 10) + (lo - 0xDC00); an unpaired surrogate becomes U+FFFD.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>

namespace lensopt {

// UTF-16 bytes (without a byte-order mark) as UTF-8; a trailing odd byte is dropped.
std::string utf16_to_utf8(std::string_view bytes, bool little_endian);

// A file's bytes as UTF-8 text: UTF-16 LE or BE with a BOM is converted, a UTF-8 BOM dropped,
// valid UTF-8 returned as is, anything else read as ISO-8859-1. Line ends are left alone.
std::string decode_text(std::string_view bytes);

// Whether `bytes` is well-formed UTF-8 (no overlong forms, surrogates or code points > U+10FFFF).
bool is_valid_utf8(std::string_view bytes);

// ISO-8859-1 bytes as UTF-8.
std::string latin1_to_utf8(std::string_view bytes);

// `bytes` if it is valid UTF-8, else read as ISO-8859-1 (for names and paths shown or written).
std::string to_valid_utf8(std::string_view bytes);

// Levenshtein distance d(a, b): the fewest single-character insertions, deletions and
// substitutions turning a into b (byte-wise, case-sensitive), by the recurrence
//   d(i, j) = min(d(i-1, j) + 1, d(i, j-1) + 1, d(i-1, j-1) + [a_i != b_j]).
// For "did you mean" suggestions (lens keys, glass names).
std::size_t edit_distance(std::string_view a, std::string_view b);

// ASCII letters in lower case (other bytes unchanged).
std::string to_lower(std::string_view text);

// A path's extension in lower case, with its dot (".zmx", ".png"; "" when it has none): the key of
// every choice of file format by name.
std::string lower_extension(const std::filesystem::path& path);

}  // namespace lensopt
