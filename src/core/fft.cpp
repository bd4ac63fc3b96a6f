// FFT sizes and the process-wide FFTW plan cache (core/fft.h).
#include "core/fft.h"

#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <mutex>
#include <utility>

#include "lensopt/core/error.h"

namespace lensopt {

int fft_size(int m) {
  for (int n = std::max(m, 1);; ++n) {
    int r = n;
    for (int p : {2, 3, 5, 7})
      while (r % p == 0) r /= p;
    if (r == 1) return n;
  }
}

namespace {

// FFTW's planner is not thread-safe: every plan of the process is made under this one lock (the
// real plans of the renderer and the complex plans of wave optics alike).
std::mutex& planner_mutex() {
  static std::mutex mutex;
  return mutex;
}

}  // namespace

FftPlans fft_plans(int ny, int nx) {
  static std::map<std::pair<int, int>, FftPlans> cache;
  std::lock_guard<std::mutex> lock(planner_mutex());
  auto it = cache.find({ny, nx});
  if (it != cache.end()) return it->second;
  RealBuffer real(static_cast<std::size_t>(ny) * nx);
  ComplexBuffer spectrum(static_cast<std::size_t>(ny) * (nx / 2 + 1));
  FftPlans plans;
  // FFTW_ESTIMATE: planning costs microseconds and does not touch the arrays.
  plans.forward = fftw_plan_dft_r2c_2d(ny, nx, real.data, spectrum.data, FFTW_ESTIMATE);
  plans.backward = fftw_plan_dft_c2r_2d(ny, nx, spectrum.data, real.data, FFTW_ESTIMATE);
  if (!plans.forward || !plans.backward) throw Error(fmt::format("FFTW cannot plan {}x{}", ny, nx));
  cache.emplace(std::make_pair(ny, nx), plans);
  return plans;
}

fftw_plan complex_fft_plan(int m) {
  static std::map<int, fftw_plan> cache;
  std::lock_guard<std::mutex> lock(planner_mutex());
  auto it = cache.find(m);
  if (it != cache.end()) return it->second;
  ComplexBuffer buffer(static_cast<std::size_t>(m) * m);
  fftw_plan plan = fftw_plan_dft_2d(m, m, buffer.data, buffer.data, FFTW_FORWARD, FFTW_ESTIMATE);
  if (!plan) throw Error(fmt::format("FFTW cannot plan {}x{}", m, m));
  cache.emplace(m, plan);
  return plan;
}

}  // namespace lensopt
