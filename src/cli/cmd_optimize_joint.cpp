// lensopt optimize LENS --joint -o OUT.toml: joint lens + network optimization (joint/joint.h).
// Writes OUT.toml (the joint lens), OUT.csv (per-step log, unless --log), OUT.network.pt (the
// jointly trained network, unless --network), and checkpoints with --checkpoint-every. With a
// detection dataset (--data) also OUT.detector.pt, the perfect-optics detector (--detector
// reuses it in a run of another lens), and the paper's four-setting table.
#include <fmt/core.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "core/json_number.h"
#include "lensopt/core/error.h"
#include "lensopt/core/interrupt.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/joint/joint.h"
#include "lensopt/lens/lens_io.h"

namespace lensopt::cli {
namespace {

struct JointCommand {
  std::string task = "restoration";
  std::string images;
  std::string data;
  std::string classes;  // a TOML file with a [classes] map
  std::string detector;
  int steps = 300;
  int perfect_steps = 0;
  int decay_steps = -1;  // default: two thirds of the steps (the paper: 50k + 100k)
  int batch = 4;
  int crop = 256;
  double lambda_lens = 1.0;
  double lens_lr = 5e-3;
  double task_lr = 1e-3;
  double weight_spot = NAN;
  unsigned long seed = 1;
  int checkpoint_every = 0;
  std::string checkpoint_dir;
  std::string resume;
  std::string log;
  std::string network;
  bool only_joint = false;
  bool continuous_glass = false;
  bool no_image_solve = false;
  std::string distortion = "auto";
  bool no_relative_illumination = false;
  int res_factor = 1;
  int psf_rings = 8, psf_fields = 21;
  int design_rings = 8, design_fields = 11;
  int scenes = 6;
  int scene_width = 1280, scene_height = 720;
  int eval_crops = 8;
  double holdout = 0.2;
  int features = 16, layers = 4;
  int stop_after = -1;
};

std::filesystem::path beside(const std::filesystem::path& out, const std::string& suffix) {
  return out.parent_path() / (out.stem().string() + suffix);
}

// The files a joint run writes: the lens, the step log, the network and (with
// --checkpoint-every) the checkpoint folder; defaults beside OUT.toml.
struct JointOutputs {
  std::filesystem::path lens, log, network, checkpoint_dir;
  std::filesystem::path detector;  // with --data: the perfect-optics detector (else empty)
};

JointOutputs joint_outputs(const JointCommand& cmd, const std::filesystem::path& out_path) {
  return {
      out_path, cmd.log.empty() ? beside(out_path, ".csv") : std::filesystem::path(cmd.log),
      cmd.network.empty() ? beside(out_path, ".network.pt") : std::filesystem::path(cmd.network),
      cmd.checkpoint_dir.empty() ? beside(out_path, ".checkpoint")
                                 : std::filesystem::path(cmd.checkpoint_dir),
      cmd.data.empty() ? std::filesystem::path() : beside(out_path, ".detector.pt")};
}

// --data: a COCO / BDD100K JSON, or a folder with annotations.json (`lensopt chart --detection`).
std::filesystem::path annotations_path(const std::string& data) {
  if (data.empty()) return {};
  const std::filesystem::path p(data);
  if (std::filesystem::is_directory(p)) {
    const std::filesystem::path json = p / "annotations.json";
    if (!std::filesystem::is_regular_file(json))
      throw Error(SourceLocation{p.string()},
                  "a detection dataset folder needs annotations.json (COCO; or give the JSON)");
    return json;
  }
  if (!std::filesystem::is_regular_file(p))
    throw Error(SourceLocation{p.string()}, "no such detection dataset (COCO or BDD100K JSON)");
  return p;
}

// The output layer's checks before any work: every output can be written and is none of the
// run's inputs (the lens, unless --in-place; the training images; a TorchScript task's module;
// the resumed checkpoint, except as the checkpoint folder itself, which a resumed run goes on
// writing), and no two outputs are the same file.
void check_joint_outputs(const JointCommand& cmd, const OptimizeShared& shared) {
  const std::filesystem::path out_path = shared.output_path;
  if (out_path.empty()) throw Error("give -o OUT.toml (or --in-place to overwrite the input)");
  const JointOutputs outs = joint_outputs(cmd, out_path);
  std::vector<std::filesystem::path> inputs;
  if (!cmd.images.empty()) inputs.emplace_back(cmd.images);
  if (!cmd.data.empty()) inputs.emplace_back(cmd.data);
  if (!cmd.detector.empty()) inputs.emplace_back(cmd.detector);
  const std::string kTorchScript = "torchscript:";
  if (cmd.task.rfind(kTorchScript, 0) == 0)
    inputs.emplace_back(cmd.task.substr(kTorchScript.size()));
  std::vector<std::filesystem::path> file_inputs = inputs;
  if (!cmd.resume.empty()) file_inputs.emplace_back(cmd.resume);
  file_inputs.emplace_back(shared.lens_path);
  std::vector<std::filesystem::path> written;
  std::vector<std::filesystem::path> files = {outs.log, outs.network};
  if (!outs.detector.empty()) files.push_back(outs.detector);
  for (const auto& out : files) {
    std::vector<std::filesystem::path> others = file_inputs;
    others.insert(others.end(), written.begin(), written.end());
    others.push_back(outs.lens);
    check_output_file(out, others);
    written.push_back(out);
  }
  check_output_file(outs.lens, shared.in_place ? inputs : file_inputs);
  if (cmd.checkpoint_every > 0) {
    inputs.emplace_back(shared.lens_path);
    check_output_dir(outs.checkpoint_dir, inputs);
  }
}

// The output lens path, checked before any work: given, .toml, not the input (unless
// --in-place).
std::filesystem::path checked_output_path(const OptimizeShared& shared) {
  std::filesystem::path out_path = shared.output_path;
  if (out_path.empty()) throw Error("give -o OUT.toml (or --in-place to overwrite the input)");
  if (!shared.in_place && std::filesystem::exists(out_path) &&
      std::filesystem::equivalent(out_path, shared.lens_path))
    throw Error(SourceLocation{out_path.string()},
                "refusing to overwrite the input lens; use --in-place to do that");
  if (out_path.extension() != ".toml")
    throw Error(SourceLocation{out_path.string()}, "the optimized lens is written as .toml");
  return out_path;
}

// The run's options from the command line (validated).
JointOptions joint_options(const JointCommand& cmd, const OptimizeShared& shared,
                           const std::filesystem::path& out_path) {
  JointOptions options;
  options.task = cmd.task;
  options.task_options.learning_rate = cmd.task_lr;
  options.task_options.seed = static_cast<unsigned>(cmd.seed);
  options.task_options.features = cmd.features;
  options.task_options.layers = cmd.layers;
  if (shared.threads > 0) options.task_options.threads = shared.threads;
  options.data.images_dir = cmd.images;
  options.data.annotations = annotations_path(cmd.data);
  if (!cmd.classes.empty()) {
    if (cmd.data.empty())
      throw Error(SourceLocation{"--classes"},
                  "--classes maps a detection dataset's categories: "
                  "give --data too");
    options.data.classes = cmd.classes;
  }
  options.pretrained_task = cmd.detector;
  options.perfect_steps = cmd.perfect_steps;
  options.data.batch_size = cmd.batch;
  options.data.crop_px = cmd.crop;
  options.data.seed = cmd.seed;
  options.data.builtin_scenes = cmd.scenes;
  options.data.builtin_width = cmd.scene_width;
  options.data.builtin_height = cmd.scene_height;
  options.data.eval_crops = cmd.eval_crops;
  options.data.holdout_fraction = cmd.holdout;
  options.imaging.sampling.rings = cmd.psf_rings;
  options.imaging.sampling.fields = cmd.psf_fields;
  options.imaging.res_factor = cmd.res_factor;
  // The restoration target is the sharp, undistorted crop: a small CNN cannot undo a warp (the
  // Doublet's -7.6 % at 25 deg moves corner content by ~55 px at 1280 x 720), and it would swamp
  // the blur in the task's loss. The paper likewise keeps distortion out of its detection loss
  // by correcting the ground truth. So "auto" renders without distortion for restoration and
  // with it for TorchScript tasks (which can correct their targets themselves).
  options.imaging.distortion =
      cmd.distortion == "on" || (cmd.distortion == "auto" && cmd.task != "restoration");
  options.imaging.relative_illumination = !cmd.no_relative_illumination;
  options.design_sampling.rings = cmd.design_rings;
  options.design_sampling.fields = cmd.design_fields;
  if (shared.threads >= 0) {
    options.imaging.threads = shared.threads;
    options.imaging.sampling.threads = shared.threads;
    options.design_sampling.threads = shared.threads;
  }
  if (!std::isnan(cmd.weight_spot)) options.loss.weight_spot = cmd.weight_spot;
  if (!std::isnan(shared.weight_ray_path)) options.loss.weight_ray_path = shared.weight_ray_path;
  if (!std::isnan(shared.weight_ray_angle)) options.loss.weight_ray_angle = shared.weight_ray_angle;
  if (!std::isnan(shared.weight_glass)) options.loss.weight_glass = shared.weight_glass;
  options.lambda_lens = cmd.lambda_lens;
  options.lens_learning_rate = cmd.lens_lr;
  const int decay = cmd.decay_steps >= 0 ? cmd.decay_steps : (2 * cmd.steps) / 3;
  if (decay > cmd.steps)
    throw Error(fmt::format("--decay-steps {} exceeds --steps {}", decay, cmd.steps));
  options.constant_steps = cmd.steps - decay;
  options.decay_steps = decay;
  options.glass_mode = cmd.continuous_glass ? GlassMode::kContinuous : GlassMode::kQuantized;
  options.paraxial_image_solve = !cmd.no_image_solve;
  options.freeze = shared.freeze;
  options.run_baselines = !cmd.only_joint;
  options.checkpoint_every = cmd.checkpoint_every;
  const JointOutputs outputs = joint_outputs(cmd, out_path);
  options.checkpoint_dir = outputs.checkpoint_dir;
  options.resume_dir = cmd.resume;
  options.log_csv = outputs.log;
  options.perfect_task_out = outputs.detector;
  options.stop_after_steps = cmd.stop_after;
  options.verbose = !shared.quiet;
  options.validate();
  return options;
}

// joint - fixed/trained of the held-out metric (NaN without both settings).
double joint_margin(const JointResult& result) {
  const JointSettingResult* joint = nullptr;
  const JointSettingResult* fixed_trained = nullptr;
  for (const auto& s : result.settings) {
    if (s.name == "joint") joint = &s;
    if (s.name == "fixed/trained") fixed_trained = &s;
  }
  return joint && fixed_trained ? joint->metric - fixed_trained->metric : NAN;
}

void print_joint_json(const Lens& lens, const std::filesystem::path& out_path,
                      const std::filesystem::path& network, const JointOptions& options,
                      const JointResult& result) {
  const double margin = joint_margin(result);
  nlohmann::json j;
  j["lens"] = lens.name;
  j["output"] = out_path.string();
  j["network"] = network.string();
  j["log"] = options.log_csv.string();
  j["task"] = options.task;
  j["metric"] = result.metric_name;
  const bool detection = !options.data.annotations.empty();
  nlohmann::json settings = nlohmann::json::array();
  for (const auto& s : result.settings) {
    nlohmann::json row = {{"name", s.name},
                          {"metric", finite_or_null(s.metric)},
                          {"mean_spot_um", finite_or_null(s.mean_spot_um)}};
    if (detection) {
      row["ap"] = finite_or_null(s.metric);
      row["ap50"] = finite_or_null(s.ap50);
      row["ap75"] = finite_or_null(s.ap75);
      row["psnr_db"] = finite_or_null(s.psnr_db);
      row["ssim"] = finite_or_null(s.ssim);
      nlohmann::json per_category = nlohmann::json::array();
      for (const JointSettingResult::CategoryAp& c : s.ap_per_category)
        per_category.push_back(
            {{"category_id", c.category_id}, {"name", c.name}, {"ap", finite_or_null(c.ap)}});
      row["ap_per_category"] = per_category;
    }
    settings.push_back(row);
  }
  j["settings"] = settings;
  if (detection) {
    j["data"] = options.data.annotations.string();
    j["detector"] = options.perfect_task_out.string();
    j["res_factor"] = options.imaging.res_factor;
    j["distortion"] = options.imaging.distortion;
    j["seed"] = options.data.seed;
    j["batch"] = options.data.batch_size;
    j["crop"] = options.data.crop_px;
    j["eval_crops"] = result.eval_crops;
  }
  if (!std::isnan(margin)) j["joint_minus_fixed_trained"] = margin;
  j["glasses"] = result.glasses;
  nlohmann::json changes = nlohmann::json::array();
  for (const auto& c : result.glass_changes)
    changes.push_back({{"phase", c.phase},
                       {"step", c.step},
                       {"element", c.element + 1},
                       {"from", c.from},
                       {"to", c.to}});
  j["glass_changes"] = changes;
  j["steps"] = options.total_steps();
  j["reverted_steps"] = result.reverted_steps;
  j["seconds"] = result.seconds;
  const JointTimings& t = result.timings;
  j["step_seconds"] = {{"trace", t.trace_s},     {"psf", t.psf_s},
                       {"render", t.render_s},   {"adjoint", t.adjoint_s},
                       {"network", t.network_s}, {"design_loss", t.design_loss_s},
                       {"total", t.step_s},      {"total_cpu", t.step_cpu_s},
                       {"steps", t.steps}};
  j["notes"] = result.notes;
  fmt::print("{}\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
}

void print_joint_text(const OptimizeShared& shared, const std::filesystem::path& out_path,
                      const std::filesystem::path& network, const JointOptions& options,
                      const JointResult& result) {
  const double margin = joint_margin(result);
  fmt::print("lensopt optimize --joint: {} -> {} (task {}, {} steps)\n", shared.lens_path,
             out_path.string(), options.task, options.total_steps());
  if (!options.data.annotations.empty()) {
    // The paper's Table 2: per setting the lens's mean spot, PSNR and SSIM and the detector's
    // COCO AP on the held-out crops (predicted boxes corrected for distortion).
    auto cell = [](double v, int width, int digits) {
      return std::isfinite(v) ? fmt::format("{:{}.{}f}", v, width, digits)
                              : fmt::format("{:>{}}", "-", width);
    };
    fmt::print("  {:<14} {:>14} {:>10} {:>7} {:>7} {:>7} {:>7}\n", "setting", "mean spot (um)",
               "PSNR (dB)", "SSIM", "AP", "AP50", "AP75");
    for (const auto& s : result.settings)
      fmt::print("  {:<14} {} {} {} {} {} {}\n", s.name, cell(s.mean_spot_um, 14, 2),
                 cell(s.psnr_db, 10, 2), cell(s.ssim, 7, 4), cell(s.metric, 7, 4),
                 cell(s.ap50, 7, 4), cell(s.ap75, 7, 4));
    fmt::print("  held out: {} crops of {} px; resolution factor {}x; distortion {}\n",
               result.eval_crops, options.data.crop_px, options.imaging.res_factor,
               options.imaging.distortion ? "on (boxes corrected)" : "off");
  } else {
    fmt::print("  setting          held-out {:<12} mean spot (um)\n", result.metric_name);
    for (const auto& s : result.settings)
      fmt::print("  {:<16} {:21.4f}   {:10.2f}\n", s.name, s.metric, s.mean_spot_um);
  }
  if (!std::isnan(margin))
    fmt::print("  joint - fixed/trained: {:+.4f} ({})\n", margin,
               margin > 0 ? "joint wins" : "joint does not win");
  std::string glasses;
  for (const std::string& g : result.glasses) glasses += (glasses.empty() ? "" : ", ") + g;
  fmt::print("  glasses: {}; {} glass changes\n", glasses, result.glass_changes.size());
  if (result.reverted_steps > 0)
    fmt::print("  {} failed steps reverted (lens step halved each time)\n", result.reverted_steps);
  const JointTimings& t = result.timings;
  fmt::print(
      "  per joint step: {:.3f} s, {:.3f} s CPU (trace {:.3f}, PSFs {:.3f}, render {:.3f}, adjoint "
      "{:.3f}, network {:.3f}, l_lens {:.3f})\n",
      t.step_s, t.step_cpu_s, t.trace_s, t.psf_s, t.render_s, t.adjoint_s, t.network_s,
      t.design_loss_s);
  fmt::print("  log {}; network {}; {:.1f} s\n", options.log_csv.string(), network.string(),
             result.seconds);
}

void run_joint(const JointCommand& cmd, const OptimizeShared& shared) {
  require_torch();  // before any output: says why the libtorch module cannot be loaded
  check_joint_outputs(cmd, shared);
  const Lens lens = read_lens(shared.lens_path);
  const std::filesystem::path out_path = checked_output_path(shared);
  JointOptions options = joint_options(cmd, shared, out_path);
  const std::filesystem::path network = joint_outputs(cmd, out_path).network;

  JointResult result;
  {
    const InterruptScope interrupt;  // SIGINT / SIGTERM: stop at the next step, checkpoint
    options.interrupt = interrupt.flag();
    result = optimize_joint(lens, options, network);
  }
  if (result.interrupted) {
    fmt::print(
        stderr,
        "lensopt optimize --joint: stopped after {} steps{}; nothing written but the log{}\n",
        result.steps_done,
        options.checkpoint_every > 0
            ? fmt::format(" (resume with --resume {})", options.checkpoint_dir.string())
            : "",
        options.checkpoint_every > 0 ? " and the checkpoint" : "");
    throw ExitCode{130};
  }
  write_lens(result.lens, out_path);
  if (shared.json)
    print_joint_json(lens, out_path, network, options, result);
  else
    print_joint_text(shared, out_path, network, options, result);
}

}  // namespace

std::function<void(const OptimizeShared&)> setup_optimize_joint(CLI::App& sub) {
  auto cmd = std::make_shared<JointCommand>();
  const std::string g = "joint (with --joint)";
  sub.add_option("--task", cmd->task,
                 "restoration (default), detection (the built-in detector; needs --data) or "
                 "torchscript:MODEL.pt")
      ->group(g);
  sub.add_option("--images", cmd->images,
                 "directory of training images (default: built-in scenes; with --data: the "
                 "dataset's images, default DATA/images)")
      ->group(g);
  sub.add_option("--data", cmd->data,
                 "detection dataset: COCO or BDD100K JSON, or a folder with annotations.json "
                 "(lensopt chart --detection); runs perfect optics, fixed/fixed, fixed/trained "
                 "and joint")
      ->group(g);
  sub.add_option("--classes", cmd->classes,
                 "with --data: a TOML file whose [classes] table gathers the dataset's "
                 "categories by name into the detector's classes (docs/detection.md); default: "
                 "COCO's own categories in order of id, BDD100K's through the paper's six")
      ->group(g);
  sub.add_option("--perfect-steps", cmd->perfect_steps,
                 "with --data: training steps of the base perfect-optics detector, the start of "
                 "fixed/trained and joint (default: --steps); the perfect-optics row trains "
                 "--steps more on sharp crops")
      ->group(g);
  sub.add_option("--detector", cmd->detector,
                 "with --data: the base perfect-optics detector of an earlier run "
                 "(OUT.detector.pt), used instead of training one")
      ->group(g);
  sub.add_option("--steps", cmd->steps, "optimization steps per trained setting (default 300)")
      ->group(g);
  sub.add_option("--decay-steps", cmd->decay_steps,
                 "of them, half-cosine decay steps at the end (default 2/3 of --steps)")
      ->group(g);
  sub.add_option("--batch", cmd->batch, "crops per step (default 4)")->group(g);
  sub.add_option("--crop", cmd->crop, "crop size, px (default 256)")->group(g);
  sub.add_option("--lambda-lens", cmd->lambda_lens, "weight of l_lens in l_joint (default 1)")
      ->group(g);
  sub.add_option("--lens-lr", cmd->lens_lr, "lens learning rate (default 5e-3)")->group(g);
  sub.add_option("--task-lr", cmd->task_lr, "network learning rate (default 1e-3)")->group(g);
  sub.add_option("--weight-spot", cmd->weight_spot, "lambda_S (default 1; 0: the ablation)")
      ->group(g);
  sub.add_option("--seed", cmd->seed, "seed of crops, scenes and network (default 1)")->group(g);
  sub.add_option("--checkpoint-every", cmd->checkpoint_every, "checkpoint every N steps")->group(g);
  sub.add_option("--checkpoint-dir", cmd->checkpoint_dir,
                 "checkpoint directory (default OUT.checkpoint)")
      ->group(g);
  sub.add_option("--resume", cmd->resume, "resume from a checkpoint directory")->group(g);
  sub.add_option("--log", cmd->log, "per-step CSV (default OUT.csv)")->group(g);
  sub.add_option("--network", cmd->network, "trained network file (default OUT.network.pt)")
      ->group(g);
  sub.add_flag("--only-joint", cmd->only_joint,
               "skip the fixed-lens settings (fixed/fixed, fixed/trained)")
      ->group(g);
  sub.add_flag("--continuous-glass", cmd->continuous_glass, "ablation: no glass quantization")
      ->group(g);
  sub.add_flag("--no-image-solve", cmd->no_image_solve, "ablation: no paraxial image solve")
      ->group(g);
  sub.add_option("--distortion", cmd->distortion,
                 "render the distortion warp: auto (default: off for restoration, on for "
                 "detection and TorchScript tasks), on, off")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->group(g);
  sub.add_flag("--no-relative-illumination", cmd->no_relative_illumination,
               "render without relative illumination")
      ->group(g);
  sub.add_option("--res-factor", cmd->res_factor, "simulated resolution factor, 1 or 2")->group(g);
  sub.add_option("--psf-rings", cmd->psf_rings, "pupil rings of the PSFs (default 8)")->group(g);
  sub.add_option("--psf-fields", cmd->psf_fields, "PSF fields (default 21)")->group(g);
  sub.add_option("--design-rings", cmd->design_rings, "pupil rings of l_lens (default 8)")
      ->group(g);
  sub.add_option("--design-fields", cmd->design_fields, "fields of l_lens (default 11)")->group(g);
  sub.add_option("--scenes", cmd->scenes, "built-in scenes: chart + N-1 dead leaves (default 6)")
      ->group(g);
  sub.add_option("--scene-width", cmd->scene_width, "built-in scene width, px (default 1280)")
      ->group(g);
  sub.add_option("--scene-height", cmd->scene_height, "built-in scene height, px (default 720)")
      ->group(g);
  sub.add_option("--holdout", cmd->holdout,
                 "share of the images of --images or --data held out for evaluation (default 0.2)")
      ->group(g);
  sub.add_option("--eval-crops", cmd->eval_crops, "held-out crops scored (default 8)")->group(g);
  sub.add_option("--features", cmd->features, "restoration network features (default 16)")
      ->group(g);
  sub.add_option("--layers", cmd->layers, "restoration network layers (default 4)")->group(g);
  sub.add_option("--stop-after", cmd->stop_after, "stop after N steps (as if interrupted)")
      ->group(g);
  return [cmd](const OptimizeShared& shared) { run_joint(*cmd, shared); };
}

}  // namespace lensopt::cli
