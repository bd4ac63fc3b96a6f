// lensopt bench: the foundation's performance figures on the Tessar at full paper sampling.
#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <nlohmann/json.hpp>
#include <omp.h>

#include "commands.h"
#include "lensopt/analysis/gradient.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/lens/lens_io.h"

namespace lensopt::cli {
namespace {

struct BenchCommand {
  std::string lens_path = std::string(LENSOPT_SOURCE_DIR) + "/lenses/tessar.toml";
  bool json = false;
  int repeats = 20;
  int threads = 0;
};

template <typename F>
double median_ms(int repeats, F&& f) {
  std::vector<double> times;
  for (int i = 0; i < repeats; ++i) {
    const auto start = std::chrono::steady_clock::now();
    f();
    const auto stop = std::chrono::steady_clock::now();
    times.push_back(std::chrono::duration<double, std::milli>(stop - start).count());
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

void run_bench(const BenchCommand& cmd) {
  const Lens lens = read_lens(cmd.lens_path);
  TraceOptions options;  // the paper's sampling, ray aiming on
  options.threads = cmd.threads;
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);

  double mean_spot_um = 0;
  const double eval_ms = median_ms(cmd.repeats, [&] {
    const TraceSystem<double> sys = prepare_system(trace_lens, lens.specs, options);
    mean_spot_um = evaluate_spots(sys, options.threads).mean_rms_spot_mm * 1000.0;
  });
  SpotGradient gradient;
  const double grad_ms = median_ms(std::max(1, cmd.repeats / 10), [&] {
    gradient = mean_spot_gradient_auto(trace_lens, lens.specs, variables, options);
  });
  const TraceSystem<double> sys = prepare_system(trace_lens, lens.specs, options);
  const double rays = static_cast<double>(sys.fields_deg.size()) * sys.wavelength_count *
                      static_cast<double>(sys.pupil.size());
  const double ray_surfaces_per_s = rays * lens.surfaces.size() / (eval_ms / 1000.0);
  const int threads = cmd.threads > 0 ? cmd.threads : omp_get_max_threads();
  if (cmd.json) {
    nlohmann::json j;
    j["lens"] = lens.name;
    j["threads"] = threads;
    j["rays"] = rays;
    j["surfaces"] = lens.surfaces.size();
    j["variables"] = variables.size();
    j["mean_rms_spot_um"] = mean_spot_um;
    j["spot_eval_ms"] = eval_ms;
    j["spot_grad_ms"] = grad_ms;
    j["ray_surfaces_per_s"] = ray_surfaces_per_s;
    fmt::print("{}\n", j.dump(2));
  } else {
    fmt::print("lensopt bench: {} ({} surfaces), {} fields x {} wavelengths x {} rays, ray aiming "
               "on, {} threads\n",
               lens.name, lens.surfaces.size(), sys.fields_deg.size(), sys.wavelength_count,
               sys.pupil.size(), threads);
    fmt::print("  mean RMS spot                     {:10.3f} um\n", mean_spot_um);
    fmt::print("  spot evaluation (double)          {:10.2f} ms   (median of {})\n", eval_ms,
               cmd.repeats);
    fmt::print("  gradient, {} variables (Jets)     {:10.2f} ms\n", variables.size(), grad_ms);
    fmt::print("  ray-surface intersections         {:10.3g} per s\n", ray_surfaces_per_s);
  }
}

}  // namespace

void setup_bench(CLI::App& app) {
  auto cmd = std::make_shared<BenchCommand>();
  CLI::App* sub = app.add_subcommand("bench", "Benchmark the tracer (Tessar, full sampling)");
  sub->add_option("--lens", cmd->lens_path, "lens to benchmark (default: lenses/tessar.toml)");
  sub->add_flag("--json", cmd->json, "JSON keys spot_eval_ms, spot_grad_ms, ray_surfaces_per_s");
  sub->add_option("--repeats", cmd->repeats, "repetitions (median reported)")
      ->check(CLI::Range(1, 10000));
  sub->add_option("--threads", cmd->threads, "threads (0: all cores)")->check(CLI::Range(0, 1024));
  sub->callback([cmd] { run_bench(*cmd); });
}

}  // namespace lensopt::cli
