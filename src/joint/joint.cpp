#include "lensopt/joint/joint.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <nlohmann/json.hpp>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/glass/glass.h"
#include "lensopt/optimize/design_gradient.h"

namespace lensopt {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr const char* kFixedFixed = "fixed/fixed";
constexpr const char* kFixedTrained = "fixed/trained";
constexpr const char* kJoint = "joint";
constexpr int kCheckpointVersion = 1;

// The per-step CSV, kept in memory and rewritten atomically (it is small).
class CsvLog {
 public:
  static std::string header(const LensParameterization& param) {
    std::string h =
        "phase,step,lr_lens,lr_task,loss_joint,loss_task,loss_lens,loss_spot_mm,loss_ray_path_mm,"
        "loss_ray_angle,loss_glass,mean_spot_um,failed_rays,grad_norm_task,grad_norm_lens";
    int m = 0;
    for (const LensVariable& v : param.variables())
      if (v.kind == LensVariable::Kind::kGlass0) h += fmt::format(",glass{}", ++m);
    return h + "\n";
  }
  CsvLog(std::filesystem::path path, std::string text)
      : path_(std::move(path)), text_(std::move(text)) {}
  void add(const std::string& row) { text_ += row + "\n"; }
  void flush() const {
    if (!path_.empty()) write_file_atomic(path_, text_);
  }
  const std::string& text() const { return text_; }

 private:
  std::filesystem::path path_;
  std::string text_;
};

std::string join_glasses(const LensParameterization& param, const std::vector<int>& glasses) {
  std::string out;
  for (int g : glasses) out += "," + param.glass_space().name(g);
  return out;
}

TaskBatch make_batch(const DifferentiableImaging& imaging, const JointData& data,
                     const std::vector<Sample>& samples) {
  TaskBatch batch;
  for (const Sample& s : samples) {
    const Scene& scene = data.scenes().at(s.scene);
    batch.rendered.push_back(imaging.render(scene.image, s.crop));
    batch.sharp.push_back(data.crop(s));
    batch.targets.push_back(scene.targets);
  }
  return batch;
}

// The task metric over the held-out crops (mean over crops), in batches of the batch size.
double evaluate(const DifferentiableImaging& imaging, Task& task, const JointData& data) {
  const std::vector<Sample>& all = data.eval_samples();
  const std::size_t b = static_cast<std::size_t>(data.options().batch_size);
  double sum = 0;
  for (std::size_t i = 0; i < all.size(); i += b) {
    const std::vector<Sample> part(all.begin() + i, all.begin() + std::min(all.size(), i + b));
    sum += task.metric(make_batch(imaging, data, part)) * static_cast<double>(part.size());
  }
  return sum / static_cast<double>(all.size());
}

double norm(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s);
}

nlohmann::json settings_json(const std::vector<JointSettingResult>& settings) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& s : settings)
    j.push_back({{"name", s.name},
                 {"metric", s.metric},
                 {"mean_spot_um", s.mean_spot_um},
                 {"done", s.done}});
  return j;
}

// Everything a resumed run needs.
struct Progress {
  std::string phase;
  int step = 0;  // next step of the phase
  std::vector<double> x, m, v;
  std::string rng;
  int steps_done = 0;
  bool task_state = false;  // task.pt belongs to this phase
};

}  // namespace

void JointOptions::validate() const {
  task_options.validate();
  data.validate();
  imaging.validate();
  design_sampling.validate();
  loss.validate();
  if (!(lambda_lens >= 0.0) || !std::isfinite(lambda_lens))
    throw Error(fmt::format("lambda_lens = {} must be finite and >= 0", lambda_lens));
  if (!(lens_learning_rate >= 0.0) || !std::isfinite(lens_learning_rate))
    throw Error(fmt::format("lens learning rate {} must be finite and >= 0", lens_learning_rate));
  if (constant_steps < 0 || decay_steps < 0 || total_steps() < 1)
    throw Error(fmt::format("steps: {} constant + {} decay; at least one step in all",
                            constant_steps, decay_steps));
  if (checkpoint_every < 0)
    throw Error(fmt::format("checkpoint interval {} must be >= 0", checkpoint_every));
  if (checkpoint_every > 0 && checkpoint_dir.empty())
    throw Error("checkpoints every N steps need a checkpoint directory");
  if (glass_mode == GlassMode::kFixed)
    throw Error("the joint optimization's glasses are quantized or continuous, not fixed");
}

double learning_rate_factor(int step, int constant_steps, int decay_steps) {
  if (step < constant_steps || decay_steps <= 0) return 1.0;
  const double t = std::min(1.0, static_cast<double>(step - constant_steps) / decay_steps);
  return 0.5 * (1.0 + std::cos(3.14159265358979323846 * t));
}

double task_loss_gradient(DifferentiableImaging& imaging, Task& task, const JointData& data,
                          const std::vector<Sample>& samples, const std::vector<double>& x,
                          std::vector<double>* grad_x) {
  imaging.prepare(x);
  const TaskBatch batch = make_batch(imaging, data, samples);
  const TaskOutput out = task.step(batch, false, grad_x != nullptr);
  if (grad_x) {
    grad_x->assign(x.size(), 0.0);
    for (std::size_t b = 0; b < samples.size(); ++b)
      imaging.backward(data.scenes().at(samples[b].scene).image, samples[b].crop,
                       out.grad_rendered.at(b), *grad_x);
  }
  return out.loss;
}

JointResult optimize_joint(const Lens& start, const JointOptions& options,
                           const std::filesystem::path& network_out) {
  options.validate();
  const auto clock_start = Clock::now();
  auto say = [&](const std::string& s) {
    if (options.verbose) fmt::print(stderr, "{}\n", s);
  };
  JointResult result;
  LensParameterization param(
      start, GlassSpace(*load_catalog(start.catalog_name.empty() ? "ohara" : start.catalog_name)));
  param.set_paraxial_image_solve(options.paraxial_image_solve);
  const GlassMode mode = options.glass_mode;
  const std::vector<double> x0 = param.from_lens(start);
  const int n = param.size();
  const std::vector<int> frozen = param.select(options.freeze);
  std::vector<char> is_frozen(n, 0);
  for (int i : frozen) is_frozen[i] = 1;

  JointData data(options.data);
  for (const std::string& note : data.notes()) {
    say("lensopt optimize --joint: " + note);
    result.notes.push_back(note);
  }
  DifferentiableImaging imaging(param, mode, {}, options.imaging);

  std::vector<std::string> phases;
  if (options.run_baselines) phases = {kFixedFixed, kFixedTrained};
  phases.push_back(kJoint);
  for (const std::string& p : phases) result.settings.push_back({p, 0, 0, false});

  // Resume.
  Progress progress{
      phases.front(), 0, x0, std::vector<double>(n, 0.0), std::vector<double>(n, 0.0), "", 0,
      false};
  CsvLog log(options.log_csv, CsvLog::header(param));
  std::filesystem::path resume_task;
  if (!options.resume_dir.empty()) {
    const std::filesystem::path file = options.resume_dir / "checkpoint.json";
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(read_file(file));
      if (j.at("version").get<int>() != kCheckpointVersion)
        throw Error(SourceLocation{file.string()}, "unsupported checkpoint version");
      if (j.at("variables").get<int>() != n || j.at("task").get<std::string>() != options.task ||
          j.at("phases").get<std::vector<std::string>>() != phases)
        throw Error(SourceLocation{file.string()},
                    "the checkpoint is of another lens structure, task or set of settings");
      progress.phase = j.at("phase").get<std::string>();
      progress.step = j.at("step").get<int>();
      progress.x = j.at("x").get<std::vector<double>>();
      progress.m = j.at("m").get<std::vector<double>>();
      progress.v = j.at("v").get<std::vector<double>>();
      progress.rng = j.at("rng").get<std::string>();
      progress.steps_done = j.at("steps_done").get<int>();
      progress.task_state = j.at("task_state").get<bool>();
      for (const auto& s : j.at("settings")) {
        for (auto& r : result.settings)
          if (r.name == s.at("name").get<std::string>()) {
            r.metric = s.at("metric").get<double>();
            r.mean_spot_um = s.at("mean_spot_um").get<double>();
            r.done = s.at("done").get<bool>();
          }
      }
      for (const auto& c : j.at("glass_changes"))
        result.glass_changes.push_back(
            {c.at("phase"), c.at("step"), c.at("element"), c.at("from"), c.at("to")});
    } catch (const nlohmann::json::exception& e) {
      throw Error(SourceLocation{file.string()}, fmt::format("corrupt checkpoint: {}", e.what()));
    }
    log = CsvLog(options.log_csv, read_file(options.resume_dir / "log.csv"));
    resume_task = options.resume_dir / "task.pt";
    say(fmt::format("lensopt optimize --joint: resuming {} at step {} from {}", progress.phase,
                    progress.step, options.resume_dir.string()));
  }

  const int total = options.total_steps();
  int steps_this_call = 0;
  auto stop_requested = [&] {
    return (options.interrupt && options.interrupt->load()) ||
           (options.stop_after_steps >= 0 && steps_this_call >= options.stop_after_steps);
  };
  const std::size_t first_phase =
      std::find(phases.begin(), phases.end(), progress.phase) - phases.begin();
  if (first_phase >= phases.size())
    throw Error(
        fmt::format("checkpoint phase '{}' is not among this run's settings", progress.phase));

  std::unique_ptr<Task> task;
  auto checkpoint = [&](const std::string& phase, int step, const std::vector<double>& x,
                        const std::vector<double>& m, const std::vector<double>& v) {
    if (options.checkpoint_every <= 0) return;
    const std::filesystem::path dir = options.checkpoint_dir;
    std::filesystem::create_directories(dir);
    if (task) task->save(dir / "task.pt");
    write_file_atomic(dir / "log.csv", log.text());
    nlohmann::json changes = nlohmann::json::array();
    for (const GlassChange& c : result.glass_changes)
      changes.push_back({{"phase", c.phase},
                         {"step", c.step},
                         {"element", c.element},
                         {"from", c.from},
                         {"to", c.to}});
    const nlohmann::json j = {{"version", kCheckpointVersion},
                              {"task", options.task},
                              {"phases", phases},
                              {"variables", n},
                              {"phase", phase},
                              {"step", step},
                              {"steps_done", result.steps_done},
                              {"x", x},
                              {"m", m},
                              {"v", v},
                              {"rng", data.rng_state()},
                              {"task_state", task != nullptr},
                              {"settings", settings_json(result.settings)},
                              {"glass_changes", changes}};
    write_file_atomic(dir / "checkpoint.json", j.dump(1));
  };

  result.steps_done = progress.steps_done;
  std::vector<double> x = x0;
  for (std::size_t pi = first_phase; pi < phases.size() && !result.interrupted; ++pi) {
    const std::string phase = phases[pi];
    const bool resumed = pi == first_phase && !options.resume_dir.empty();
    const bool train_lens = phase == kJoint;
    int t = resumed ? progress.step : 0;
    x = resumed ? progress.x : x0;
    std::vector<double> m = resumed ? progress.m : std::vector<double>(n, 0.0);
    std::vector<double> v = resumed ? progress.v : std::vector<double>(n, 0.0);
    task = make_task(options.task, options.task_options);
    data.restart();
    if (resumed) {
      if (progress.task_state) task->load(resume_task);
      if (!progress.rng.empty()) data.set_rng_state(progress.rng);
    }
    JointSettingResult& setting = result.settings[pi];
    if (!train_lens) imaging.prepare(x);  // a fixed lens is sampled once; a trained one per step
    DesignValueGradient design =
        design_loss_gradient(param, x, mode, {}, options.design_sampling, options.loss);
    std::vector<int> glasses = param.nearest_glasses(x.data());
    say(fmt::format("lensopt optimize --joint: {} (task {}, {} steps)", phase, task->name(),
                    phase == kFixedFixed ? 0 : total));
    if (phase != kFixedFixed) {
      while (t < total) {
        if (stop_requested()) {
          result.interrupted = true;
          break;
        }
        const auto step_start = Clock::now();
        const std::clock_t step_cpu_start = std::clock();
        const double factor = learning_rate_factor(t, options.constant_steps, options.decay_steps);
        const double lr_lens = train_lens ? options.lens_learning_rate * factor : 0.0;
        const double lr_task = options.task_options.learning_rate * factor;
        task->set_learning_rate(lr_task);
        const std::vector<Sample> samples = data.next_batch();
        if (train_lens) imaging.prepare(x);
        const auto render_start = Clock::now();
        const TaskBatch batch = make_batch(imaging, data, samples);
        const double render_s = seconds_since(render_start);
        const auto network_start = Clock::now();
        const TaskOutput out = task->step(batch, true, train_lens);
        const double network_s = seconds_since(network_start);
        const std::string row_glasses = join_glasses(param, glasses);
        std::vector<double> grad_task(n, 0.0), grad(n, 0.0);
        double adjoint_s = 0, design_s = 0;
        if (train_lens) {
          const auto adjoint_start = Clock::now();
          for (std::size_t b = 0; b < samples.size(); ++b)
            imaging.backward(data.scenes().at(samples[b].scene).image, samples[b].crop,
                             out.grad_rendered.at(b), grad_task);
          adjoint_s = seconds_since(adjoint_start);
          const auto design_start = Clock::now();
          design = design_loss_gradient(param, x, mode, {}, options.design_sampling, options.loss);
          design_s = seconds_since(design_start);
          bool finite = design.finite;
          for (int i = 0; i < n; ++i) {
            grad[i] = is_frozen[i] ? 0.0 : grad_task[i] + options.lambda_lens * design.gradient[i];
            finite = finite && std::isfinite(grad[i]);
          }
          if (!finite) {
            say(fmt::format("  {} step {}: non-finite gradient; lens update skipped", phase, t));
          } else {
            // Adam with bias correction (t + 1 updates so far).
            const double b1 = 0.9, b2 = 0.999, eps = 1e-8;
            const double c1 = 1.0 - std::pow(b1, t + 1), c2 = 1.0 - std::pow(b2, t + 1);
            for (int i = 0; i < n; ++i) {
              if (is_frozen[i]) continue;
              m[i] = b1 * m[i] + (1.0 - b1) * grad[i];
              v[i] = b2 * v[i] + (1.0 - b2) * grad[i] * grad[i];
              x[i] -= lr_lens * (m[i] / c1) / (std::sqrt(v[i] / c2) + eps);
            }
          }
          const std::vector<int> now = param.nearest_glasses(x.data());
          for (std::size_t e = 0; e < now.size(); ++e)
            if (now[e] != glasses[e]) {
              const GlassChange c{phase, t, static_cast<int>(e),
                                  param.glass_space().name(glasses[e]),
                                  param.glass_space().name(now[e])};
              result.glass_changes.push_back(c);
              say(fmt::format("  {} step {}: glass {} {} -> {}", phase, t, e + 1, c.from, c.to));
            }
          glasses = now;
        }
        // The row describes the lens the step's images came from and the losses at it.
        const double l_lens = design.loss.total;
        log.add(fmt::format(
            "{},{},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.6f},"
            "{},{:.10g},{:.10g}{}",
            phase, t, lr_lens, lr_task, out.loss + options.lambda_lens * l_lens, out.loss, l_lens,
            design.loss.spot_mm, design.loss.ray_path_mm, design.loss.ray_angle, design.loss.glass,
            design.loss.spot_mm * 1000.0, design.loss.failed_rays, norm(grad_task),
            norm(design.gradient), row_glasses));
        ++t;
        ++result.steps_done;
        ++steps_this_call;
        if (train_lens) {
          const ImagingTimings& it = imaging.timings();
          JointTimings& jt = result.timings;
          jt.trace_s += it.trace_s;
          jt.psf_s += it.psf_s;
          jt.render_s += render_s;
          jt.adjoint_s += adjoint_s;
          jt.network_s += network_s;
          jt.design_loss_s += design_s;
          jt.step_s += seconds_since(step_start);
          jt.step_cpu_s += static_cast<double>(std::clock() - step_cpu_start) / CLOCKS_PER_SEC;
          ++jt.steps;
        }
        if (options.verbose && (t % 10 == 0 || t == total))
          say(fmt::format("  {} step {}/{}: task loss {:.6g}, l_lens {:.6g}, mean spot {:.2f} um",
                          phase, t, total, out.loss, l_lens, design.loss.spot_mm * 1000.0));
        log.flush();  // the whole (small) log, atomically, every step
        if (options.checkpoint_every > 0 && t % options.checkpoint_every == 0 && t < total)
          checkpoint(phase, t, x, m, v);
      }
      log.flush();
      if (result.interrupted) {
        checkpoint(phase, t, x, m, v);
        break;
      }
    }
    // Score the setting on the held-out crops with the final lens and network.
    imaging.prepare(x);
    setting.metric = evaluate(imaging, *task, data);
    setting.mean_spot_um =
        design_loss_gradient(param, x, mode, {}, options.design_sampling, options.loss)
            .loss.spot_mm *
        1000.0;
    setting.done = true;
    say(fmt::format("lensopt optimize --joint: {}: held-out {} {:.4f}, mean spot {:.2f} um", phase,
                    task->metric_name(), setting.metric, setting.mean_spot_um));
    if (pi + 1 < phases.size()) {
      task.reset();  // the next phase starts a fresh network
      checkpoint(phases[pi + 1], 0, x0, std::vector<double>(n, 0.0), std::vector<double>(n, 0.0));
    }
  }
  if (result.timings.steps > 0) {
    JointTimings& jt = result.timings;
    const double s = jt.steps;
    jt.trace_s /= s;
    jt.psf_s /= s;
    jt.render_s /= s;
    jt.adjoint_s /= s;
    jt.network_s /= s;
    jt.design_loss_s /= s;
    jt.step_s /= s;
    jt.step_cpu_s /= s;
  }
  if (!network_out.empty() && task && !result.interrupted) task->save_network(network_out);
  result.metric_name = task ? task->metric_name() : "";
  result.x = x;
  result.lens = param.to_lens(x.data(), mode);
  for (int g : param.nearest_glasses(x.data()))
    result.glasses.push_back(param.glass_space().name(g));
  result.seconds = seconds_since(clock_start);
  return result;
}

}  // namespace lensopt
