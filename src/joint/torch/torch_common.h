// Tensor helpers shared by the libtorch tasks (src/joint/torch/ only: it includes libtorch).
#pragma once

#include <fmt/format.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/joint/task.h"

namespace lensopt {

// The tasks' factories inside the module (task.h and detector.h say what they make).
std::unique_ptr<Task> make_torch_task(const std::string& spec, const TaskOptions& options);
std::unique_ptr<Task> make_detection_task(const TaskOptions& options, int classes);
std::unique_ptr<Task> make_torchscript_detection_task(const std::filesystem::path& model,
                                                      const TaskOptions& options);
// Whether a TorchScript file's forward takes (images, boxes, labels): a detector.
bool torchscript_forward_takes_boxes(const std::filesystem::path& model);

inline torch::Dtype dtype_of(const TaskOptions& options) {
  return options.double_precision ? torch::kFloat64 : torch::kFloat32;
}

// B x C x H x W tensor (a copy) of a batch of interleaved images.
inline torch::Tensor to_tensor(const std::vector<FloatImage>& images, int channels,
                               torch::Dtype dtype) {
  if (images.empty()) throw Error("a task batch must hold at least one image");
  std::vector<torch::Tensor> list;
  for (const FloatImage& im : images) {
    if (im.channels != channels || im.width != images[0].width || im.height != images[0].height)
      throw Error(
          fmt::format("task batch: a {}x{}x{} image among {}x{}x{} ones (the task has {} "
                      "channels)",
                      im.width, im.height, im.channels, images[0].width, images[0].height,
                      images[0].channels, channels));
    list.push_back(torch::from_blob(const_cast<float*>(im.pixels.data()),
                                    {im.height, im.width, im.channels}, torch::kFloat32)
                       .permute({2, 0, 1}));
  }
  return torch::stack(list).to(dtype).contiguous();
}

// The task's input: the rendered crops, or their double values when given and the task runs in
// double.
inline torch::Tensor input_tensor(const TaskBatch& batch, const TaskOptions& options) {
  if (batch.rendered_values.empty() || !options.double_precision)
    return to_tensor(batch.rendered, options.channels, dtype_of(options));
  if (batch.rendered_values.size() != batch.rendered.size())
    throw Error("task batch: rendered_values must match rendered, image for image");
  std::vector<torch::Tensor> list;
  for (std::size_t i = 0; i < batch.rendered.size(); ++i) {
    const FloatImage& im = batch.rendered[i];
    if (batch.rendered_values[i].size() != im.pixels.size() || im.channels != options.channels)
      throw Error("task batch: rendered_values must match rendered, image for image");
    list.push_back(torch::from_blob(const_cast<double*>(batch.rendered_values[i].data()),
                                    {im.height, im.width, im.channels}, torch::kFloat64)
                       .permute({2, 0, 1}));
  }
  return torch::stack(list).contiguous();
}

inline std::vector<FloatImage> from_tensor(const torch::Tensor& t) {
  const torch::Tensor hwc = t.detach().to(torch::kFloat32).permute({0, 2, 3, 1}).contiguous();
  const int b = static_cast<int>(hwc.size(0)), h = static_cast<int>(hwc.size(1)),
            w = static_cast<int>(hwc.size(2)), c = static_cast<int>(hwc.size(3));
  std::vector<FloatImage> out;
  const float* data = hwc.data_ptr<float>();
  for (int i = 0; i < b; ++i) {
    FloatImage im(w, h, c);
    std::copy_n(data + static_cast<std::size_t>(i) * w * h * c, im.pixels.size(),
                im.pixels.begin());
    out.push_back(std::move(im));
  }
  return out;
}

// Runs a libtorch call, turning its exceptions into lensopt::Error with a context.
template <typename F>
auto guarded(const std::string& context, F&& f) {
  try {
    return f();
  } catch (const c10::Error& e) {
    throw Error(fmt::format("{}: {}", context, e.what_without_backtrace()));
  }
}

inline void set_adam_learning_rate(torch::optim::Adam& adam, double learning_rate) {
  for (auto& group : adam.param_groups())
    static_cast<torch::optim::AdamOptions&>(group.options()).lr(learning_rate);
}

// The parameters of a TorchScript module that Adam trains: those that require a gradient
// (PyTorch's nn.Parameter default); a module saved with none flagged (e.g. defined in C++) trains
// all of them. Throws Error naming the file if it has none.
inline std::vector<torch::Tensor> trainable_parameters(const torch::jit::Module& module,
                                                       const std::filesystem::path& path) {
  std::vector<torch::Tensor> parameters;
  for (const torch::Tensor& p : module.parameters())
    if (p.requires_grad()) parameters.push_back(p);
  if (parameters.empty())
    for (torch::Tensor p : module.parameters()) parameters.push_back(p.requires_grad_(true));
  if (parameters.empty())
    throw Error(SourceLocation{path.string()},
                "the TorchScript module has no trainable parameters");
  return parameters;
}

// A TorchScript task's state: its trained parameters and its Adam state, written atomically to
// one libtorch archive ("p0", "p1", ..., "optimizer") and read back exactly.
inline void save_parameters_and_adam(const std::filesystem::path& path,
                                     const std::vector<torch::Tensor>& parameters,
                                     torch::optim::Adam& adam) {
  guarded(fmt::format("saving {}", path.string()), [&] {
    torch::serialize::OutputArchive archive, optimizer;
    for (std::size_t i = 0; i < parameters.size(); ++i)
      archive.write(fmt::format("p{}", i), parameters[i]);
    adam.save(optimizer);
    archive.write("optimizer", optimizer);
    write_file_atomic_with(
        path, [&](const std::filesystem::path& tmp) { archive.save_to(tmp.string()); });
    return 0;
  });
}

inline void load_parameters_and_adam(const std::filesystem::path& path,
                                     std::vector<torch::Tensor>& parameters,
                                     torch::optim::Adam& adam) {
  guarded(fmt::format("loading {}", path.string()), [&] {
    torch::serialize::InputArchive archive, optimizer;
    archive.load_from(path.string());
    torch::NoGradGuard no_grad;
    for (std::size_t i = 0; i < parameters.size(); ++i) {
      torch::Tensor value;
      archive.read(fmt::format("p{}", i), value);
      parameters[i].copy_(value);
    }
    archive.read("optimizer", optimizer);
    adam.load(optimizer);
    return 0;
  });
}

// A built-in task's state: its network's weights and its Adam state in one libtorch archive
// (the network's entries and "optimizer"), written atomically and read back exactly.
inline void save_network_and_adam(const std::filesystem::path& path, const torch::nn::Module& net,
                                  torch::optim::Adam& adam) {
  guarded(fmt::format("saving {}", path.string()), [&] {
    torch::serialize::OutputArchive archive, optimizer;
    net.save(archive);
    adam.save(optimizer);
    archive.write("optimizer", optimizer);
    write_file_atomic_with(
        path, [&](const std::filesystem::path& tmp) { archive.save_to(tmp.string()); });
    return 0;
  });
}

inline void load_network_and_adam(const std::filesystem::path& path, torch::nn::Module& net,
                                  torch::optim::Adam& adam, torch::Dtype dtype) {
  guarded(fmt::format("loading {}", path.string()), [&] {
    torch::serialize::InputArchive archive, optimizer;
    archive.load_from(path.string());
    net.load(archive);
    net.to(dtype);
    archive.read("optimizer", optimizer);
    adam.load(optimizer);
    return 0;
  });
}

// A built-in task's network weights alone (a libtorch archive), written atomically.
inline void save_network_weights(const std::filesystem::path& path, const torch::nn::Module& net) {
  guarded(fmt::format("saving {}", path.string()), [&] {
    torch::serialize::OutputArchive archive;
    net.save(archive);
    write_file_atomic_with(
        path, [&](const std::filesystem::path& tmp) { archive.save_to(tmp.string()); });
    return 0;
  });
}

// The TorchScript module itself, loadable by torch.jit.load, written atomically.
inline void save_torchscript_module(const std::filesystem::path& path,
                                    const torch::jit::Module& module) {
  guarded(fmt::format("saving {}", path.string()), [&] {
    write_file_atomic_with(path,
                           [&](const std::filesystem::path& tmp) { module.save(tmp.string()); });
    return 0;
  });
}

}  // namespace lensopt
