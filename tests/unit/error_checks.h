// Helpers of the unit tests that check error messages.
#pragma once

#include <doctest/doctest.h>

#include <string>

#include "lensopt/core/error.h"

namespace lensopt::test {

// The what() of the lensopt::Error that `f` throws ("" and a failed check if it throws none).
template <typename F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  FAIL_CHECK("no lensopt::Error was thrown");
  return "";
}

// Checks that `text` contains `part`, printing both when it does not.
inline void check_contains(const std::string& text, const std::string& part) {
  CHECK_MESSAGE(text.find(part) != std::string::npos, "'", part, "' not in: ", text);
}

}  // namespace lensopt::test
