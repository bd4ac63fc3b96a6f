// The downstream task of the joint optimization: it sees a batch of rendered crops, returns its
// loss and dL/d(rendered crops), and trains its own parameters. The interface has no libtorch
// types, so the core builds without libtorch; the tasks themselves (src/joint/torch/) need it.
//
// Images cross the interface as FloatImage (interleaved channels, values ~[0, 1]); a task turns a
// batch into a B x C x H x W tensor and returns the gradient in the same FloatImage layout.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "lensopt/render/image.h"

namespace lensopt {

struct TaskBatch {
  std::vector<FloatImage> rendered;            // the lens's images: the task's input
  std::vector<FloatImage> sharp;               // the matching sharp crops (restoration target)
  std::vector<std::filesystem::path> targets;  // per image: a targets file, or empty
};

struct TaskOutput {
  double loss = 0;
  std::vector<FloatImage> grad_rendered;  // dL/d(rendered), when asked for
};

struct TaskOptions {
  double learning_rate = 1e-3;  // the task's own Adam
  int channels = 3;             // image channels
  unsigned seed = 1;            // weight initialization
  void validate() const;
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
  // Weights and optimizer state, written atomically; load restores both exactly.
  virtual void save(const std::filesystem::path& path) const = 0;
  virtual void load(const std::filesystem::path& path) = 0;
};

// Whether lensopt was built with libtorch (CMake option LENSOPT_WITH_TORCH).
bool torch_available();

// "restoration" (the built-in small CNN) or "torchscript:MODEL.pt". Throws Error if libtorch is
// not built in, the model cannot be loaded, or the spec is unknown.
std::unique_ptr<Task> make_task(const std::string& spec, const TaskOptions& options);

}  // namespace lensopt
