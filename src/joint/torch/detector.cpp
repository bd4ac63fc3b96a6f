// The detection tasks of joint/detector.h: the built-in CenterNet-style detector and TorchScript
// detectors.
#include "lensopt/joint/detector.h"

#include <torch/script.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "lensopt/core/atomic_file.h"
#include "torch_common.h"

namespace lensopt {
namespace {

// The heads' strides and the box sizes each one is trained on (joint/detector.h): an object
// whose longer side is m pixels belongs to the first level with m < kLevelMaxSide (the last takes
// the rest).
constexpr std::array<int, 3> kStrides = {4, 8, 16};
constexpr std::array<double, 2> kLevelMaxSide = {32.0, 64.0};
constexpr int kTopDetections = 100;
constexpr int kGroups = 8;              // GroupNorm groups of every normalized convolution
constexpr int kWarmupSteps = 100;       // linear learning-rate warm-up of a fresh detector
constexpr double kCrossLevelIoU = 0.6;  // detections of two levels overlapping more: duplicates
// The format of the built-in detector's state files (save/load): 2 since the GroupNorm network
// with heads at three strides; version-1 files (no "detector_version" entry) are refused.
constexpr int64_t kDetectorVersion = 2;

int level_of(const Box& b) {
  const double side = std::max(b.width(), b.height());
  int level = 0;
  while (level < static_cast<int>(kLevelMaxSide.size()) && side >= kLevelMaxSide[level]) ++level;
  return level;
}

// conv k x k (padding k / 2) -> GroupNorm -> ReLU.
struct ConvNormImpl : torch::nn::Module {
  ConvNormImpl(int in, int out, int kernel, int stride) {
    conv = register_module("conv", torch::nn::Conv2d(torch::nn::Conv2dOptions(in, out, kernel)
                                                         .stride(stride)
                                                         .padding(kernel / 2)
                                                         .bias(false)));
    norm = register_module("norm", torch::nn::GroupNorm(kGroups, out));
  }
  torch::Tensor forward(const torch::Tensor& x) { return torch::relu(norm(conv(x))); }
  torch::nn::Conv2d conv{nullptr};
  torch::nn::GroupNorm norm{nullptr};
};
TORCH_MODULE(ConvNorm);

torch::nn::Conv2d conv1x1(int in, int out) {
  return torch::nn::Conv2d(torch::nn::Conv2dOptions(in, out, 1));
}

struct DetectorNetImpl : torch::nn::Module {
  static constexpr int kWidth = 64;  // channels of the pyramid and of the head
  explicit DetectorNetImpl(int channels, int classes) {
    stem = register_module("stem", ConvNorm(channels, 16, 3, 2));
    s4a = register_module("s4a", ConvNorm(16, 32, 3, 2));
    s4b = register_module("s4b", ConvNorm(32, 32, 3, 1));
    s8a = register_module("s8a", ConvNorm(32, 64, 3, 2));
    s8b = register_module("s8b", ConvNorm(64, 64, 3, 1));
    s16a = register_module("s16a", ConvNorm(64, 96, 3, 2));
    s16b = register_module("s16b", ConvNorm(96, 96, 3, 1));
    s32a = register_module("s32a", ConvNorm(96, 128, 3, 2));
    s32b = register_module("s32b", ConvNorm(128, 128, 3, 1));
    lat4 = register_module("lat4", conv1x1(32, kWidth));
    lat8 = register_module("lat8", conv1x1(64, kWidth));
    lat16 = register_module("lat16", conv1x1(96, kWidth));
    lat32 = register_module("lat32", conv1x1(128, kWidth));
    tower = register_module("tower", ConvNorm(kWidth, kWidth, 3, 1));
    heat = register_module("heat", conv1x1(kWidth, classes));
    size = register_module("size", conv1x1(kWidth, 2));
    offset = register_module("offset", conv1x1(kWidth, 2));
    // The output layers start near zero weight, so their first predictions are the biases: the
    // heat prior 0.1 (logit log(0.1 / 0.9)), a box of 4 x 4 cells (the middle of a level's
    // range), the offset of a cell's centre.
    torch::NoGradGuard no_grad;
    for (auto* head : {&heat, &size, &offset}) torch::nn::init::normal_((*head)->weight, 0, 0.01);
    heat->bias.fill_(std::log(0.1 / 0.9));
    size->bias.fill_(std::log(4.0));
    offset->bias.fill_(0.5);
  }
  // Per level (strides 4, 8, 16): heat-map logits (B x K x H/S x W/S), log sizes and offsets
  // (B x 2 x H/S x W/S each), as {heat, size, offset} of level 0, then level 1, ...
  std::vector<torch::Tensor> forward(const torch::Tensor& x) {
    namespace F = torch::nn::functional;
    const torch::Tensor c4 = s4b(s4a(stem(x)));
    const torch::Tensor c8 = s8b(s8a(c4));
    const torch::Tensor c16 = s16b(s16a(c8));
    const torch::Tensor c32 = s32b(s32a(c16));
    auto up = [](const torch::Tensor& t, const torch::Tensor& like) {
      return F::interpolate(t, F::InterpolateFuncOptions()
                                   .size(std::vector<int64_t>{like.size(2), like.size(3)})
                                   .mode(torch::kNearest));
    };
    const torch::Tensor p16 = lat16(c16) + up(lat32(c32), c16);
    const torch::Tensor p8 = lat8(c8) + up(p16, c8);
    const torch::Tensor p4 = lat4(c4) + up(p8, c4);
    std::vector<torch::Tensor> out;
    for (const torch::Tensor& p : {p4, p8, p16}) {
      const torch::Tensor t = tower(p);
      out.push_back(heat(t));
      out.push_back(size(t));
      out.push_back(offset(t));
    }
    return out;
  }
  ConvNorm stem{nullptr}, s4a{nullptr}, s4b{nullptr}, s8a{nullptr}, s8b{nullptr}, s16a{nullptr},
      s16b{nullptr}, s32a{nullptr}, s32b{nullptr}, tower{nullptr};
  torch::nn::Conv2d lat4{nullptr}, lat8{nullptr}, lat16{nullptr}, lat32{nullptr}, heat{nullptr},
      size{nullptr}, offset{nullptr};
};
TORCH_MODULE(DetectorNet);

// The training targets of one batch at one level's resolution (see joint/detector.h).
struct Targets {
  torch::Tensor heat;      // B x K x h x w
  torch::Tensor index;     // P: flat cell index b * h * w + y * w + x of each object
  torch::Tensor log_size;  // P x 2
  torch::Tensor offset;    // P x 2
  int objects = 0;
};

Targets make_targets(const TaskBatch& batch, int classes, int level, int h, int w,
                     torch::Dtype dtype) {
  const int stride = kStrides[level];
  const int b = static_cast<int>(batch.rendered.size());
  std::vector<float> heat(static_cast<std::size_t>(b) * classes * h * w, 0.0f);
  std::vector<int64_t> index;
  std::vector<float> log_size, offset;
  for (int i = 0; i < b && i < static_cast<int>(batch.boxes.size()); ++i) {
    for (const GroundTruth& g : batch.boxes[i]) {
      if (g.crowd || g.category < 1 || g.category > classes || g.box.empty()) continue;
      if (level_of(g.box) != level) continue;
      const double cx = 0.5 * (g.box.x0 + g.box.x1) / stride,
                   cy = 0.5 * (g.box.y0 + g.box.y1) / stride;
      const int ix = static_cast<int>(std::floor(cx)), iy = static_cast<int>(std::floor(cy));
      if (ix < 0 || iy < 0 || ix >= w || iy >= h) continue;
      const double r = 0.3 * std::min(g.box.width(), g.box.height()) / stride;
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
      log_size.push_back(static_cast<float>(std::log(g.box.width() / stride)));
      log_size.push_back(static_cast<float>(std::log(g.box.height() / stride)));
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

// The loss of joint/detector.h, mean over the batch: every level's terms summed, divided by the
// number of objects over all levels.
torch::Tensor detection_loss(const std::vector<torch::Tensor>& out,
                             const std::vector<Targets>& targets) {
  int objects = 0;
  for (const Targets& t : targets) objects += t.objects;
  const double n = std::max(1, objects);
  torch::Tensor loss;
  for (std::size_t level = 0; level < targets.size(); ++level) {
    const Targets& t = targets[level];
    const torch::Tensor& heat = out[3 * level];
    const torch::Tensor pred = torch::sigmoid(heat).clamp(1e-4, 1 - 1e-4);
    const torch::Tensor pos = t.heat.eq(1.0).to(pred.dtype());
    const torch::Tensor pos_loss = torch::log(pred) * (1 - pred).pow(2) * pos;
    const torch::Tensor neg_loss =
        torch::log(1 - pred) * pred.pow(2) * (1 - t.heat).pow(4) * (1 - pos);
    torch::Tensor term = -(pos_loss.sum() + neg_loss.sum()) / n;
    if (t.objects > 0) {
      // Gather the size and offset predictions at the centre cells: B x 2 x h x w -> (B h w) x 2.
      auto at_centres = [&](const torch::Tensor& map) {
        return map.permute({0, 2, 3, 1}).reshape({-1, 2}).index_select(0, t.index);
      };
      term = term + torch::abs(at_centres(out[3 * level + 1]) - t.log_size).sum() / n +
             torch::abs(at_centres(out[3 * level + 2]) - t.offset).sum() / n;
    }
    loss = level == 0 ? term : loss + term;
  }
  return loss / static_cast<double>(out[0].size(0));
}

// Peaks of one level's heat maps as detections (joint/detector.h), at most kTopDetections per
// image, appended to `result`.
void decode_level(const torch::Tensor& heat_logits, const torch::Tensor& size_map,
                  const torch::Tensor& offset_map, int stride,
                  std::vector<std::vector<Detection>>& result) {
  namespace F = torch::nn::functional;
  const torch::Tensor heat = torch::sigmoid(heat_logits.detach()).to(torch::kFloat32);
  const torch::Tensor peak =
      heat * heat.eq(F::max_pool2d(heat, F::MaxPool2dFuncOptions(3).stride(1).padding(1)));
  const int64_t b = heat.size(0), k = heat.size(1), h = heat.size(2), w = heat.size(3);
  const int64_t top = std::min<int64_t>(kTopDetections, k * h * w);
  const auto [scores, cells] = peak.reshape({b, -1}).topk(top, 1);
  const torch::Tensor sizes = size_map.detach().to(torch::kFloat32).contiguous();
  const torch::Tensor offsets = offset_map.detach().to(torch::kFloat32).contiguous();
  const auto s = scores.accessor<float, 2>();
  const auto c = cells.accessor<int64_t, 2>();
  const auto sz = sizes.accessor<float, 4>();
  const auto of = offsets.accessor<float, 4>();
  for (int64_t i = 0; i < b; ++i)
    for (int64_t j = 0; j < top; ++j) {
      if (!(s[i][j] > 0)) continue;
      const int64_t cell = c[i][j];
      const int64_t cls = cell / (h * w), y = (cell / w) % h, x = cell % w;
      const double cx = (x + of[i][0][y][x]) * stride, cy = (y + of[i][1][y][x]) * stride;
      const double bw = std::exp(std::clamp(sz[i][0][y][x], -10.0f, 10.0f)) * stride;
      const double bh = std::exp(std::clamp(sz[i][1][y][x], -10.0f, 10.0f)) * stride;
      result[i].push_back({static_cast<int>(i), static_cast<int>(cls) + 1,
                           Box{cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2},
                           static_cast<double>(s[i][j])});
    }
}

// Every level's peaks; a detection overlapping a higher-scoring one of the same class from
// another level by IoU > kCrossLevelIoU is dropped (the same object seen at two strides); the
// best kTopDetections per image are kept, by score.
std::vector<std::vector<Detection>> decode(const std::vector<torch::Tensor>& out) {
  const int64_t b = out[0].size(0);
  std::vector<std::vector<std::pair<Detection, int>>> tagged(b);
  for (std::size_t level = 0; level < kStrides.size(); ++level) {
    std::vector<std::vector<Detection>> found(b);
    decode_level(out[3 * level], out[3 * level + 1], out[3 * level + 2], kStrides[level], found);
    for (int64_t i = 0; i < b; ++i)
      for (const Detection& d : found[i]) tagged[i].push_back({d, static_cast<int>(level)});
  }
  std::vector<std::vector<Detection>> result(b);
  for (int64_t i = 0; i < b; ++i) {
    auto& list = tagged[i];
    std::stable_sort(list.begin(), list.end(),
                     [](const auto& a, const auto& c) { return a.first.score > c.first.score; });
    std::vector<std::pair<Detection, int>> kept;
    for (const auto& candidate : list) {
      if (static_cast<int>(kept.size()) == kTopDetections) break;
      const bool duplicate = std::any_of(kept.begin(), kept.end(), [&](const auto& k) {
        return k.second != candidate.second && k.first.category == candidate.first.category &&
               iou(k.first.box, candidate.first.box) > kCrossLevelIoU;
      });
      if (!duplicate) kept.push_back(candidate);
    }
    for (const auto& k : kept) result[i].push_back(k.first);
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

// The Adam steps taken by a network's parameters (0 before the first; restored by load).
int64_t adam_steps(const torch::optim::Adam& adam) {
  for (const auto& entry : adam.state())
    return static_cast<const torch::optim::AdamParamState&>(*entry.second).step();
  return 0;
}

class DetectionTask : public Task {
 public:
  DetectionTask(const TaskOptions& options, int classes)
      : options_(options), classes_(classes), learning_rate_(options.learning_rate) {
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
      check_image_size(x);
      std::vector<Targets> targets;
      for (std::size_t level = 0; level < kStrides.size(); ++level)
        targets.push_back(make_targets(
            batch, classes_, static_cast<int>(level), static_cast<int>(x.size(2)) / kStrides[level],
            static_cast<int>(x.size(3)) / kStrides[level], dtype_of(options_)));
      if (!train && !want_grad) {
        torch::NoGradGuard no_grad;
        out.loss = detection_loss(net_->forward(x), targets).item<double>();
        return out;
      }
      if (want_grad) x.set_requires_grad(true);
      adam_->zero_grad();
      const torch::Tensor loss = detection_loss(net_->forward(x), targets);
      loss.backward();
      out.loss = loss.item<double>();
      if (want_grad) out.grad_rendered = from_tensor(x.grad());
      if (train) {
        // Warm-up: the k-th step of a fresh detector (k = 1, 2, ...) uses min(1, k / W) of the
        // scheduled rate; a loaded detector continues its own step count.
        const double warm =
            std::min(1.0, static_cast<double>(adam_steps(*adam_) + 1) / kWarmupSteps);
        set_adam_learning_rate(*adam_, learning_rate_ * warm);
        adam_->step();
      }
      return out;
    });
  }

  std::vector<std::vector<Detection>> detect(const TaskBatch& batch) override {
    return guarded("detection task", [&] {
      torch::NoGradGuard no_grad;
      const torch::Tensor x = input_tensor(batch, options_);
      check_image_size(x);
      return decode(net_->forward(x));
    });
  }

  std::vector<FloatImage> predict(const TaskBatch&) override { return {}; }
  bool detects() const override { return true; }

  double metric(const TaskBatch& batch) override { return batch_ap(batch, detect(batch)); }

  void set_learning_rate(double learning_rate) override { learning_rate_ = learning_rate; }

  // The network, the Adam state and "detector_version" in one libtorch archive.
  void save(const std::filesystem::path& path) const override {
    guarded(fmt::format("saving {}", path.string()), [&] {
      torch::serialize::OutputArchive archive, optimizer;
      net_->save(archive);
      adam_->save(optimizer);
      archive.write("optimizer", optimizer);
      archive.write("detector_version", torch::tensor(kDetectorVersion, torch::kInt64));
      write_file_atomic_with(
          path, [&](const std::filesystem::path& tmp) { archive.save_to(tmp.string()); });
      return 0;
    });
  }
  void load(const std::filesystem::path& path) override {
    guarded(fmt::format("loading {}", path.string()), [&] {
      torch::serialize::InputArchive archive, optimizer;
      archive.load_from(path.string());
      torch::Tensor version;
      const int64_t v = archive.try_read("detector_version", version) ? version.item<int64_t>() : 1;
      if (v != kDetectorVersion)
        throw Error(SourceLocation{path.string()},
                    fmt::format("a state file of the built-in detector's version {}, this "
                                "lensopt's detector is version {} (GroupNorm, heads at strides "
                                "4, 8, 16): train the detector again (--perfect-steps) instead "
                                "of reusing it (--detector, --resume)",
                                v, kDetectorVersion));
      net_->load(archive);
      net_->to(dtype_of(options_));
      archive.read("optimizer", optimizer);
      adam_->load(optimizer);
      return 0;
    });
  }
  void save_network(const std::filesystem::path& path) const override {
    save_network_weights(path, *net_);
  }

 private:
  static void check_image_size(const torch::Tensor& x) {
    if (x.size(2) % 16 != 0 || x.size(3) % 16 != 0)
      throw Error(
          fmt::format("the built-in detector needs image sides that are multiples of 16 "
                      "(got {}x{})",
                      x.size(3), x.size(2)));
  }

  TaskOptions options_;
  int classes_;
  double learning_rate_;  // the schedule's rate (set_learning_rate), before the warm-up
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
