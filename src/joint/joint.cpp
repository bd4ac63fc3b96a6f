#include "lensopt/joint/joint.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <map>
#include <nlohmann/json.hpp>
#include <utility>

#include "core/json_number.h"
#include "lensopt/core/adam.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/detection/crop_boxes.h"
#include "lensopt/glass/glass.h"
#include "lensopt/joint/detector.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/render/metrics.h"
#include "lensopt/render/render.h"

namespace lensopt {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr const char* kPerfect = "perfect";
constexpr const char* kFixedFixed = "fixed/fixed";
constexpr const char* kFixedTrained = "fixed/trained";
constexpr const char* kJoint = "joint";
constexpr int kCheckpointVersion = 2;  // 2: perfect optics trains base + continuation

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

// A number read back (null, written by finite_or_null for NaN, reads as NaN).
double number_of(const nlohmann::json& j, const char* key) {
  const auto it = j.find(key);
  return it != j.end() && it->is_number() ? it->get<double>() : NAN;
}

nlohmann::json settings_json(const std::vector<JointSettingResult>& settings) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& s : settings) {
    nlohmann::json per_category = nlohmann::json::array();
    for (const JointSettingResult::CategoryAp& c : s.ap_per_category)
      per_category.push_back(
          {{"category_id", c.category_id}, {"name", c.name}, {"ap", finite_or_null(c.ap)}});
    j.push_back({{"name", s.name},
                 {"metric", finite_or_null(s.metric)},
                 {"mean_spot_um", finite_or_null(s.mean_spot_um)},
                 {"ap50", finite_or_null(s.ap50)},
                 {"ap75", finite_or_null(s.ap75)},
                 {"psnr_db", finite_or_null(s.psnr_db)},
                 {"ssim", finite_or_null(s.ssim)},
                 {"ap_per_category", per_category},
                 {"done", s.done}});
  }
  return j;
}

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
  if (perfect_steps < 0)
    throw Error(fmt::format("perfect-optics steps {} must be >= 0", perfect_steps));
  if (checkpoint_every > 0 && checkpoint_dir.empty())
    throw Error("checkpoints every N steps need a checkpoint directory");
  if (glass_mode == GlassMode::kFixed)
    throw Error("the joint optimization's glasses are quantized or continuous, not fixed");
  if (task == "detection" && data.annotations.empty())
    throw Error(
        "the detection task needs a detection dataset (COCO or BDD100K annotations: --data)");
  if (task == "detection" && data.crop_px % 16 != 0)
    throw Error(
        fmt::format("the built-in detector needs crops whose side is a multiple of 16 "
                    "(crop {} px)",
                    data.crop_px));
  if (!pretrained_task.empty() && !std::filesystem::is_regular_file(pretrained_task))
    throw Error(SourceLocation{pretrained_task.string()}, "no such detector state file");
}

double learning_rate_factor(int step, int constant_steps, int decay_steps) {
  if (step < constant_steps || decay_steps <= 0) return 1.0;
  const double t = std::min(1.0, static_cast<double>(step - constant_steps) / decay_steps);
  return 0.5 * (1.0 + std::cos(kPi * t));
}

double task_loss_gradient(DifferentiableImaging& imaging, Task& task, const JointData& data,
                          const std::vector<Sample>& samples, const std::vector<double>& x,
                          std::vector<double>* grad_x,
                          const std::vector<std::vector<GroundTruth>>& boxes) {
  imaging.prepare(x);
  TaskBatch batch = make_batch(imaging, data, samples);
  batch.boxes = boxes;
  const TaskOutput out = task.step(batch, false, grad_x != nullptr);
  if (grad_x) {
    grad_x->assign(x.size(), 0.0);
    for (std::size_t b = 0; b < samples.size(); ++b)
      imaging.backward(data.scenes().at(samples[b].scene).image, samples[b].crop,
                       out.grad_rendered.at(b), *grad_x);
  }
  return out.loss;
}

namespace {

// The lens state before the last Adam update: what a failed step reverts to (as Ceres rejects
// an infeasible point and shrinks its trust region), and the factor on the lens learning rate:
// halved by every failed step, doubled (up to 1) by every successful one.
struct LensSafeguard {
  bool valid = false;  // a successful update exists to revert
  std::vector<double> x, m, v;
  double step_scale = 1.0;
  int consecutive_failures = 0;
};

// Failed steps in a row after which the run gives up (the lens cannot be imaged near here).
constexpr int kMaxConsecutiveFailures = 8;

// Where a phase starts: its step, lens, Adam moments, and the task's and crop stream's state.
struct Progress {
  std::string phase;
  int step = 0;  // next step of the phase
  std::vector<double> x;
  AdamMoments moments;
  LensSafeguard safeguard;
  std::string rng;
  int steps_done = 0;
  bool task_state = false;  // task.pt belongs to this phase
};

// The measurements of one step, for the CSV row and the timings.
struct StepRecord {
  TaskOutput out;
  std::vector<double> grad_task;
  double render_s = 0, network_s = 0, adjoint_s = 0, design_s = 0;
};

// The lens variables of the run (the start's catalog, or OHARA).
LensParameterization parameterization(const Lens& start, const JointOptions& options) {
  LensParameterization param(
      start, GlassSpace(*load_catalog(start.catalog_name.empty() ? "ohara" : start.catalog_name)));
  param.set_paraxial_image_solve(options.paraxial_image_solve);
  return param;
}

// One call of optimize_joint: its settings run in turn, each as a sequence of steps.
class JointRun {
 public:
  JointRun(const Lens& start, const JointOptions& options)
      : options_(options),
        param_(parameterization(start, options)),
        data_(options.data),
        imaging_(param_, options.glass_mode, {}, options.imaging),
        log_(options.log_csv, CsvLog::header(param_)),
        detection_(data_.detection()),
        sensor_diagonal_mm_(param_.structure().specs.sensor_diagonal_mm) {
    x0_ = param_.from_lens(start);
    n_ = param_.size();
    is_frozen_.assign(n_, 0);
    // The lens file's vary flags, pickups and solves, then --freeze (optimize/variables.h).
    const VariableChoice choice = choose_variables(param_, options.freeze, {}, false);
    for (int i : choice.held) is_frozen_[i] = 1;
    if (start.has_vary_flags() || start.has_solves())
      for (const std::string& line : choice.report) say("lensopt optimize --joint: " + line);
    for (const std::string& note : data_.notes()) {
      say("lensopt optimize --joint: " + note);
      result_.notes.push_back(note);
    }
    if (detection_) {
      phases_.push_back(kPerfect);
      check_categories();
      DifferentiableImagingOptions quality = options.imaging;
      quality.distortion = false;
      quality.relative_illumination = false;
      quality_imaging_ = std::make_unique<DifferentiableImaging>(param_, options.glass_mode,
                                                                 std::vector<int>{}, quality);
      const std::filesystem::path dir =
          options.checkpoint_every > 0 ? options.checkpoint_dir : temporary_dir();
      perfect_path_ = dir / "perfect.pt";
      base_path_ = dir / "perfect-base.pt";
    }
    if (options.run_baselines) {
      phases_.push_back(kFixedFixed);
      phases_.push_back(kFixedTrained);
    }
    phases_.push_back(kJoint);
    for (const std::string& p : phases_) {
      JointSettingResult r;
      r.name = p;
      result_.settings.push_back(r);
    }
  }
  ~JointRun() {
    std::error_code ec;
    if (!temp_dir_.empty()) std::filesystem::remove_all(temp_dir_, ec);
  }
  JointRun(const JointRun&) = delete;
  JointRun& operator=(const JointRun&) = delete;

  JointResult run(const std::filesystem::path& network_out);

 private:
  void say(const std::string& s) const {
    if (options_.verbose) fmt::print(stderr, "{}\n", s);
  }
  bool stop_requested() const {
    return (options_.interrupt && options_.interrupt->load()) ||
           (options_.stop_after_steps >= 0 && steps_this_call_ >= options_.stop_after_steps);
  }
  std::unique_ptr<Task> new_task() const {
    return options_.task_factory ? options_.task_factory(options_.task, options_.task_options)
                                 : make_task(options_.task, options_.task_options);
  }
  Progress start_progress() const {
    return {phases_.front(), 0, x0_, AdamMoments(n_), {}, "", 0, false};
  }
  Progress read_checkpoint(const std::filesystem::path& dir);
  void write_checkpoint(const std::string& phase, int step, const std::vector<double>& x,
                        const AdamMoments& moments, const LensSafeguard& safeguard);
  // Runs phase `pi` from `progress` (its step, lens, moments); false if interrupted.
  bool run_phase(std::size_t pi, Progress progress, bool resumed);
  // The images, the task's step and (training the lens) the gradient of step t; throws Error on
  // any failure (an exception, a non-finite loss or gradient).
  StepRecord step_gradient(const std::string& phase, int t, bool train_lens,
                           const std::vector<double>& x, std::vector<double>& grad);
  void log_glass_changes(const std::string& phase, int t, std::vector<int>& glasses,
                         const std::vector<double>& x);
  void add_timings(const StepRecord& r, Clock::time_point step_start, std::clock_t cpu_start);
  void score_setting(std::size_t pi, const std::vector<double>& x);
  void score_detection(JointSettingResult& setting, bool perfect, const std::vector<double>& x);
  void finish_timings();
  // Samples the lens (imaging_.prepare) and forgets the box distortions of the previous lens.
  void prepare(const std::vector<double>& x) {
    imaging_.prepare(x);
    distortions_.clear();
  }
  // The distortion of boxes in a scene of this size at the prepared lens (null: not rendered).
  const BoxDistortion* distortion_for(const FloatImage& scene, bool perfect);
  // The task's batch of samples: the lens's images (or, for perfect optics, the sharp crops)
  // and, with detection, the boxes as the images show them.
  TaskBatch batch_of(const std::vector<Sample>& samples, bool perfect);
  // The built-in detector's classes hold the dataset's categories (Error naming the first not).
  void check_categories() const;
  // A folder of this run for the perfect-optics detector when there are no checkpoints.
  std::filesystem::path temporary_dir();

  const JointOptions& options_;
  LensParameterization param_;
  JointData data_;
  DifferentiableImaging imaging_;
  CsvLog log_;
  std::vector<double> x0_;
  int n_ = 0;
  std::vector<char> is_frozen_;
  std::vector<std::string> phases_;
  JointResult result_;
  std::unique_ptr<Task> task_;
  std::filesystem::path resume_task_;
  DesignValueGradient design_;  // l_lens at the lens of the last step
  int steps_this_call_ = 0;
  bool detection_ = false;
  double sensor_diagonal_mm_ = 0;
  std::unique_ptr<DifferentiableImaging> quality_imaging_;    // detection: PSNR and SSIM
  std::map<std::pair<int, int>, BoxDistortion> distortions_;  // by scene size
  std::filesystem::path perfect_path_;  // the perfect-optics detector (perfect, fixed/fixed)
  std::filesystem::path base_path_;     // it after --perfect-steps: the fine-tunes' start
  std::filesystem::path temp_dir_;
};

std::filesystem::path JointRun::temporary_dir() {
  if (temp_dir_.empty()) {
    static std::atomic<int> counter{0};
    temp_dir_ = std::filesystem::temp_directory_path() /
                fmt::format("lensopt-joint-{}-{}", ::getpid(), counter++);
    std::filesystem::create_directories(temp_dir_);
  }
  return temp_dir_;
}

void JointRun::check_categories() const {
  if (options_.task != "detection") return;
  // The boxes hold class indices 1..K (JointData::category_map); the built-in detector has
  // kDetectorClasses outputs.
  const CategoryMap& classes = data_.category_map();
  if (classes.class_count() > kDetectorClasses) {
    std::string names;
    for (const DetectionCategory& c : classes.classes)
      names += (names.empty() ? "" : ", ") + c.name;
    throw Error(SourceLocation{options_.data.annotations.string()},
                fmt::format("the dataset has {} categories ({}); the built-in detector has {} "
                            "classes: gather them with --classes FILE.toml (a [classes] map, "
                            "docs/detection.md)",
                            classes.class_count(), names, kDetectorClasses));
  }
}

const BoxDistortion* JointRun::distortion_for(const FloatImage& scene, bool perfect) {
  if (perfect || !options_.imaging.distortion) return nullptr;
  const std::pair<int, int> size{scene.width, scene.height};
  auto it = distortions_.find(size);
  if (it == distortions_.end()) {
    const ImagingOptics& optics = imaging_.optics();
    ImagingModel model;
    model.sensor_diagonal_mm = sensor_diagonal_mm_;
    model.fields_deg = optics.fields_deg;
    model.reference_y_mm = optics.reference_y_mm;
    model.centroid_y_mm = optics.centroid_y_mm;
    it = distortions_
             .emplace(size,
                      BoxDistortion(model, scene.width, scene.height, options_.imaging.res_factor))
             .first;
  }
  return &it->second;
}

TaskBatch JointRun::batch_of(const std::vector<Sample>& samples, bool perfect) {
  if (!perfect && !detection_) return make_batch(imaging_, data_, samples);
  TaskBatch batch;
  for (const Sample& s : samples) {
    const Scene& scene = data_.scenes().at(s.scene);
    batch.sharp.push_back(data_.crop(s));
    batch.rendered.push_back(perfect ? batch.sharp.back() : imaging_.render(scene.image, s.crop));
    batch.targets.push_back(scene.targets);
    const CropFrame frame{double(s.crop.x0), double(s.crop.y0), double(s.crop.width),
                          double(s.crop.height)};
    batch.boxes.push_back(
        crop_ground_truth(scene.boxes, distortion_for(scene.image, perfect), frame));
  }
  return batch;
}

Progress JointRun::read_checkpoint(const std::filesystem::path& dir) {
  Progress progress = start_progress();
  const std::filesystem::path file = dir / "checkpoint.json";
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(read_file(file));
    // Version 1 differs only in the perfect-optics phase (detection).
    const int version = j.at("version").get<int>();
    if (version != kCheckpointVersion && !(version == 1 && !detection_))
      throw Error(SourceLocation{file.string()}, "unsupported checkpoint version");
    if (j.at("variables").get<int>() != n_ || j.at("task").get<std::string>() != options_.task ||
        j.at("phases").get<std::vector<std::string>>() != phases_)
      throw Error(SourceLocation{file.string()},
                  "the checkpoint is of another lens structure, task or set of settings");
    progress.phase = j.at("phase").get<std::string>();
    progress.step = j.at("step").get<int>();
    progress.x = j.at("x").get<std::vector<double>>();
    progress.moments.m = j.at("m").get<std::vector<double>>();
    progress.moments.v = j.at("v").get<std::vector<double>>();
    progress.rng = j.at("rng").get<std::string>();
    progress.steps_done = j.at("steps_done").get<int>();
    progress.task_state = j.at("task_state").get<bool>();
    // The safeguard (absent in checkpoints before it existed: nothing to revert, full steps).
    LensSafeguard& g = progress.safeguard;
    g.step_scale = j.value("lens_step_scale", 1.0);
    result_.reverted_steps = j.value("reverted_steps", 0);
    if (j.contains("accepted")) {
      const nlohmann::json& a = j.at("accepted");
      g.valid = true;
      g.x = a.at("x").get<std::vector<double>>();
      g.m = a.at("m").get<std::vector<double>>();
      g.v = a.at("v").get<std::vector<double>>();
    }
    for (const auto& s : j.at("settings")) {
      for (auto& r : result_.settings)
        if (r.name == s.at("name").get<std::string>()) {
          r.metric = number_of(s, "metric");
          r.mean_spot_um = number_of(s, "mean_spot_um");
          r.ap50 = number_of(s, "ap50");
          r.ap75 = number_of(s, "ap75");
          r.psnr_db = number_of(s, "psnr_db");
          r.ssim = number_of(s, "ssim");
          r.ap_per_category.clear();
          if (s.contains("ap_per_category"))
            for (const auto& c : s.at("ap_per_category"))
              r.ap_per_category.push_back({c.at("category_id").get<int>(),
                                           c.at("name").get<std::string>(), number_of(c, "ap")});
          r.done = s.at("done").get<bool>();
        }
    }
    for (const auto& c : j.at("glass_changes"))
      result_.glass_changes.push_back(
          {c.at("phase"), c.at("step"), c.at("element"), c.at("from"), c.at("to")});
  } catch (const nlohmann::json::exception& e) {
    throw Error(SourceLocation{file.string()}, fmt::format("corrupt checkpoint: {}", e.what()));
  }
  log_ = CsvLog(options_.log_csv, read_file(dir / "log.csv"));
  resume_task_ = dir / "task.pt";
  // The perfect-optics detectors, where this run keeps them (it may checkpoint elsewhere).
  for (const std::filesystem::path& to : {perfect_path_, base_path_}) {
    const std::filesystem::path from = dir / to.filename();
    if (detection_ && std::filesystem::exists(from) &&
        !(std::filesystem::exists(to) && std::filesystem::equivalent(from, to))) {
      std::filesystem::create_directories(to.parent_path());
      write_file_atomic(to, read_file(from));
    }
  }
  say(fmt::format("lensopt optimize --joint: resuming {} at step {} from {}", progress.phase,
                  progress.step, dir.string()));
  return progress;
}

void JointRun::write_checkpoint(const std::string& phase, int step, const std::vector<double>& x,
                                const AdamMoments& moments, const LensSafeguard& safeguard) {
  if (options_.checkpoint_every <= 0) return;
  const std::filesystem::path dir = options_.checkpoint_dir;
  std::filesystem::create_directories(dir);
  if (task_) task_->save(dir / "task.pt");
  write_file_atomic(dir / "log.csv", log_.text());
  nlohmann::json changes = nlohmann::json::array();
  for (const GlassChange& c : result_.glass_changes)
    changes.push_back({{"phase", c.phase},
                       {"step", c.step},
                       {"element", c.element},
                       {"from", c.from},
                       {"to", c.to}});
  nlohmann::json j = {{"version", kCheckpointVersion},
                      {"task", options_.task},
                      {"phases", phases_},
                      {"variables", n_},
                      {"phase", phase},
                      {"step", step},
                      {"steps_done", result_.steps_done},
                      {"x", x},
                      {"m", moments.m},
                      {"v", moments.v},
                      {"rng", data_.rng_state()},
                      {"task_state", task_ != nullptr},
                      {"settings", settings_json(result_.settings)},
                      {"glass_changes", changes},
                      {"lens_step_scale", safeguard.step_scale},
                      {"reverted_steps", result_.reverted_steps}};
  if (safeguard.valid) j["accepted"] = {{"x", safeguard.x}, {"m", safeguard.m}, {"v", safeguard.v}};
  write_file_atomic(dir / "checkpoint.json", j.dump(1));
}

StepRecord JointRun::step_gradient(const std::string& phase, int t, bool train_lens,
                                   const std::vector<double>& x, std::vector<double>& grad) {
  StepRecord r;
  const std::vector<Sample> samples = data_.next_batch();
  if (train_lens) prepare(x);
  const auto render_start = Clock::now();
  const TaskBatch batch = batch_of(samples, phase == kPerfect);
  r.render_s = seconds_since(render_start);
  const auto network_start = Clock::now();
  r.out = task_->step(batch, true, train_lens);
  r.network_s = seconds_since(network_start);
  if (!std::isfinite(r.out.loss))
    throw Error(fmt::format("{} step {}: the task loss is {}", phase, t, r.out.loss));
  r.grad_task.assign(n_, 0.0);
  if (!train_lens) return r;
  const auto adjoint_start = Clock::now();
  for (std::size_t b = 0; b < samples.size(); ++b)
    imaging_.backward(data_.scenes().at(samples[b].scene).image, samples[b].crop,
                      r.out.grad_rendered.at(b), r.grad_task);
  r.adjoint_s = seconds_since(adjoint_start);
  const auto design_start = Clock::now();
  design_ = design_loss_gradient(param_, x, options_.glass_mode, {}, options_.design_sampling,
                                 options_.loss);
  r.design_s = seconds_since(design_start);
  bool finite = design_.finite && std::isfinite(design_.loss.total);
  for (int i = 0; i < n_; ++i) {
    grad[i] = is_frozen_[i] ? 0.0 : r.grad_task[i] + options_.lambda_lens * design_.gradient[i];
    finite = finite && std::isfinite(grad[i]);
  }
  if (!finite) throw Error(fmt::format("{} step {}: non-finite lens gradient", phase, t));
  return r;
}

void JointRun::log_glass_changes(const std::string& phase, int t, std::vector<int>& glasses,
                                 const std::vector<double>& x) {
  const std::vector<int> now = param_.nearest_glasses(x.data());
  for (std::size_t e = 0; e < now.size(); ++e)
    if (now[e] != glasses[e]) {
      const GlassChange c{phase, t, static_cast<int>(e), param_.glass_space().name(glasses[e]),
                          param_.glass_space().name(now[e])};
      result_.glass_changes.push_back(c);
      say(fmt::format("  {} step {}: glass {} {} -> {}", phase, t, e + 1, c.from, c.to));
    }
  glasses = now;
}

void JointRun::add_timings(const StepRecord& r, Clock::time_point step_start,
                           std::clock_t cpu_start) {
  const ImagingTimings it = imaging_.timings();
  JointTimings& jt = result_.timings;
  jt.trace_s += it.trace_s;
  jt.psf_s += it.psf_s;
  jt.render_s += r.render_s;
  jt.adjoint_s += r.adjoint_s;
  jt.network_s += r.network_s;
  jt.design_loss_s += r.design_s;
  jt.step_s += seconds_since(step_start);
  jt.step_cpu_s += static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  ++jt.steps;
}

bool JointRun::run_phase(std::size_t pi, Progress progress, bool resumed) {
  const std::string phase = phases_[pi];
  const bool train_lens = phase == kJoint;
  // The perfect-optics phase trains in two stages: the base detector (perfect_steps, its own
  // schedule with the same share of decay steps), the start of fixed/trained and joint; then,
  // from the same crop stream's start and with the same schedule as they, total_steps() more on
  // the sharp crops, so that every trained setting gets the same training budget. The base stage
  // is skipped when the base detector is given (pretrained_task).
  int constant = options_.constant_steps, decay = options_.decay_steps;
  int base_total = 0, base_constant = 0, base_decay = 0;
  if (phase == kPerfect) {
    base_total = options_.perfect_steps > 0 ? options_.perfect_steps : options_.total_steps();
    base_decay = static_cast<int>(std::lround(static_cast<double>(base_total) *
                                              options_.decay_steps / options_.total_steps()));
    base_constant = base_total - base_decay;
  }
  const int total = base_total + constant + decay;
  int t = progress.step;
  std::vector<double>& x = progress.x;
  AdamMoments& moments = progress.moments;
  LensSafeguard& safeguard = progress.safeguard;
  const bool perfect = phase == kPerfect;
  const bool pretrained = perfect && !options_.pretrained_task.empty();
  task_ = new_task();
  if (task_->detects() != detection_)
    throw Error(detection_ ? fmt::format("task {} is not a detector; a detection dataset needs "
                                         "--task detection or a TorchScript detector",
                                         task_->name())
                           : fmt::format("task {} is a detector: give it a detection dataset "
                                         "(COCO or BDD100K annotations, --data)",
                                         task_->name()));
  data_.restart();
  // The network's start: the state of a resumed phase; else, with detection, the perfect-optics
  // detector (given, or trained by the first phase); else the task's initialization.
  if (resumed && progress.task_state) {
    task_->load(resume_task_);
  } else if (pretrained) {
    task_->load(options_.pretrained_task);
  } else if (detection_ && !perfect) {
    task_->load(phase == kFixedFixed ? perfect_path_ : base_path_);
  }
  if (pretrained && t < base_total) t = base_total;
  if (resumed && !progress.rng.empty()) data_.set_rng_state(progress.rng);
  // A fixed lens is sampled once; a trained one per step; perfect optics renders nothing.
  if (!train_lens && !perfect) prepare(x);
  design_ = design_loss_gradient(param_, x, options_.glass_mode, {}, options_.design_sampling,
                                 options_.loss);
  std::vector<int> glasses = param_.nearest_glasses(x.data());
  const bool trains = phase != kFixedFixed;
  say(fmt::format("lensopt optimize --joint: {} (task {}, {} steps)", phase, task_->name(),
                  trains ? total - (pretrained ? base_total : 0) : 0));
  if (trains) {
    while (t < total) {
      if (perfect && t == base_total) {
        // The base detector is done (or given): kept for the fine-tunes, and the continuation
        // sees the crops they see.
        if (base_path_.has_parent_path())
          std::filesystem::create_directories(base_path_.parent_path());
        task_->save(base_path_);
        if (!options_.perfect_task_out.empty()) task_->save(options_.perfect_task_out);
        data_.restart();
      }
      if (stop_requested()) {
        result_.interrupted = true;
        result_.x = x;
        log_.flush();
        write_checkpoint(phase, t, x, moments, safeguard);
        return false;
      }
      const auto step_start = Clock::now();
      const std::clock_t step_cpu_start = std::clock();
      const double factor = t < base_total ? learning_rate_factor(t, base_constant, base_decay)
                                           : learning_rate_factor(t - base_total, constant, decay);
      const double lr_lens =
          train_lens ? options_.lens_learning_rate * factor * safeguard.step_scale : 0.0;
      const double lr_task = options_.task_options.learning_rate * factor;
      task_->set_learning_rate(lr_task);
      const std::string row_glasses = join_glasses(param_, glasses);
      std::vector<double> grad(n_, 0.0);
      StepRecord r;
      try {
        r = step_gradient(phase, t, train_lens, x, grad);
      } catch (const std::exception& e) {
        // A failed step: back to the lens before the last update, with half the step.
        ++result_.reverted_steps;
        if (++safeguard.consecutive_failures > kMaxConsecutiveFailures)
          throw Error(fmt::format("{} step {}: {} failed steps in a row; the last: {}", phase, t,
                                  safeguard.consecutive_failures, e.what()));
        if (safeguard.valid) {
          x = safeguard.x;
          moments.m = safeguard.m;
          moments.v = safeguard.v;
          safeguard.valid = false;
        }
        safeguard.step_scale *= 0.5;
        say(fmt::format("  {} step {}: failed ({}); reverted, lens step x{:g}", phase, t, e.what(),
                        safeguard.step_scale));
        if (train_lens) log_glass_changes(phase, t, glasses, x);
        ++t;
        ++result_.steps_done;
        ++steps_this_call_;
        continue;
      }
      if (train_lens) {
        safeguard = {true, x, moments.m, moments.v, std::min(1.0, 2.0 * safeguard.step_scale), 0};
        adam_update(x, grad, moments.m, moments.v, t + 1, lr_lens, is_frozen_);
        log_glass_changes(phase, t, glasses, x);
      } else {
        safeguard.consecutive_failures = 0;
      }
      // The row describes the lens the step's images came from and the losses at it.
      const double l_lens = design_.loss.total;
      log_.add(fmt::format(
          "{},{},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.6f},"
          "{},{:.10g},{:.10g}{}",
          phase, t, lr_lens, lr_task, r.out.loss + options_.lambda_lens * l_lens, r.out.loss,
          l_lens, design_.loss.spot_mm, design_.loss.ray_path_mm, design_.loss.ray_angle,
          design_.loss.glass, design_.loss.spot_mm * 1000.0, design_.loss.failed_rays,
          norm(r.grad_task), norm(design_.gradient), row_glasses));
      ++t;
      ++result_.steps_done;
      ++steps_this_call_;
      if (train_lens) add_timings(r, step_start, step_cpu_start);
      if (options_.verbose && (t % 10 == 0 || t == total))
        say(fmt::format("  {} step {}/{}: task loss {:.6g}, l_lens {:.6g}, mean spot {:.2f} um",
                        phase, t, total, r.out.loss, l_lens, design_.loss.spot_mm * 1000.0));
      log_.flush();  // the whole (small) log, atomically, every step
      if (options_.checkpoint_every > 0 && t % options_.checkpoint_every == 0 && t < total)
        write_checkpoint(phase, t, x, moments, safeguard);
    }
    log_.flush();
  }
  if (perfect) {
    if (perfect_path_.has_parent_path())
      std::filesystem::create_directories(perfect_path_.parent_path());
    task_->save(perfect_path_);
  }
  score_setting(pi, x);
  result_.x = x;
  return true;
}

// Scores setting pi on the held-out crops with the final lens and network.
void JointRun::score_setting(std::size_t pi, const std::vector<double>& x) {
  JointSettingResult& setting = result_.settings[pi];
  const bool perfect = setting.name == kPerfect;
  if (detection_) {
    score_detection(setting, perfect, x);
  } else {
    prepare(x);
    setting.metric = evaluate(imaging_, *task_, data_);
  }
  setting.mean_spot_um = perfect ? NAN
                                 : design_loss_gradient(param_, x, options_.glass_mode, {},
                                                        options_.design_sampling, options_.loss)
                                           .loss.spot_mm *
                                       1000.0;
  setting.done = true;
  if (detection_)
    say(
        fmt::format("lensopt optimize --joint: {}: held-out AP {:.4f} (AP50 {:.4f}, AP75 {:.4f}), "
                    "PSNR {:.2f} dB, SSIM {:.4f}, mean spot {:.2f} um",
                    setting.name, setting.metric, setting.ap50, setting.ap75, setting.psnr_db,
                    setting.ssim, setting.mean_spot_um));
  else
    say(fmt::format("lensopt optimize --joint: {}: held-out {} {:.4f}, mean spot {:.2f} um",
                    setting.name, task_->metric_name(), setting.metric, setting.mean_spot_um));
}

// COCO AP of all held-out crops' detections at once (predictions corrected for distortion), and
// the lens's PSNR and SSIM (joint/joint.h).
void JointRun::score_detection(JointSettingResult& setting, bool perfect,
                               const std::vector<double>& x) {
  if (!perfect) prepare(x);
  const std::vector<Sample>& all = data_.eval_samples();
  const std::size_t b = static_cast<std::size_t>(data_.options().batch_size);
  std::vector<GroundTruth> truths;
  std::vector<Detection> detections;
  for (std::size_t i = 0; i < all.size(); i += b) {
    const std::vector<Sample> part(all.begin() + i, all.begin() + std::min(all.size(), i + b));
    const TaskBatch batch = batch_of(part, perfect);
    const std::vector<std::vector<Detection>> found = task_->detect(batch);
    for (std::size_t k = 0; k < part.size(); ++k) {
      const Sample& s = part[k];
      const Scene& scene = data_.scenes().at(s.scene);
      const int id = static_cast<int>(i + k);
      const CropFrame frame{double(s.crop.x0), double(s.crop.y0), double(s.crop.width),
                            double(s.crop.height)};
      const BoxDistortion* distortion = distortion_for(scene.image, perfect);
      for (GroundTruth g : crop_evaluation_ground_truth(scene.boxes, distortion, frame)) {
        g.image = id;
        truths.push_back(g);
      }
      if (k >= found.size()) continue;
      std::vector<Detection> d = found[k];
      correct_crop_detections(d, distortion, frame);
      for (Detection& one : d) {
        one.image = id;
        detections.push_back(one);
      }
    }
  }
  const CocoStats stats = evaluate_coco(truths, detections);
  // Reported by the dataset's own category ids (the detector works on class indices 1..K).
  const CategoryMap& classes = data_.category_map();
  setting.ap_per_category.clear();
  for (std::size_t i = 0; i < stats.categories.size(); ++i) {
    const int k = stats.categories[i];
    if (k < 1 || k > classes.class_count()) continue;  // a detector class the dataset lacks
    setting.ap_per_category.push_back(
        {classes.category_of(k), classes.classes[k - 1].name, stats.ap_per_category[i]});
  }
  setting.metric = stats.ap;
  setting.ap50 = stats.ap50;
  setting.ap75 = stats.ap75;
  setting.psnr_db = NAN;
  setting.ssim = NAN;
  if (perfect) return;
  quality_imaging_->prepare(x, false);
  double psnr_sum = 0, ssim_sum = 0;
  int n = 0;
  for (const Sample& s : all) {
    const FloatImage sharp = data_.crop(s);
    const FloatImage lens = quality_imaging_->render(data_.scenes().at(s.scene).image, s.crop);
    const double p = psnr_db(sharp, lens, 3, options_.imaging.threads);
    if (!std::isfinite(p)) continue;
    psnr_sum += p;
    ssim_sum += ssim(sharp, lens, 3, options_.imaging.threads);
    ++n;
  }
  if (n > 0) {
    setting.psnr_db = psnr_sum / n;
    setting.ssim = ssim_sum / n;
  }
}

// Per-step means of the joint phase's timings.
void JointRun::finish_timings() {
  JointTimings& jt = result_.timings;
  if (jt.steps == 0) return;
  const double s = jt.steps;
  for (double* v : {&jt.trace_s, &jt.psf_s, &jt.render_s, &jt.adjoint_s, &jt.network_s,
                    &jt.design_loss_s, &jt.step_s, &jt.step_cpu_s})
    *v /= s;
}

JointResult JointRun::run(const std::filesystem::path& network_out) {
  const auto clock_start = Clock::now();
  const bool resuming = !options_.resume_dir.empty();
  const Progress progress = resuming ? read_checkpoint(options_.resume_dir) : start_progress();
  const std::size_t first_phase =
      std::find(phases_.begin(), phases_.end(), progress.phase) - phases_.begin();
  if (first_phase >= phases_.size())
    throw Error(
        fmt::format("checkpoint phase '{}' is not among this run's settings", progress.phase));
  result_.steps_done = progress.steps_done;
  result_.x = x0_;
  result_.eval_crops = static_cast<int>(data_.eval_samples().size());
  for (std::size_t pi = first_phase; pi < phases_.size(); ++pi) {
    const bool resumed = pi == first_phase && resuming;
    Progress start = resumed ? progress : start_progress();
    start.phase = phases_[pi];
    if (!run_phase(pi, std::move(start), resumed)) break;
    if (pi + 1 < phases_.size()) {
      task_.reset();  // the next phase starts a fresh network
      write_checkpoint(phases_[pi + 1], 0, x0_, AdamMoments(n_), LensSafeguard{});
    }
  }
  finish_timings();
  if (!network_out.empty() && task_ && !result_.interrupted) task_->save_network(network_out);
  result_.metric_name = task_ ? task_->metric_name() : "";
  const std::vector<double>& x = result_.x;
  result_.lens = param_.to_lens(x.data(), options_.glass_mode);
  for (int g : param_.nearest_glasses(x.data()))
    result_.glasses.push_back(param_.glass_space().name(g));
  result_.seconds = seconds_since(clock_start);
  return result_;
}

}  // namespace

JointResult optimize_joint(const Lens& start, const JointOptions& options,
                           const std::filesystem::path& network_out) {
  options.validate();
  JointRun run(start, options);
  return run.run(network_out);
}

}  // namespace lensopt
