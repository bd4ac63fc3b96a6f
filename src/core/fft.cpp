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

FftPlans fft_plans(int ny, int nx) {
  static std::mutex planner_mutex;
  static std::map<std::pair<int, int>, FftPlans> cache;
  std::lock_guard<std::mutex> lock(planner_mutex);
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

}  // namespace lensopt
