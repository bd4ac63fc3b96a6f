// The downstream task of the joint optimization: it sees a batch of rendered crops, returns its
// loss and dL/d(rendered crops), and trains its own parameters. The interface has no libtorch
// types, so the core builds without libtorch; the tasks themselves (src/joint/torch/) need it.
//
// Images cross the interface as FloatImage (interleaved channels, values ~[0, 1]); a task turns a
// batch into a B x C x H x W tensor and returns the gradient in the same FloatImage layout.
//
// Built-in task "restoration": a residual CNN  y = x + N(x),  N = conv3x3(C -> F), ReLU,
// (conv3x3(F -> F), ReLU) x (layers - 2), conv3x3(F -> C), with the last layer initialized to 0
// so the untrained network is the identity (the "network fixed" setting restores nothing). Loss:
// MSE(y, sharp) averaged over every pixel, channel and image; trained by Adam. Metric: mean over
// the batch of PSNR(y clamped to [0, 1], sharp) = 10 log10(1 / MSE_i), dB.
// User task "torchscript:MODEL.pt": a TorchScript module whose forward(images, targets) returns
// the scalar loss (mean over the batch); its parameters are trained by Adam. targets is a B x N
// float tensor of the batch's targets files (every image of the batch must have one, all with N
// numbers; see joint/data.h for the format), or the B x C x H x W sharp crops when no image has a
// targets file. Metric: -loss.
// Gradient: dL/d(rendered) by torch autograd through the network, the loss being the mean over
// the batch (so the gradients of one image carry the 1/B).
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "lensopt/detection/coco_eval.h"
#include "lensopt/render/image.h"

namespace lensopt {

struct TaskBatch {
  std::vector<FloatImage> rendered;            // the lens's images: the task's input
  std::vector<FloatImage> sharp;               // the matching sharp crops (restoration target)
  std::vector<std::filesystem::path> targets;  // per image: a targets file, or empty
  // Optional: the rendered crops in double (DifferentiableImaging::render_values, same layout as
  // `rendered`, which must be there too). A double-precision task then uses these as its input,
  // so finite differences of the loss are not limited by float rounding (6e-8 per pixel).
  std::vector<std::vector<double>> rendered_values;
  // Detection tasks: per image, the ground-truth boxes in the crop's pixels (as the image shows
  // them: moved with the crop and, in training, distorted like the image; detection/boxes.h).
  std::vector<std::vector<GroundTruth>> boxes;
};

struct TaskOutput {
  double loss = 0;
  std::vector<FloatImage> grad_rendered;  // dL/d(rendered), when asked for
};

struct TaskOptions {
  double learning_rate = 1e-3;    // the task's own Adam
  int channels = 3;               // image channels
  unsigned seed = 1;              // weight initialization
  int features = 16;              // restoration: feature channels F
  int layers = 4;                 // restoration: convolution layers (>= 2)
  bool double_precision = false;  // run the network in float64 (gradient checks)
  int threads = 2;                // torch intra-op threads (deterministic for a fixed count)
  void validate() const;          // throws Error naming the bad value
};

class Task {
 public:
  virtual ~Task() = default;
  virtual std::string name() const = 0;
  // Loss of the batch (mean over the batch); dL/d(rendered) if want_grad; one step of the
  // task's optimizer if train.
  virtual TaskOutput step(const TaskBatch& batch, bool train, bool want_grad) = 0;
  // The task metric of a batch, higher is better (restoration: mean PSNR, dB, of the restored
  // images against the sharp ones).
  virtual double metric(const TaskBatch& batch) = 0;
  virtual std::string metric_name() const = 0;
  virtual void set_learning_rate(double learning_rate) = 0;
  // The task's output images for a batch (restoration: the restored crops, clamped to [0, 1]);
  // empty for tasks whose output is not an image.
  virtual std::vector<FloatImage> predict(const TaskBatch& batch) = 0;
  // Detection tasks: per image, the detected boxes in the crop's pixels (Detection::image is the
  // index in the batch); empty for other tasks.
  virtual std::vector<std::vector<Detection>> detect(const TaskBatch&) { return {}; }
  // Whether the task is a detector (trains on TaskBatch::boxes, answers detect()).
  virtual bool detects() const { return false; }
  // Weights and optimizer state, written atomically; load restores both exactly.
  virtual void save(const std::filesystem::path& path) const = 0;
  virtual void load(const std::filesystem::path& path) = 0;
  // The trained network alone (restoration: a libtorch archive of the weights; TorchScript: the
  // module itself, loadable by torch.jit.load), written atomically.
  virtual void save_network(const std::filesystem::path& path) const = 0;
};

// Whether the libtorch tasks can be made: lensopt was built with libtorch (CMake option
// LENSOPT_WITH_TORCH) and its module liblensopt_torch.so loads (joint/torch_loader.cpp says where
// it is looked for; the environment variable LENSOPT_TORCH_PLUGIN names it explicitly).
bool torch_available();
// Throws Error saying why the libtorch tasks cannot be made (not built, module not found, or it
// failed to load), if torch_available() is false.
void require_torch();

// "restoration" (the built-in small CNN), "detection" (the built-in detector, joint/detector.h)
// or "torchscript:MODEL.pt" (a restoration-style module, or a detector by the contract of
// joint/detector.h, told apart by forward's argument count). Throws Error if libtorch is
// not available (require_torch), the model cannot be loaded, or the spec is unknown.
std::unique_ptr<Task> make_task(const std::string& spec, const TaskOptions& options);

}  // namespace lensopt
