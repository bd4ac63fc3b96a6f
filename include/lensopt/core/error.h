// Errors of lensopt. Numerical kernels never throw: a failed ray is a flag. Exceptions are
// for input and output only: a malformed file, an unknown glass, an unwritable path.
#pragma once

#include <stdexcept>
#include <string>

namespace lensopt {

// Where in an input file a problem is. line and column are 1-based; 0 means unknown.
struct SourceLocation {
  std::string file;
  int line = 0;
  int column = 0;

  // "file:line:column" with the unknown parts left out.
  std::string to_string() const;
};

// Bad input or an I/O failure. what() reads "file:line:column: message".
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message);
  Error(SourceLocation where, const std::string& message);

  const SourceLocation& where() const { return where_; }
  const std::string& message() const { return message_; }

 private:
  SourceLocation where_;
  std::string message_;
};

}  // namespace lensopt
