// Text decoding shared by the readers of vendor files (AGF catalogs, Zemax .zmx lenses), which
// OpticStudio writes as UTF-16 LE with a byte-order mark or as ASCII / UTF-8.
//
// UTF-16: a code unit u outside [0xD800, 0xDFFF] is the code point u; a surrogate pair (hi, lo)
// is 0x10000 + ((hi - 0xD800) << 10) + (lo - 0xDC00); an unpaired surrogate becomes U+FFFD.
#pragma once

#include <string>
#include <string_view>

namespace lensopt {

// UTF-16 bytes (without a byte-order mark) as UTF-8; a trailing odd byte is dropped.
std::string utf16_to_utf8(std::string_view bytes, bool little_endian);

// A file's bytes as UTF-8 text: UTF-16 LE or BE with a BOM is converted, a UTF-8 BOM dropped,
// anything else returned as is. Line ends are left alone (CRLF stays CRLF).
std::string decode_text(std::string_view bytes);

}  // namespace lensopt
