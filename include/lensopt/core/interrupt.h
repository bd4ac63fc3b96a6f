// SIGINT / SIGTERM as a request to stop, for the long runs (optimize, search, joint, render).
//
// While an InterruptScope lives, both signals set one process-wide flag instead of ending the
// process; the run polls it (interrupted(), or the flag itself handed to an options struct as
// `const std::atomic<bool>*`), stops at its next safe point and writes what it has. The scope
// clears the flag when it starts and restores the previous handlers when it ends (also when the
// run throws). One scope at a time: a nested scope shares the flag and restores the outer
// scope's handlers at its end. The Python bindings take SIGINT only (Ctrl-C stops the call and
// returns what it has; SIGTERM keeps ending the interpreter).
#pragma once

#include <atomic>

namespace lensopt {

class InterruptScope {
 public:
  enum class Signals { kInterruptAndTerminate, kInterruptOnly };
  explicit InterruptScope(Signals signals = Signals::kInterruptAndTerminate);
  ~InterruptScope();
  InterruptScope(const InterruptScope&) = delete;
  InterruptScope& operator=(const InterruptScope&) = delete;

  // Whether SIGINT or SIGTERM arrived since the scope began.
  bool interrupted() const;
  // The flag itself (set by the handler), for options structs that poll it.
  const std::atomic<bool>* flag() const;

 private:
  using Handler = void (*)(int);
  bool terminate_;
  Handler previous_int_;
  Handler previous_term_ = nullptr;
};

}  // namespace lensopt
