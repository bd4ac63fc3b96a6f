// lensopt bench: the foundation's performance figures on the Tessar at full paper sampling.
#include <fmt/core.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <memory>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "lensopt/analysis/gradient.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/analysis/spot_adjoint.h"
#include "lensopt/analysis/wave.h"
#include "lensopt/core/threads.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/joint/imaging.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/render/chart.h"

namespace lensopt::cli {
namespace {

struct BenchCommand {
  std::string lens_path = std::string(LENSOPT_SOURCE_DIR) + "/lenses/tessar.toml";
  bool json = false;
  int repeats = 20;
  int threads = 0;
  bool joint_imaging = false;  // the joint optimization's differentiable imaging instead
  int rings = 8;               // its PSF sampling
  bool aspherize = false;      // every curved surface made an even asphere (issue 16)
  bool wave = false;           // the polychromatic diffraction MTF instead (issue 17)
  int pupil_samples = 128;     // its pupil grid
};

// Process CPU time (all threads), ms: on a shared machine the wall time depends on the load.
double cpu_now_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

// Median wall time (ms) of `repeats` runs of f; `cpu_ms` (if given) gets the median CPU time.
// Gives every curved surface a conic and a4..a16 terms small enough to keep the optics close to
// the spherical lens's (sag change at the 40 % of the radius height below 1 um), so that the
// benchmark times the asphere's Newton intersection on every surface.
Lens aspherized(Lens lens) {
  for (Surface& s : lens.surfaces) {
    if (s.is_stop || s.curvature_per_mm == 0.0) continue;
    s.conic = -0.05;
    double h = 0.4 / std::abs(s.curvature_per_mm);
    for (int j = 0; j < kAsphereOrders; ++j)
      s.asphere[j] = (j % 2 ? -1.0 : 1.0) * 1e-4 / std::pow(h, 2 * j + 4);
  }
  return lens;
}

template <typename F>
double median_ms(int repeats, F&& f, double* cpu_ms = nullptr) {
  std::vector<double> times, cpu;
  for (int i = 0; i < repeats; ++i) {
    const double c0 = cpu_now_ms();
    const auto start = std::chrono::steady_clock::now();
    f();
    const auto stop = std::chrono::steady_clock::now();
    cpu.push_back(cpu_now_ms() - c0);
    times.push_back(std::chrono::duration<double, std::milli>(stop - start).count());
  }
  std::sort(times.begin(), times.end());
  std::sort(cpu.begin(), cpu.end());
  if (cpu_ms) *cpu_ms = cpu[cpu.size() / 2];
  return times[times.size() / 2];
}

void run_bench(const BenchCommand& cmd) {
  const Lens spherical = read_lens(cmd.lens_path);
  const Lens lens = cmd.aspherize ? aspherized(spherical) : spherical;
  TraceOptions options;  // the paper's sampling, ray aiming on
  options.threads = cmd.threads;
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  // The spherical lens's variables, so that --aspherize times the same gradient.
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(spherical);

  double mean_spot_um = 0;
  double eval_cpu_ms = 0, grad_cpu_ms = 0, adjoint_cpu_ms = 0;
  const double eval_ms = median_ms(
      cmd.repeats,
      [&] {
        const TraceSystem<double> sys = prepare_system(trace_lens, lens.specs, options);
        mean_spot_um = evaluate_spots(sys, options.threads).mean_rms_spot_mm * 1000.0;
      },
      &eval_cpu_ms);
  SpotGradient gradient;
  const double grad_ms = median_ms(
      std::max(1, cmd.repeats / 10),
      [&] { gradient = mean_spot_gradient_auto(trace_lens, lens.specs, variables, options); },
      &grad_cpu_ms);
  // The adjoint (reverse-mode) gradient, and its largest relative difference from the Jets.
  SpotGradient adjoint;
  const double adjoint_ms = median_ms(
      cmd.repeats,
      [&] { adjoint = mean_spot_gradient_fast(trace_lens, lens.specs, variables, options); },
      &adjoint_cpu_ms);
  double largest = 0, adjoint_difference = 0;
  for (double d : gradient.gradient) largest = std::max(largest, std::abs(d));
  for (std::size_t i = 0; i < variables.size(); ++i)
    adjoint_difference =
        std::max(adjoint_difference, std::abs(adjoint.gradient[i] - gradient.gradient[i]) /
                                         std::max(std::abs(gradient.gradient[i]), 1e-6 * largest));
  // The lens design loss l_lens at the optimizer's sampling (8 rings x 11 fields, the
  // constraint rays at 21 fields): its gradient by Jets (before issue 18) and by the adjoint.
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions design_sampling;
  design_sampling.rings = 8;
  design_sampling.fields = 11;
  design_sampling.threads = cmd.threads;
  double design_jets_cpu_ms = 0, design_adjoint_cpu_ms = 0;
  const double design_jets_ms = median_ms(
      std::max(1, cmd.repeats / 4),
      [&] { design_loss_gradient_jets(param, x, GlassMode::kQuantized, {}, design_sampling, {}); },
      &design_jets_cpu_ms);
  const double design_adjoint_ms = median_ms(
      cmd.repeats,
      [&] { design_loss_gradient(param, x, GlassMode::kQuantized, {}, design_sampling, {}); },
      &design_adjoint_cpu_ms);
  const TraceSystem<double> sys = prepare_system(trace_lens, lens.specs, options);
  const double rays = static_cast<double>(sys.fields_deg.size()) * sys.wavelength_count *
                      static_cast<double>(sys.pupil.size());
  const double ray_surfaces_per_s = rays * lens.surfaces.size() / (eval_ms / 1000.0);
  const int threads = thread_count(cmd.threads);
  if (cmd.json) {
    nlohmann::json j;
    j["lens"] = lens.name;
    j["aspherized"] = cmd.aspherize;
    j["threads"] = threads;
    j["rays"] = rays;
    j["surfaces"] = lens.surfaces.size();
    j["variables"] = variables.size();
    j["mean_rms_spot_um"] = mean_spot_um;
    j["spot_eval_ms"] = eval_ms;
    j["spot_grad_ms"] = grad_ms;
    j["spot_grad_adjoint_ms"] = adjoint_ms;
    j["design_grad_jets_ms"] = design_jets_ms;
    j["design_grad_adjoint_ms"] = design_adjoint_ms;
    j["design_grad_jets_cpu_ms"] = design_jets_cpu_ms;
    j["design_grad_adjoint_cpu_ms"] = design_adjoint_cpu_ms;
    j["spot_eval_cpu_ms"] = eval_cpu_ms;
    j["spot_grad_cpu_ms"] = grad_cpu_ms;
    j["spot_grad_adjoint_cpu_ms"] = adjoint_cpu_ms;
    j["adjoint_max_relative_difference"] = adjoint_difference;
    j["ray_surfaces_per_s"] = ray_surfaces_per_s;
    fmt::print("{}\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
  } else {
    fmt::print(
        "lensopt bench: {}{} ({} surfaces), {} fields x {} wavelengths x {} rays, ray aiming "
        "on, {} threads\n",
        lens.name, cmd.aspherize ? " aspherized" : "", lens.surfaces.size(), sys.fields_deg.size(),
        sys.wavelength_count, sys.pupil.size(), threads);
    fmt::print("  mean RMS spot                     {:10.3f} um\n", mean_spot_um);
    fmt::print("  spot evaluation (double)          {:10.2f} ms   (CPU {:.2f} ms; median of {})\n",
               eval_ms, eval_cpu_ms, cmd.repeats);
    fmt::print("  gradient, {} variables (Jets)     {:10.2f} ms   (CPU {:.2f} ms)\n",
               variables.size(), grad_ms, grad_cpu_ms);
    fmt::print(
        "  gradient, {} variables (adjoint)  {:10.2f} ms   (CPU {:.2f} ms; {:.1f}x the "
        "evaluation; max relative difference from the Jets {:.1e})\n",
        variables.size(), adjoint_ms, adjoint_cpu_ms, adjoint_ms / eval_ms, adjoint_difference);
    fmt::print(
        "  l_lens gradient, {} variables, 8 rings x 11 fields: Jets {:.2f} ms (CPU {:.2f}), "
        "adjoint {:.2f} ms (CPU {:.2f})\n",
        param.size(), design_jets_ms, design_jets_cpu_ms, design_adjoint_ms, design_adjoint_cpu_ms);
    fmt::print("  ray-surface intersections         {:10.3g} per s\n", ray_surfaces_per_s);
  }
}

// Joint imaging (issue 7): prepare() at 21 fields with `rings`, then render + backward of a batch
// of four 256 x 256 crops of a 1280 x 720 chart (quantized glasses, RI and distortion on).
void run_joint_imaging_bench(const BenchCommand& cmd) {
  const Lens lens = read_lens(cmd.lens_path);
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x = param.from_lens(lens);
  DifferentiableImagingOptions options;
  options.sampling.rings = cmd.rings;
  options.sampling.fields = 21;
  options.sampling.threads = cmd.threads;
  options.threads = cmd.threads;
  DifferentiableImaging imaging(param, GlassMode::kQuantized, {}, options);
  ChartOptions chart;
  chart.text = false;
  const FloatImage scene = make_test_chart(chart).image;
  const CropWindow crops[4] = {
      {0, 0, 256, 256}, {512, 232, 256, 256}, {1024, 464, 256, 256}, {300, 380, 256, 256}};
  std::vector<FloatImage> grads;
  for (const CropWindow& c : crops) {
    FloatImage g(c.width, c.height, scene.channels);
    for (std::size_t i = 0; i < g.pixels.size(); ++i)
      g.pixels[i] = static_cast<float>(std::sin(0.37 * static_cast<double>(i))) * 1e-3f;
    grads.push_back(std::move(g));
  }
  std::vector<double> trace_ms, psf_ms, render_ms, backward_ms, prepare_ms, step_ms, cpu_ms;
  imaging.prepare(x);  // warm-up (FFTW plans, allocations)
  for (int r = 0; r < cmd.repeats; ++r) {
    const double c0 = cpu_now_ms();
    const auto t0 = std::chrono::steady_clock::now();
    imaging.prepare(x);
    const auto t1 = std::chrono::steady_clock::now();
    trace_ms.push_back(imaging.timings().trace_s * 1000.0);
    psf_ms.push_back(imaging.timings().psf_s * 1000.0);
    std::vector<double> grad_x;
    double render_total = 0, backward_total = 0;
    for (int i = 0; i < 4; ++i) {
      const FloatImage out = imaging.render(scene, crops[i]);
      render_total += imaging.timings().render_s;
      imaging.backward(scene, crops[i], grads[i], grad_x);
      backward_total += imaging.timings().adjoint_s;
    }
    const auto t2 = std::chrono::steady_clock::now();
    prepare_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    render_ms.push_back(render_total * 1000.0);
    backward_ms.push_back(backward_total * 1000.0);
    step_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t0).count());
    cpu_ms.push_back(cpu_now_ms() - c0);
  }
  std::vector<double> values_ms;  // prepare(x, false): values only, for evaluation
  for (int r = 0; r < cmd.repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    imaging.prepare(x, false);
    values_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  const int threads = thread_count(cmd.threads);
  if (cmd.json) {
    nlohmann::json j;
    j["lens"] = lens.name;
    j["variables"] = param.size();
    j["rings"] = cmd.rings;
    j["fields"] = 21;
    j["threads"] = threads;
    j["prepare_ms"] = median(prepare_ms);
    j["trace_ms"] = median(trace_ms);
    j["psf_ms"] = median(psf_ms);
    j["prepare_values_only_ms"] = median(values_ms);
    j["render_4_crops_ms"] = median(render_ms);
    j["backward_4_crops_ms"] = median(backward_ms);
    j["step_ms"] = median(step_ms);
    j["step_cpu_ms"] = median(cpu_ms);
    fmt::print("{}\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
  } else {
    fmt::print(
        "lensopt bench --joint-imaging: {} ({} variables), 21 fields x {} rings ({} rays "
        "per field and wavelength), {} threads, median of {}\n",
        lens.name, param.size(), cmd.rings, cmd.rings * cmd.rings, threads, cmd.repeats);
    fmt::print(
        "  prepare (Jets)                    {:10.1f} ms  (trace + RI {:.1f}, PSFs + "
        "kernels {:.1f})\n",
        median(prepare_ms), median(trace_ms), median(psf_ms));
    fmt::print("  prepare, values only (double)     {:10.1f} ms\n", median(values_ms));
    fmt::print("  render, 4 crops 256x256 of 1280x720 {:8.1f} ms\n", median(render_ms));
    fmt::print("  backward, 4 crops                 {:10.1f} ms\n", median(backward_ms));
    fmt::print("  whole imaging step                {:10.1f} ms  (CPU time {:.1f} ms)\n",
               median(step_ms), median(cpu_ms));
  }
}

// Wave optics (issue 17): the polychromatic diffraction MTF (tangential and sagittal, 0 to the
// cutoff in 20 steps) at 21 fields and 3 wavelengths (486.1, 587.6, 656.3 nm) on a
// pupil_samples^2 grid, FFT padding 2; system preparation (ray aiming) is timed separately.
void run_wave_bench(const BenchCommand& cmd) {
  Lens lens = read_lens(cmd.lens_path);
  lens.specs.wavelengths_nm = {486.13, 587.56, 656.27};
  lens.specs.wavelength_channels = {2, 1, 0};
  TraceOptions trace;
  trace.fields = 21;
  trace.threads = cmd.threads;
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  TraceSystem<double> sys;
  const double prepare_ms =
      median_ms(cmd.repeats, [&] { sys = prepare_system(trace_lens, lens.specs, trace); });
  WaveOptions options;
  options.pupil_samples = cmd.pupil_samples;
  options.geometric = false;
  options.threads = cmd.threads;
  const double cutoff = sys.epd_mm / sys.efl_mm / (486.13e-6);
  std::vector<double> freqs;
  for (int k = 0; k <= 20; ++k) freqs.push_back(cutoff * k / 20.0);
  WaveReport report;
  analyze_wave(sys, options, freqs);  // warm-up (FFTW plans)
  const double mtf_ms = median_ms(cmd.repeats, [&] { report = analyze_wave(sys, options, freqs); });
  const int threads = thread_count(cmd.threads);
  if (cmd.json) {
    nlohmann::json j;
    j["lens"] = lens.name;
    j["threads"] = threads;
    j["fields"] = sys.fields_deg.size();
    j["wavelengths"] = sys.wavelength_count;
    j["pupil_samples"] = report.pupil_samples;
    j["fft_n"] = report.fft_n;
    j["prepare_ms"] = prepare_ms;
    j["diffraction_mtf_ms"] = mtf_ms;
    j["mean_rms_wavefront_waves"] = report.mean_rms_waves;
    j["mean_strehl"] = report.mean_strehl;
    fmt::print("{}\n", j.dump(2));
  } else {
    fmt::print(
        "lensopt bench --wave: {}, {} fields x {} wavelengths, {} x {} pupil, FFT {} x {}, {} "
        "threads, median of {}\n",
        lens.name, sys.fields_deg.size(), sys.wavelength_count, report.pupil_samples,
        report.pupil_samples, report.fft_n, report.fft_n, threads, cmd.repeats);
    fmt::print("  system preparation (ray aiming)   {:10.2f} ms\n", prepare_ms);
    fmt::print("  polychromatic diffraction MTF     {:10.2f} ms  (T and S, {} frequencies)\n",
               mtf_ms, freqs.size());
    fmt::print("  mean RMS wavefront {:.3f} waves, mean Strehl {:.4f}\n", report.mean_rms_waves,
               report.mean_strehl);
  }
}

}  // namespace

void setup_bench(CLI::App& app) {
  auto cmd = std::make_shared<BenchCommand>();
  CLI::App* sub = app.add_subcommand("bench", "Benchmark the tracer (Tessar, full sampling)");
  sub->add_option("--lens", cmd->lens_path, "lens to benchmark (default: lenses/tessar.toml)");
  sub->add_flag("--json", cmd->json,
                "JSON keys spot_eval_ms, spot_grad_ms, spot_grad_adjoint_ms, ray_surfaces_per_s");
  sub->add_option("--repeats", cmd->repeats, "repetitions (median reported)")
      ->check(CLI::Range(1, 10000));
  sub->add_option("--threads", cmd->threads, "threads (0: all cores)")->check(CLI::Range(0, 1024));
  sub->add_flag("--joint-imaging", cmd->joint_imaging,
                "benchmark the joint optimization's differentiable imaging instead (issue 7)");
  sub->add_flag("--aspherize", cmd->aspherize,
                "make every curved surface an even asphere (conic and a4..a16 terms) to time "
                "the asphere tracer");
  sub->add_option("--rings", cmd->rings, "PSF rings for --joint-imaging (default 8)")
      ->check(CLI::Range(1, 64));
  sub->add_flag("--wave", cmd->wave,
                "benchmark the polychromatic diffraction MTF instead (21 fields, 3 wavelengths)");
  sub->add_option("--pupil-samples", cmd->pupil_samples, "pupil grid for --wave (default 128)")
      ->check(CLI::Range(8, 1024));
  sub->callback([cmd] {
    if (cmd->wave) {
      run_wave_bench(*cmd);
    } else if (cmd->joint_imaging) {
      run_joint_imaging_bench(*cmd);
    } else {
      run_bench(*cmd);
    }
  });
}

}  // namespace lensopt::cli
