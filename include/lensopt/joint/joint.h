// Joint optimization of a lens and a downstream network (paper "Joint Optimization",
// "End-to-End Optimization"): stochastic gradient descent on
//   l_joint(x, theta) = l_task(N_theta(R(x; S))) + lambda_lens l_lens(x)
// over the lens variables x (optimize/variables.h) and the task's parameters theta, with R the
// rendered crops of sharp scenes S (joint/imaging.h) and l_lens the paper's design loss
// (optimize/design_loss.h: l_S + lambda_RP l_RP + lambda_RA l_RA + lambda_GV l_GV).
//
// Gradient of one step (batch of B crops; the task's loss is the batch mean):
//   d l_joint / dx = sum_b <d l_task / dR_b, dR_b / dx>   [task autograd, then imaging backward]
//                  + lambda_lens d l_lens / dx            [Jets, optimize/design_gradient.h]
// Glasses (GlassMode::kQuantized): the forward pass uses the nearest catalog glass, the gradient
// passes straight through to the continuous g, and l_GV pulls g towards its glass.
// Lens update: Adam (beta1 0.9, beta2 0.999, eps 1e-8) with bias correction,
//   m = b1 m + (1 - b1) g,  v = b2 v + (1 - b2) g^2,  x -= lr_t m^ / (sqrt(v^) + eps),
// learning rate lr_t = lr for t < T_c, then lr (1 + cos(pi (t - T_c) / T_d)) / 2 for the T_d
// decay steps (a half cosine to 0); the task's learning rate follows the same factor.
// A failed step (an exception from the imaging or the task, a non-finite loss or gradient) is
// not fatal: as Ceres rejects an infeasible point and shrinks its trust region, the lens and the
// Adam moments go back to before the last update, the lens step is halved (and doubled again,
// up to its schedule, by each successful step), and the run goes on with the next batch;
// JointResult::reverted_steps counts them. 8 failures in a row end the run with the error. (The
// task's own update of a failed step is kept: a network has no cheap snapshot.)
//
// The paper's three settings (its Table 2), run by one call on the same data stream (the crop
// generator and the network's initialization restart from the seed for each):
//   fixed/fixed:   the start lens, the untrained network (the identity for restoration);
//   fixed/trained: the start lens, the network trained for all steps;
//   joint:         lens and network trained together for all steps.
// Each is scored by the task metric on the held-out crops (restoration: PSNR, dB).
//
// Object detection (the paper's experiment; data.annotations set, a detector task: "detection"
// or a TorchScript detector, joint/detector.h). The crops carry their ground-truth boxes as the
// rendered image shows them (detection/crop_boxes.h: distorted by the lens's distortion at the
// current lens when the warp is rendered, then moved and clipped by the crop; the resolution
// factor enters through the distortion's geometry). The boxes are targets: no gradient flows
// through them to the lens (the images carry the lens's gradient). Four settings, the paper's
// Table 2:
//   perfect:       the detector trained on the sharp crops (no lens): first `perfect_steps`
//                  steps (the base detector; or it is loaded from `pretrained_task`), then
//                  total_steps() more with the fine-tunes' schedule and crops, so that it has
//                  the same training budget as fixed/trained and joint; scored on the sharp
//                  held-out crops;
//   fixed/fixed:   that (final) detector, unchanged, on the start lens's images;
//   fixed/trained: the base detector fine-tuned for total_steps() on the start lens's images;
//   joint:         the base detector and the lens trained together for total_steps().
// Scores on the held-out crops: COCO AP, AP50, AP75 (detection/coco_eval.h) of all crops'
// detections at once, the predicted boxes corrected by the inverse distortion and compared with the
// crop's evaluation ground truth (detection/crop_boxes.h); and the lens's image quality, the mean
// over the crops of PSNR and SSIM between the sharp crop and the lens's rendering without relative
// illumination and distortion (render/metrics.h; not defined for perfect optics).
//
// State. A per-step CSV (phase, step, learning rates, every loss term, mean spot, glasses);
// every glass change is logged; checkpoints every N steps to a directory (checkpoint.json with
// the lens variables, Adam moments, step, phase, finished results and the crop generator's
// state; task.pt with the network and its optimizer; log.csv so far), written atomically with
// checkpoint.json last. Resuming from it continues the same trajectory: the same crops, the same
// updates, the same CSV rows as an uninterrupted run.
#pragma once

#include <atomic>
#include <cmath>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "lensopt/joint/data.h"
#include "lensopt/joint/imaging.h"
#include "lensopt/joint/task.h"
#include "lensopt/lens/lens.h"
#include "lensopt/optimize/design_loss.h"
#include "lensopt/optimize/variables.h"

namespace lensopt {

// The sampling of l_lens in the joint loop: 8 rings and 11 fields, the LM optimizer's (its
// constraint rays still run at 21 fields, design_loss.h).
inline TraceOptions joint_design_sampling() {
  TraceOptions o;
  o.rings = 8;
  o.fields = 11;
  return o;
}

struct JointOptions {
  std::string task = "restoration";  // or "torchscript:MODEL.pt"
  TaskOptions task_options;          // the network's Adam learning rate, seed, threads
  DataOptions data;
  DifferentiableImagingOptions imaging;  // PSF sampling (rings, 21 fields), RI, distortion
  TraceOptions design_sampling = joint_design_sampling();  // l_lens sampling
  DesignLossOptions loss;  // lambda_S (weight_spot), lambda_RP, lambda_RA, lambda_GV
  double lambda_lens = 1.0;
  double lens_learning_rate = 5e-3;
  int constant_steps = 100;                      // T_c
  int decay_steps = 100;                         // T_d (0: no decay)
  GlassMode glass_mode = GlassMode::kQuantized;  // kContinuous: the ablation
  bool paraxial_image_solve = true;              // false: the ablation
  std::vector<std::string> freeze;               // lens variables held (names or groups)
  bool run_baselines = true;  // also run fixed/fixed and fixed/trained (else only joint; with
                              // detection the perfect-optics detector is always trained)
  std::filesystem::path pretrained_task;   // detection: the base perfect-optics detector (a
                                           // perfect_task_out of an earlier run), not trained
  std::filesystem::path perfect_task_out;  // detection: writes the base perfect-optics detector
                                           // (Task::save: weights and optimizer state)
  int perfect_steps = 0;     // detection: steps of the base perfect-optics detector (0:
                             // total_steps(); the same share of them decays); the perfect row
                             // then trains total_steps() more
  int checkpoint_every = 0;  // steps; 0: none
  std::filesystem::path checkpoint_dir;  // required when checkpoint_every > 0
  std::filesystem::path resume_dir;      // a checkpoint directory to resume from
  std::filesystem::path log_csv;         // the per-step CSV (empty: none)
  int stop_after_steps = -1;  // stop (as if interrupted) after this many steps in all (tests)
  bool verbose = true;        // progress on stderr
  const std::atomic<bool>* interrupt = nullptr;
  // Makes the task (empty: make_task(task, task_options)); tests inject tasks through it.
  std::function<std::unique_ptr<Task>(const std::string&, const TaskOptions&)> task_factory;

  int total_steps() const { return constant_steps + decay_steps; }
  void validate() const;  // throws Error naming the bad value
};

// Learning-rate factor of step t (0-based) of the schedule above.
double learning_rate_factor(int step, int constant_steps, int decay_steps);

struct GlassChange {
  std::string phase;
  int step = 0;
  int element = 0;  // 0-based glass element
  std::string from, to;
};

struct JointSettingResult {
  std::string name;         // "perfect" (detection), "fixed/fixed", "fixed/trained", "joint"
  double metric = 0;        // the task metric (detection: AP, -1 without ground truth)
  double mean_spot_um = 0;  // at the design sampling (NaN for perfect optics)
  bool done = false;
  // Detection only (else NaN): AP at IoU 0.5 and 0.75, and the lens's mean PSNR (dB) and SSIM
  // on the held-out crops (NaN for perfect optics).
  double ap50 = NAN, ap75 = NAN, psnr_db = NAN, ssim = NAN;
  // Detection only: AP (IoU 0.50:0.95) per category with ground truth in the held-out crops, by
  // the dataset's own category id and name (not the detector's class index; -1: no ground truth).
  struct CategoryAp {
    int category_id = 0;
    std::string name;
    double ap = -1;
  };
  std::vector<CategoryAp> ap_per_category;
};

// Mean wall time per joint step, seconds (the imaging's split plus the task and l_lens).
struct JointTimings {
  double trace_s = 0, psf_s = 0, render_s = 0, adjoint_s = 0;
  double network_s = 0;      // the task's forward, backward and update
  double design_loss_s = 0;  // l_lens and its gradient (Jets)
  double step_s = 0;         // the whole step
  double step_cpu_s = 0;     // the whole step's process CPU time (all threads)
  int steps = 0;
};

struct JointResult {
  Lens lens;              // the jointly optimized lens
  std::vector<double> x;  // its variables
  std::vector<std::string> glasses;
  std::string metric_name;
  std::vector<JointSettingResult> settings;  // in the order above (baselines may be absent)
  std::vector<GlassChange> glass_changes;
  double seconds = 0;
  int steps_done = 0;        // joint steps run (all phases, this call and resumed ones)
  bool interrupted = false;  // stopped early (interrupt or stop_after_steps)
  int reverted_steps = 0;    // failed steps (exception, non-finite loss or gradient) reverted
  JointTimings timings;      // joint phase, this call
  int eval_crops = 0;        // held-out crops scored
  std::vector<std::string> notes;
};

// Runs the joint optimization from `start` (and the baselines). `network_out` (may be empty)
// receives the jointly trained network (Task::save_network).
JointResult optimize_joint(const Lens& start, const JointOptions& options,
                           const std::filesystem::path& network_out = {});

// One joint step's gradient pieces, for tests and the benchmark: the task loss of the crops
// rendered with variables x and its gradient (task autograd + imaging backward), without
// updating anything. `grad_x` is resized to the variable count.
// `boxes` (detection): the crops' ground truth, held fixed (TaskBatch::boxes).
double task_loss_gradient(DifferentiableImaging& imaging, Task& task, const JointData& data,
                          const std::vector<Sample>& samples, const std::vector<double>& x,
                          std::vector<double>* grad_x,
                          const std::vector<std::vector<GroundTruth>>& boxes = {});

}  // namespace lensopt
