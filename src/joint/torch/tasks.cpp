// The libtorch tasks of joint/task.h: the built-in restoration CNN and TorchScript user tasks.
// This file and detector.cpp, built as the module liblensopt_torch.so (joint/torch_plugin.h), are
// the only ones that include libtorch's headers.
#include <fmt/format.h>
#include <torch/script.h>
#include <torch/torch.h>

#include <cmath>
#include <map>

#include "joint/torch_plugin.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/joint/data.h"
#include "lensopt/joint/detector.h"
#include "lensopt/joint/task.h"
#include "torch_common.h"

namespace lensopt {
namespace {

// The restoration network y = x + N(x) (task.h).
struct RestorationNetImpl : torch::nn::Module {
  RestorationNetImpl(int channels, int features, int layers) {
    for (int l = 0; l < layers; ++l) {
      const int in = l == 0 ? channels : features;
      const int out = l == layers - 1 ? channels : features;
      convs.push_back(register_module(
          fmt::format("conv{}", l),
          torch::nn::Conv2d(
              torch::nn::Conv2dOptions(in, out, 3).padding(1).padding_mode(torch::kReflect))));
    }
    // The last layer starts at 0: the untrained network is the identity.
    torch::NoGradGuard no_grad;
    convs.back()->weight.zero_();
    convs.back()->bias.zero_();
  }
  torch::Tensor forward(const torch::Tensor& x) {
    torch::Tensor h = x;
    for (std::size_t l = 0; l < convs.size(); ++l) {
      h = convs[l]->forward(h);
      if (l + 1 < convs.size()) h = torch::relu(h);
    }
    return x + h;
  }
  std::vector<torch::nn::Conv2d> convs;
};
TORCH_MODULE(RestorationNet);

class RestorationTask : public Task {
 public:
  explicit RestorationTask(const TaskOptions& options) : options_(options) {
    torch::set_num_threads(options.threads);
    torch::manual_seed(options.seed);
    net_ = RestorationNet(options.channels, options.features, options.layers);
    net_->to(dtype_of(options));
    adam_ = std::make_unique<torch::optim::Adam>(net_->parameters(),
                                                 torch::optim::AdamOptions(options.learning_rate));
  }
  std::string name() const override { return "restoration"; }
  std::string metric_name() const override { return "PSNR (dB)"; }

  TaskOutput step(const TaskBatch& batch, bool train, bool want_grad) override {
    return guarded("restoration task", [&] {
      TaskOutput out;
      torch::Tensor x = input_tensor(batch, options_);
      const torch::Tensor y = to_tensor(batch.sharp, options_.channels, dtype_of(options_));
      if (!train && !want_grad) {
        torch::NoGradGuard no_grad;
        out.loss = torch::mse_loss(net_->forward(x), y).item<double>();
        return out;
      }
      if (want_grad) x.set_requires_grad(true);
      adam_->zero_grad();
      const torch::Tensor loss = torch::mse_loss(net_->forward(x), y);
      loss.backward();
      out.loss = loss.item<double>();
      if (want_grad) out.grad_rendered = from_tensor(x.grad());
      if (train) adam_->step();
      return out;
    });
  }

  std::vector<FloatImage> predict(const TaskBatch& batch) override {
    return guarded("restoration task", [&] {
      torch::NoGradGuard no_grad;
      const torch::Tensor x = input_tensor(batch, options_);
      return from_tensor(net_->forward(x).clamp(0.0, 1.0));
    });
  }

  double metric(const TaskBatch& batch) override {
    return guarded("restoration task", [&] {
      torch::NoGradGuard no_grad;
      const torch::Tensor x = input_tensor(batch, options_);
      const torch::Tensor y = to_tensor(batch.sharp, options_.channels, dtype_of(options_));
      const torch::Tensor restored = net_->forward(x).clamp(0.0, 1.0);
      const torch::Tensor mse = (restored - y).pow(2).mean({1, 2, 3}).to(torch::kFloat64);
      // PSNR with peak 1: 10 log10(1 / MSE) per image (MSE floored at 1e-12: 120 dB).
      return (-10.0 * torch::log10(mse.clamp_min(1e-12))).mean().item<double>();
    });
  }

  void set_learning_rate(double learning_rate) override {
    set_adam_learning_rate(*adam_, learning_rate);
  }

  void save(const std::filesystem::path& path) const override {
    save_network_and_adam(path, *net_, *adam_);
  }
  void load(const std::filesystem::path& path) override {
    load_network_and_adam(path, *net_, *adam_, dtype_of(options_));
  }
  void save_network(const std::filesystem::path& path) const override {
    save_network_weights(path, *net_);
  }

 private:
  TaskOptions options_;
  RestorationNet net_{nullptr};
  std::unique_ptr<torch::optim::Adam> adam_;
};

class TorchScriptTask : public Task {
 public:
  TorchScriptTask(const std::filesystem::path& model_path, const TaskOptions& options)
      : options_(options), path_(model_path) {
    torch::set_num_threads(options.threads);
    torch::manual_seed(options.seed);
    if (!std::filesystem::is_regular_file(model_path))
      throw Error(SourceLocation{model_path.string()}, "TorchScript model file not found");
    try {
      module_ = torch::jit::load(model_path.string());
    } catch (const c10::Error& e) {
      throw Error(
          SourceLocation{model_path.string()},
          fmt::format("cannot load the TorchScript module: {}", e.what_without_backtrace()));
    }
    if (!module_.find_method("forward"))
      throw Error(SourceLocation{model_path.string()},
                  "the TorchScript module has no forward(images, targets)");
    module_.to(dtype_of(options));
    module_.train();
    parameters_ = trainable_parameters(module_, model_path);
    adam_ = std::make_unique<torch::optim::Adam>(parameters_,
                                                 torch::optim::AdamOptions(options.learning_rate));
  }
  std::string name() const override { return "torchscript:" + path_.string(); }
  std::string metric_name() const override { return "-loss"; }

  TaskOutput step(const TaskBatch& batch, bool train, bool want_grad) override {
    return guarded(name(), [&] {
      TaskOutput out;
      torch::Tensor x = input_tensor(batch, options_);
      const torch::Tensor targets = targets_of(batch);
      if (!train && !want_grad) {
        torch::NoGradGuard no_grad;
        out.loss = loss_of(x, targets).item<double>();
        return out;
      }
      if (want_grad) x.set_requires_grad(true);
      adam_->zero_grad();
      const torch::Tensor loss = loss_of(x, targets);
      loss.backward();
      out.loss = loss.item<double>();
      if (want_grad) out.grad_rendered = from_tensor(x.grad());
      if (train) adam_->step();
      return out;
    });
  }

  std::vector<FloatImage> predict(const TaskBatch&) override { return {}; }

  double metric(const TaskBatch& batch) override { return -step(batch, false, false).loss; }

  void set_learning_rate(double learning_rate) override {
    set_adam_learning_rate(*adam_, learning_rate);
  }

  void save(const std::filesystem::path& path) const override {
    save_parameters_and_adam(path, parameters_, *adam_);
  }
  void load(const std::filesystem::path& path) override {
    load_parameters_and_adam(path, parameters_, *adam_);
  }
  void save_network(const std::filesystem::path& path) const override {
    save_torchscript_module(path, module_);
  }

 private:
  torch::Tensor loss_of(const torch::Tensor& x, const torch::Tensor& targets) {
    const torch::Tensor loss = module_.forward({x, targets}).toTensor();
    if (loss.numel() != 1)
      throw Error(fmt::format("{}: forward returned {} values; it must return the scalar loss",
                              name(), loss.numel()));
    return loss.reshape({});
  }

  // B x N targets from the batch's files, or the sharp crops when there are none.
  torch::Tensor targets_of(const TaskBatch& batch) {
    std::size_t with = 0;
    for (const auto& t : batch.targets) with += !t.empty();
    if (with == 0) return to_tensor(batch.sharp, options_.channels, dtype_of(options_));
    if (with != batch.rendered.size())
      throw Error(
          fmt::format("{}: {} of {} images of the batch have a targets file; all or none "
                      "must",
                      name(), with, batch.rendered.size()));
    std::vector<torch::Tensor> rows;
    for (const auto& path : batch.targets) {
      auto it = targets_.find(path.string());
      if (it == targets_.end()) it = targets_.emplace(path.string(), read_targets_file(path)).first;
      const std::vector<double>& v = it->second;
      if (!rows.empty() && static_cast<int64_t>(v.size()) != rows[0].size(0))
        throw Error(SourceLocation{path.string()},
                    fmt::format("{} targets where the batch's first image has {}", v.size(),
                                rows[0].size(0)));
      rows.push_back(torch::tensor(v, torch::kFloat64));
    }
    return torch::stack(rows).to(dtype_of(options_));
  }

  TaskOptions options_;
  std::filesystem::path path_;
  mutable torch::jit::Module module_;
  std::vector<torch::Tensor> parameters_;
  std::unique_ptr<torch::optim::Adam> adam_;
  std::map<std::string, std::vector<double>> targets_;
};

}  // namespace

std::unique_ptr<Task> make_torch_task(const std::string& spec, const TaskOptions& options) {
  options.validate();
  if (spec == "restoration") return std::make_unique<RestorationTask>(options);
  const std::string prefix = "torchscript:";
  if (spec == "detection") return make_detection_task(options, kDetectorClasses);
  if (spec.rfind(prefix, 0) == 0 && spec.size() > prefix.size()) {
    const std::filesystem::path model = spec.substr(prefix.size());
    if (std::filesystem::is_regular_file(model) && torchscript_forward_takes_boxes(model))
      return make_torchscript_detection_task(model, options);
    return std::make_unique<TorchScriptTask>(model, options);
  }
  throw Error(
      fmt::format("unknown task '{}'; known: restoration, detection, torchscript:MODEL.pt", spec));
}

}  // namespace lensopt

// The module's one exported symbol (joint/torch_plugin.h).
extern "C" __attribute__((visibility("default"))) const lensopt::TorchPlugin*
lensopt_torch_plugin() {
  static const lensopt::TorchPlugin plugin{lensopt::kTorchPluginAbi, sizeof(lensopt::TaskBatch),
                                           sizeof(lensopt::TaskOptions), &lensopt::make_torch_task,
                                           &lensopt::torchscript_forward_takes_boxes};
  return &plugin;
}
