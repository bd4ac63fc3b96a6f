// InterruptScope (core/interrupt.h).
#include "lensopt/core/interrupt.h"

#include <csignal>

namespace lensopt {
namespace {

std::atomic<bool> g_interrupted{false};
static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs a lock-free flag");

extern "C" void on_interrupt_signal(int) {
  g_interrupted.store(true);
}

}  // namespace

InterruptScope::InterruptScope(Signals signals)
    : terminate_(signals == Signals::kInterruptAndTerminate) {
  g_interrupted.store(false);
  previous_int_ = std::signal(SIGINT, on_interrupt_signal);
  if (terminate_) previous_term_ = std::signal(SIGTERM, on_interrupt_signal);
}

InterruptScope::~InterruptScope() {
  std::signal(SIGINT, previous_int_ == SIG_ERR ? SIG_DFL : previous_int_);
  if (terminate_) std::signal(SIGTERM, previous_term_ == SIG_ERR ? SIG_DFL : previous_term_);
}

bool InterruptScope::interrupted() const {
  return g_interrupted.load();
}

const std::atomic<bool>* InterruptScope::flag() const {
  return &g_interrupted;
}

}  // namespace lensopt
