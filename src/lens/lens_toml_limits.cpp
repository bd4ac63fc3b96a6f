// The lexical pre-scan of TOML text (lens/input_limits.h): nesting depth and dotted-key length,
// counted before toml++ descends into them.
//
// Outside strings and comments, '[' and '{' open a level and ']' and '}' close one; a table
// header [[a]] counts its two brackets, so a file's depth is at most its deepest value plus two.
// A dotted key is a run of '.' not interrupted by '=', ',', a bracket or a line end: a key's
// parts are separated by dots (whitespace and quoted parts may stand between them), while a
// value holds at most one dot outside strings (a float, a time's fraction), so any run of more
// than one dot is a key. Strings are skipped by TOML's rules: basic "..." with backslash escapes,
// literal '...', and their multi-line forms """...""" and '''...''', whose closing delimiter may
// be followed by up to two more quotes that belong to the string.
#include <fmt/format.h>

#include "lensopt/core/error.h"
#include "lensopt/lens/input_limits.h"

namespace lensopt {

namespace {

class TomlScan {
 public:
  TomlScan(std::string_view text, const std::string& file) : text_(text), file_(file) {}

  void run() {
    const std::size_t n = text_.size();
    std::size_t i = 0;
    int depth = 0;
    int dots = 0;
    while (i < n) {
      const char c = text_[i];
      switch (c) {
        case '\n':
          new_line(i);
          dots = 0;
          ++i;
          break;
        case '#':
          while (i < n && text_[i] != '\n') ++i;
          break;
        case '"':
        case '\'':
          i = skip_string(i);
          break;
        case '[':
        case '{':
          if (++depth > kMaxTomlNesting)
            fail(i, fmt::format("the arrays, tables and inline tables nest more than {} levels "
                                "deep here; lensopt reads at most {} (no lens file needs more)",
                                kMaxTomlNesting, kMaxTomlNesting));
          dots = 0;
          ++i;
          break;
        case ']':
        case '}':
          if (depth > 0) --depth;
          dots = 0;
          ++i;
          break;
        case '=':
        case ',':
          dots = 0;
          ++i;
          break;
        case '.':
          if (++dots >= kMaxTomlKeyParts)
            fail(i, fmt::format("a dotted key of more than {} parts; lensopt reads at most {} "
                                "(no lens file needs more)",
                                kMaxTomlKeyParts, kMaxTomlKeyParts));
          ++i;
          break;
        default:
          ++i;
      }
    }
  }

 private:
  void new_line(std::size_t newline_at) {
    ++line_;
    line_start_ = newline_at + 1;
  }

  [[noreturn]] void fail(std::size_t at, const std::string& message) const {
    throw Error(SourceLocation{file_, line_, static_cast<int>(at - line_start_) + 1}, message);
  }

  bool three(std::size_t i, char q) const {
    return i + 2 < text_.size() && text_[i] == q && text_[i + 1] == q && text_[i + 2] == q;
  }

  // The position after the string that opens at i (a quote). An unterminated single-line string
  // ends before its line end (the parser reports it).
  std::size_t skip_string(std::size_t i) {
    const std::size_t n = text_.size();
    const char q = text_[i];
    const bool basic = q == '"';
    if (three(i, q)) {
      i += 3;
      while (i < n) {
        const char c = text_[i];
        if (basic && c == '\\') {
          if (i + 1 < n && text_[i + 1] == '\n') new_line(i + 1);
          i += 2;
          continue;
        }
        if (c == '\n') {
          new_line(i);
          ++i;
          continue;
        }
        if (three(i, q)) {
          std::size_t k = i;
          while (k < n && k < i + 5 && text_[k] == q) ++k;
          return k;
        }
        ++i;
      }
      return n;
    }
    ++i;
    while (i < n) {
      const char c = text_[i];
      if (c == '\n') return i;
      if (basic && c == '\\') {
        if (i + 1 < n && text_[i + 1] == '\n') return i + 1;
        i += 2;
        continue;
      }
      ++i;
      if (c == q) return i;
    }
    return n;
  }

  std::string_view text_;
  const std::string& file_;
  int line_ = 1;
  std::size_t line_start_ = 0;
};

}  // namespace

void check_toml_nesting(std::string_view text, const std::string& source_name) {
  TomlScan(text, source_name).run();
}

}  // namespace lensopt
