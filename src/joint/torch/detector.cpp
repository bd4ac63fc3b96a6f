// The detection tasks of joint/detector.h: the built-in CenterNet-style detector and TorchScript
// detectors.
#include "lensopt/joint/detector.h"

#include <torch/script.h>

#include <algorithm>
#include <cmath>

#include "lensopt/core/atomic_file.h"
#include "torch_common.h"

namespace lensopt {
namespace {

constexpr int kStride = 4;
constexpr int kTopDetections = 100;

torch::nn::Conv2d conv(int in, int out, int kernel, int stride) {
  return torch::nn::Conv2d(
      torch::nn::Conv2dOptions(in, out, kernel).stride(stride).padding(kernel / 2));
}

struct DetectorNetImpl : torch::nn::Module {
  explicit DetectorNetImpl(int channels, int classes) {
    s2 = register_module("s2", conv(channels, 16, 3, 2));
    s4a = register_module("s4a", conv(16, 32, 3, 2));
    s4b = register_module("s4b", conv(32, 32, 3, 1));
    s8a = register_module("s8a", conv(32, 64, 3, 2));
    s8b = register_module("s8b", conv(64, 64, 3, 1));
    s16a = register_module("s16a", conv(64, 64, 3, 2));
    s16b = register_module("s16b", conv(64, 64, 3, 1));
    lat8 = register_module("lat8", conv(64, 64, 1, 1));
    lat4 = register_module("lat4", conv(32, 64, 1, 1));
    top8 = register_module("top8", conv(64, 64, 3, 1));
    top4 = register_module("top4", conv(64, 32, 3, 1));
    heat = register_module("heat", conv(32, classes, 1, 1));
    size = register_module("size", conv(32, 2, 1, 1));
    offset = register_module("offset", conv(32, 2, 1, 1));
    torch::NoGradGuard no_grad;
    heat->bias.fill_(std::log(0.1 / 0.9));
  }
  // Heat-map logits (B x K x H/4 x W/4), log sizes and offsets (B x 2 x H/4 x W/4 each).
  std::vector<torch::Tensor> forward(const torch::Tensor& x) {
    namespace F = torch::nn::functional;
    const torch::Tensor f2 = torch::relu(s2(x));
    const torch::Tensor f4 = torch::relu(s4b(torch::relu(s4a(f2))));
    const torch::Tensor f8 = torch::relu(s8b(torch::relu(s8a(f4))));
    const torch::Tensor f16 = torch::relu(s16b(torch::relu(s16a(f8))));
    auto up = [](const torch::Tensor& t, const torch::Tensor& like) {
      return F::interpolate(t, F::InterpolateFuncOptions()
                                   .size(std::vector<int64_t>{like.size(2), like.size(3)})
                                   .mode(torch::kNearest));
    };
    const torch::Tensor t8 = torch::relu(top8(up(f16, f8) + lat8(f8)));
    const torch::Tensor t4 = torch::relu(top4(up(t8, f4) + lat4(f4)));
    return {heat(t4), size(t4), offset(t4)};
  }
  torch::nn::Conv2d s2{nullptr}, s4a{nullptr}, s4b{nullptr}, s8a{nullptr}, s8b{nullptr},
      s16a{nullptr}, s16b{nullptr}, lat8{nullptr}, lat4{nullptr}, top8{nullptr}, top4{nullptr},
      heat{nullptr}, size{nullptr}, offset{nullptr};
};
TORCH_MODULE(DetectorNet);

// The training targets of one batch at the heads' resolution (see joint/detector.h).
struct Targets {
  torch::Tensor heat;         // B x K x h x w
  torch::Tensor index;        // P: flat cell index b * h * w + y * w + x of each object
  torch::Tensor batch_class;  // unused
  torch::Tensor log_size;     // P x 2
  torch::Tensor offset;       // P x 2
  int objects = 0;
};

Targets make_targets(const TaskBatch& batch, int classes, int h, int w, torch::Dtype dtype) {
  const int b = static_cast<int>(batch.rendered.size());
  std::vector<float> heat(static_cast<std::size_t>(b) * classes * h * w, 0.0f);
  std::vector<int64_t> index;
  std::vector<float> log_size, offset;
  for (int i = 0; i < b && i < static_cast<int>(batch.boxes.size()); ++i) {
    for (const GroundTruth& g : batch.boxes[i]) {
      if (g.crowd || g.category < 1 || g.category > classes || g.box.empty()) continue;
      const double cx = 0.5 * (g.box.x0 + g.box.x1) / kStride,
                   cy = 0.5 * (g.box.y0 + g.box.y1) / kStride;
      const int ix = static_cast<int>(std::floor(cx)), iy = static_cast<int>(std::floor(cy));
      if (ix < 0 || iy < 0 || ix >= w || iy >= h) continue;
      const double r = 0.3 * std::min(g.box.width(), g.box.height()) / kStride;
      const double sigma = (2 * r + 1) / 6;
      const int reach = static_cast<int>(std::ceil(3 * sigma));
      float* map = heat.data() + (static_cast<std::size_t>(i) * classes + g.category - 1) * h * w;
      for (int y = std::max(0, iy - reach); y <= std::min(h - 1, iy + reach); ++y)
        for (int x = std::max(0, ix - reach); x <= std::min(w - 1, ix + reach); ++x) {
          const double d2 = (x - ix) * (x - ix) + (y - iy) * (y - iy);
          float& v = map[y * w + x];
          v = std::max(v, static_cast<float>(std::exp(-d2 / (2 * sigma * sigma))));
        }
      index.push_back(static_cast<int64_t>(i) * h * w + iy * w + ix);
      log_size.push_back(static_cast<float>(std::log(g.box.width() / kStride)));
      log_size.push_back(static_cast<float>(std::log(g.box.height() / kStride)));
      offset.push_back(static_cast<float>(cx - ix));
      offset.push_back(static_cast<float>(cy - iy));
    }
  }
  Targets t;
  t.objects = static_cast<int>(index.size());
  t.heat = torch::from_blob(heat.data(), {b, classes, h, w}, torch::kFloat32).to(dtype).clone();
  t.index = torch::tensor(index, torch::kInt64);
  t.log_size = torch::from_blob(log_size.data(), {t.objects, 2}, torch::kFloat32).to(dtype).clone();
  t.offset = torch::from_blob(offset.data(), {t.objects, 2}, torch::kFloat32).to(dtype).clone();
  return t;
}

// The loss of joint/detector.h, mean over the batch.
torch::Tensor detection_loss(const std::vector<torch::Tensor>& out, const Targets& t) {
  const torch::Tensor pred = torch::sigmoid(out[0]).clamp(1e-4, 1 - 1e-4);
  const torch::Tensor pos = t.heat.eq(1.0).to(pred.dtype());
  const torch::Tensor pos_loss = torch::log(pred) * (1 - pred).pow(2) * pos;
  const torch::Tensor neg_loss =
      torch::log(1 - pred) * pred.pow(2) * (1 - t.heat).pow(4) * (1 - pos);
  const double n = std::max(1, t.objects);
  torch::Tensor loss = -(pos_loss.sum() + neg_loss.sum()) / n;
  if (t.objects > 0) {
    // Gather the size and offset predictions at the centre cells: B x 2 x h x w -> (B h w) x 2.
    auto at_centres = [&](const torch::Tensor& map) {
      return map.permute({0, 2, 3, 1}).reshape({-1, 2}).index_select(0, t.index);
    };
    loss = loss + torch::abs(at_centres(out[1]) - t.log_size).sum() / n +
           torch::abs(at_centres(out[2]) - t.offset).sum() / n;
  }
  return loss / static_cast<double>(pred.size(0));
}

// Peaks of the heat maps as detections (joint/detector.h).
std::vector<std::vector<Detection>> decode(const std::vector<torch::Tensor>& out) {
  namespace F = torch::nn::functional;
  const torch::Tensor heat = torch::sigmoid(out[0].detach()).to(torch::kFloat32);
  const torch::Tensor peak =
      heat * heat.eq(F::max_pool2d(heat, F::MaxPool2dFuncOptions(3).stride(1).padding(1)));
  const int64_t b = heat.size(0), k = heat.size(1), h = heat.size(2), w = heat.size(3);
  const int64_t top = std::min<int64_t>(kTopDetections, k * h * w);
  const auto [scores, cells] = peak.reshape({b, -1}).topk(top, 1);
  const torch::Tensor sizes = out[1].detach().to(torch::kFloat32).contiguous();
  const torch::Tensor offsets = out[2].detach().to(torch::kFloat32).contiguous();
  const auto s = scores.accessor<float, 2>();
  const auto c = cells.accessor<int64_t, 2>();
  const auto sz = sizes.accessor<float, 4>();
  const auto of = offsets.accessor<float, 4>();
  std::vector<std::vector<Detection>> result(b);
  for (int64_t i = 0; i < b; ++i)
    for (int64_t j = 0; j < top; ++j) {
      if (!(s[i][j] > 0)) continue;
      const int64_t cell = c[i][j];
      const int64_t cls = cell / (h * w), y = (cell / w) % h, x = cell % w;
      const double cx = (x + of[i][0][y][x]) * kStride, cy = (y + of[i][1][y][x]) * kStride;
      const double bw = std::exp(std::clamp(sz[i][0][y][x], -10.0f, 10.0f)) * kStride;
      const double bh = std::exp(std::clamp(sz[i][1][y][x], -10.0f, 10.0f)) * kStride;
      result[i].push_back({static_cast<int>(i), static_cast<int>(cls) + 1,
                           Box{cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2},
                           static_cast<double>(s[i][j])});
    }
  return result;
}

// COCO AP of a batch's detections against its boxes (image = index in the batch).
double batch_ap(const TaskBatch& batch, const std::vector<std::vector<Detection>>& detections) {
  std::vector<GroundTruth> gts;
  std::vector<Detection> dts;
  for (std::size_t i = 0; i < batch.boxes.size(); ++i)
    for (GroundTruth g : batch.boxes[i]) {
      g.image = static_cast<int>(i);
      gts.push_back(g);
    }
  for (const auto& list : detections) dts.insert(dts.end(), list.begin(), list.end());
  const double ap = evaluate_coco(gts, dts).ap;
  return ap < 0 ? 0.0 : ap;
}

class DetectionTask : public Task {
 public:
  DetectionTask(const TaskOptions& options, int classes) : options_(options), classes_(classes) {
    torch::set_num_threads(options.threads);
    torch::manual_seed(options.seed);
    net_ = DetectorNet(options.channels, classes);
    net_->to(dtype_of(options));
    adam_ = std::make_unique<torch::optim::Adam>(net_->parameters(),
                                                 torch::optim::AdamOptions(options.learning_rate));
  }
  std::string name() const override { return "detection"; }
  std::string metric_name() const override { return "AP"; }

  TaskOutput step(const TaskBatch& batch, bool train, bool want_grad) override {
    return guarded("detection task", [&] {
      TaskOutput out;
      torch::Tensor x = input_tensor(batch, options_);
      const Targets t = make_targets(batch, classes_, (x.size(2) + kStride - 1) / kStride,
                                     (x.size(3) + kStride - 1) / kStride, dtype_of(options_));
      check_head_size(x, t);
      if (!train && !want_grad) {
        torch::NoGradGuard no_grad;
        out.loss = detection_loss(net_->forward(x), t).item<double>();
        return out;
      }
      if (want_grad) x.set_requires_grad(true);
      adam_->zero_grad();
      const torch::Tensor loss = detection_loss(net_->forward(x), t);
      loss.backward();
      out.loss = loss.item<double>();
      if (want_grad) out.grad_rendered = from_tensor(x.grad());
      if (train) adam_->step();
      return out;
    });
  }

  std::vector<std::vector<Detection>> detect(const TaskBatch& batch) override {
    return guarded("detection task", [&] {
      torch::NoGradGuard no_grad;
      return decode(net_->forward(input_tensor(batch, options_)));
    });
  }

  std::vector<FloatImage> predict(const TaskBatch&) override { return {}; }
  bool detects() const override { return true; }

  double metric(const TaskBatch& batch) override { return batch_ap(batch, detect(batch)); }

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
  static void check_head_size(const torch::Tensor& x, const Targets& t) {
    if (x.size(2) % 16 != 0 || x.size(3) % 16 != 0)
      throw Error(
          fmt::format("the built-in detector needs image sides that are multiples of 16 "
                      "(got {}x{})",
                      x.size(3), x.size(2)));
    (void)t;
  }

  TaskOptions options_;
  int classes_;
  DetectorNet net_{nullptr};
  std::unique_ptr<torch::optim::Adam> adam_;
};

class TorchScriptDetectionTask : public Task {
 public:
  TorchScriptDetectionTask(const std::filesystem::path& path, const TaskOptions& options)
      : options_(options), path_(path) {
    torch::set_num_threads(options.threads);
    torch::manual_seed(options.seed);
    module_ = guarded(fmt::format("loading {}", path.string()),
                      [&] { return torch::jit::load(path.string()); });
    module_.to(dtype_of(options));
    module_.train();
    parameters_ = trainable_parameters(module_, path);
    adam_ = std::make_unique<torch::optim::Adam>(parameters_,
                                                 torch::optim::AdamOptions(options.learning_rate));
  }
  std::string name() const override { return "torchscript:" + path_.string(); }
  std::string metric_name() const override { return "AP"; }

  TaskOutput step(const TaskBatch& batch, bool train, bool want_grad) override {
    return guarded(name(), [&] {
      TaskOutput out;
      torch::Tensor x = input_tensor(batch, options_);
      const auto [boxes, labels] = box_tensors(batch);
      module_.train();
      if (!train && !want_grad) {
        torch::NoGradGuard no_grad;
        out.loss = scalar(module_.forward({x, boxes, labels}).toTensor()).item<double>();
        return out;
      }
      if (want_grad) x.set_requires_grad(true);
      adam_->zero_grad();
      const torch::Tensor loss = scalar(module_.forward({x, boxes, labels}).toTensor());
      loss.backward();
      out.loss = loss.item<double>();
      if (want_grad) out.grad_rendered = from_tensor(x.grad());
      if (train) adam_->step();
      return out;
    });
  }

  std::vector<std::vector<Detection>> detect(const TaskBatch& batch) override {
    return guarded(name(), [&] {
      torch::NoGradGuard no_grad;
      const torch::Tensor x = input_tensor(batch, options_);
      const auto [boxes, labels] = box_tensors(batch);
      module_.eval();
      const torch::Tensor p = module_.forward({x, boxes, labels}).toTensor();
      module_.train();
      if (p.dim() != 3 || p.size(0) != x.size(0) || p.size(2) != 6)
        throw Error(
            fmt::format("{}: in evaluation mode forward must return B x M x 6 "
                        "(x0, y0, x1, y1, score, label); got {}",
                        name(), fmt::join(p.sizes(), " x ")));
      const torch::Tensor d = p.to(torch::kFloat64).contiguous();
      const auto a = d.accessor<double, 3>();
      std::vector<std::vector<Detection>> result(d.size(0));
      for (int64_t i = 0; i < d.size(0); ++i)
        for (int64_t j = 0; j < d.size(1); ++j)
          if (a[i][j][4] > 0 && std::isfinite(a[i][j][4]))
            result[i].push_back({static_cast<int>(i), static_cast<int>(std::lround(a[i][j][5])),
                                 Box{a[i][j][0], a[i][j][1], a[i][j][2], a[i][j][3]}, a[i][j][4]});
      return result;
    });
  }

  std::vector<FloatImage> predict(const TaskBatch&) override { return {}; }
  bool detects() const override { return true; }
  double metric(const TaskBatch& batch) override { return batch_ap(batch, detect(batch)); }
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
  torch::Tensor scalar(const torch::Tensor& loss) const {
    if (loss.numel() != 1)
      throw Error(
          fmt::format("{}: in training mode forward must return the scalar loss; got {} "
                      "values",
                      name(), loss.numel()));
    return loss.reshape({});
  }

  // B x N x 4 boxes and B x N labels, padded (joint/detector.h).
  std::pair<torch::Tensor, torch::Tensor> box_tensors(const TaskBatch& batch) const {
    const int64_t b = static_cast<int64_t>(batch.rendered.size());
    std::size_t n = 1;
    for (const auto& list : batch.boxes) n = std::max(n, list.size());
    torch::Tensor boxes = torch::zeros({b, static_cast<int64_t>(n), 4}, torch::kFloat32);
    torch::Tensor labels = torch::full({b, static_cast<int64_t>(n)}, -1, torch::kInt64);
    auto ba = boxes.accessor<float, 3>();
    auto la = labels.accessor<int64_t, 2>();
    for (int64_t i = 0; i < b && i < static_cast<int64_t>(batch.boxes.size()); ++i)
      for (std::size_t j = 0; j < batch.boxes[i].size(); ++j) {
        const GroundTruth& g = batch.boxes[i][j];
        ba[i][j][0] = static_cast<float>(g.box.x0);
        ba[i][j][1] = static_cast<float>(g.box.y0);
        ba[i][j][2] = static_cast<float>(g.box.x1);
        ba[i][j][3] = static_cast<float>(g.box.y1);
        la[i][j] = g.category;
      }
    return {boxes, labels};
  }

  TaskOptions options_;
  std::filesystem::path path_;
  mutable torch::jit::Module module_;
  std::vector<torch::Tensor> parameters_;
  std::unique_ptr<torch::optim::Adam> adam_;
};

}  // namespace

std::unique_ptr<Task> make_detection_task(const TaskOptions& options, int classes) {
  options.validate();
  return std::make_unique<DetectionTask>(options, classes);
}

std::unique_ptr<Task> make_torchscript_detection_task(const std::filesystem::path& model,
                                                      const TaskOptions& options) {
  options.validate();
  return std::make_unique<TorchScriptDetectionTask>(model, options);
}

bool torchscript_forward_takes_boxes(const std::filesystem::path& model) {
  try {
    torch::jit::Module m = torch::jit::load(model.string());
    const auto method = m.find_method("forward");
    if (!method) return false;
    // The schema's arguments include `self`.
    return method->function().getSchema().arguments().size() == 4;
  } catch (const c10::Error& e) {
    throw Error(SourceLocation{model.string()},
                fmt::format("cannot load the TorchScript module: {}", e.what_without_backtrace()));
  }
}

}  // namespace lensopt
