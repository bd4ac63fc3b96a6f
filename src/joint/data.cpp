#include "lensopt/joint/data.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/render/chart.h"

namespace lensopt {
namespace {

// RGB version of an image: grey replicated, further channels dropped.
FloatImage to_rgb(const FloatImage& in) {
  if (in.channels == 3) return in;
  FloatImage out(in.width, in.height, 3);
  for (int y = 0; y < in.height; ++y)
    for (int x = 0; x < in.width; ++x)
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = in.at(x, y, in.channels >= 3 ? c : 0);
  return out;
}

std::filesystem::path targets_path_of(const std::filesystem::path& image) {
  return image.parent_path() / (image.stem().string() + ".targets.txt");
}

}  // namespace

void DataOptions::validate() const {
  if (batch_size < 1 || batch_size > 4096)
    throw Error(fmt::format("batch size {} must be 1 to 4096", batch_size));
  if (crop_px < 8 || crop_px > 16384)
    throw Error(fmt::format("crop size {} px must be 8 to 16384", crop_px));
  if (!(holdout_fraction > 0.0 && holdout_fraction < 1.0))
    throw Error(fmt::format("held-out fraction {} must be in (0, 1)", holdout_fraction));
  if (eval_crops < 1) throw Error(fmt::format("evaluation crops {} must be >= 1", eval_crops));
  if (images_dir.empty() && annotations.empty()) {
    if (builtin_scenes < 2 || builtin_scenes > 64)
      throw Error(fmt::format("built-in scenes {} must be 2 to 64", builtin_scenes));
    if (builtin_width < crop_px || builtin_height < crop_px || builtin_width > 16384 ||
        builtin_height > 16384)
      throw Error(fmt::format("built-in scenes of {}x{} cannot hold {} px crops", builtin_width,
                              builtin_height, crop_px));
  }
}

FloatImage make_dead_leaves(int width, int height, std::uint64_t seed) {
  // Discs painted back to front on a grey background, radius density ~ r^-3 on [r_min, r_max]
  // (scale invariant), drawn by the inverse CDF r = (r_min^-2 - u (r_min^-2 - r_max^-2))^-1/2.
  constexpr int kSuper = 2;
  const int w = width * kSuper, h = height * kSuper;
  Rng rng(seed * 0x9E3779B97F4A7C15ull + 12345);
  const UniformReal uniform{0.0, 1.0};
  std::vector<float> big(static_cast<std::size_t>(w) * h * 3, 0.5f);
  const double r_min = 1.5 * kSuper, r_max = 0.12 * std::min(w, h);
  const double a = 1.0 / (r_min * r_min), b = 1.0 / (r_max * r_max);
  const double mean_area = kPi * std::log(r_max / r_min) / ((a - b) / 2.0);
  const long discs = static_cast<long>(4.0 * w * h / mean_area) + 1;
  for (long i = 0; i < discs; ++i) {
    const double cx = uniform(rng) * w, cy = uniform(rng) * h;
    const double r = 1.0 / std::sqrt(a - uniform(rng) * (a - b));
    float colour[3];
    // Colours: a random grey level tinted by a random hue, in [0.03, 0.97].
    const double level = 0.03 + 0.94 * uniform(rng);
    for (float& c : colour)
      c = static_cast<float>(std::clamp(level + 0.35 * (uniform(rng) - 0.5), 0.03, 0.97));
    const int x0 = std::max(0, static_cast<int>(std::floor(cx - r)));
    const int x1 = std::min(w - 1, static_cast<int>(std::ceil(cx + r)));
    const int y0 = std::max(0, static_cast<int>(std::floor(cy - r)));
    const int y1 = std::min(h - 1, static_cast<int>(std::ceil(cy + r)));
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const double dx = x + 0.5 - cx, dy = y + 0.5 - cy;
        if (dx * dx + dy * dy > r * r) continue;
        float* p = &big[(static_cast<std::size_t>(y) * w + x) * 3];
        p[0] = colour[0];
        p[1] = colour[1];
        p[2] = colour[2];
      }
  }
  FloatImage out(width, height, 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c) {
        float sum = 0;
        for (int sy = 0; sy < kSuper; ++sy)
          for (int sx = 0; sx < kSuper; ++sx)
            sum += big[(static_cast<std::size_t>(y * kSuper + sy) * w + (x * kSuper + sx)) * 3 + c];
        out.at(x, y, c) = sum / (kSuper * kSuper);
      }
  return out;
}

FloatImage crop_image(const FloatImage& image, const CropWindow& crop) {
  if (crop.x0 < 0 || crop.y0 < 0 || crop.width < 1 || crop.height < 1 ||
      crop.x0 + crop.width > image.width || crop.y0 + crop.height > image.height)
    throw Error(fmt::format("crop {}x{} at ({}, {}) is outside the {}x{} image", crop.width,
                            crop.height, crop.x0, crop.y0, image.width, image.height));
  FloatImage out(crop.width, crop.height, image.channels);
  const std::size_t row = static_cast<std::size_t>(crop.width) * image.channels;
  for (int y = 0; y < crop.height; ++y)
    std::copy_n(&image.pixels[image.index(crop.x0, crop.y0 + y, 0)], row,
                &out.pixels[out.index(0, y, 0)]);
  return out;
}

std::vector<double> read_targets_file(const std::filesystem::path& path) {
  const std::string text = read_file(path);
  std::vector<double> values;
  int line = 1, column = 1;
  std::size_t i = 0;
  while (i < text.size()) {
    const char ch = text[i];
    if (ch == '\n') {
      ++line;
      column = 1;
      ++i;
      continue;
    }
    if (ch == '#') {
      while (i < text.size() && text[i] != '\n') ++i;
      continue;
    }
    if (std::isspace(static_cast<unsigned char>(ch)) || ch == ',') {
      ++i;
      ++column;
      continue;
    }
    std::size_t end = i;
    while (end < text.size() && !std::isspace(static_cast<unsigned char>(text[end])) &&
           text[end] != ',' && text[end] != '#')
      ++end;
    const std::string token = text.substr(i, end - i);
    double v = 0;
    std::istringstream in(token);
    in.imbue(std::locale::classic());
    if (!(in >> v) || !in.eof() || !std::isfinite(v))
      throw Error(SourceLocation{path.string(), line, column},
                  fmt::format("'{}' is not a finite number", token));
    values.push_back(v);
    column += static_cast<int>(end - i);
    i = end;
  }
  return values;
}

JointData::JointData(const DataOptions& options) : options_(options), rng_(options.seed) {
  options_.validate();
  const int c = options_.crop_px;
  if (options_.images_dir.empty() && !detection()) {
    ChartOptions chart_options;
    chart_options.width = options_.builtin_width;
    chart_options.height = options_.builtin_height;
    chart_options.text = false;
    scenes_.push_back({"chart", make_test_chart(chart_options).image, {}, {}});
    for (int i = 1; i < options_.builtin_scenes; ++i)
      scenes_.push_back({fmt::format("dead-leaves-{}", i),
                         make_dead_leaves(options_.builtin_width, options_.builtin_height,
                                          options_.seed * 1000 + i),
                         {},
                         {}});
    for (int i = 0; i + 1 < options_.builtin_scenes; ++i) train_.push_back(i);
    eval_.push_back(options_.builtin_scenes - 1);
    notes_.push_back(fmt::format(
        "built-in scenes: the test chart and {} dead-leaves scenes, {}x{}; held out: {}",
        options_.builtin_scenes - 1, options_.builtin_width, options_.builtin_height,
        scenes_.back().name));
  } else if (detection()) {
    load_detection_dataset();
  } else {
    const std::filesystem::path dir = options_.images_dir;
    if (!std::filesystem::is_directory(dir))
      throw Error(SourceLocation{dir.string()}, "not a directory of images");
    std::vector<std::filesystem::path> files;
    for (const auto& entry : std::filesystem::directory_iterator(dir))
      if (entry.is_regular_file() && is_supported_image(entry.path()))
        files.push_back(entry.path());
    std::sort(files.begin(), files.end());
    for (const auto& file : files) {
      try {
        FloatImage image = to_rgb(read_image(file).image);
        if (image.width < c || image.height < c) {
          notes_.push_back(fmt::format("skipped {}: {}x{} is smaller than a {} px crop",
                                       file.string(), image.width, image.height, c));
          continue;
        }
        const std::filesystem::path t = targets_path_of(file);
        scenes_.push_back({file.filename().string(),
                           std::move(image),
                           std::filesystem::exists(t) ? t : std::filesystem::path(),
                           {}});
      } catch (const Error& e) {
        notes_.push_back(fmt::format("skipped: {}", e.what()));
      }
    }
    if (scenes_.size() < 2)
      throw Error(SourceLocation{dir.string()},
                  fmt::format("{} usable images of at least {} x {} px; the joint optimization "
                              "needs at least 2 (one is held out for evaluation)",
                              scenes_.size(), c, c));
    split_scenes(dir.string());
  }
  // Evaluation tiles.
  std::vector<Sample> tiles;
  for (int s : eval_) {
    const FloatImage& im = scenes_[s].image;
    const int nx = im.width / c, ny = im.height / c;
    const int ox = (im.width - nx * c) / 2, oy = (im.height - ny * c) / 2;
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) tiles.push_back({s, CropWindow{ox + i * c, oy + j * c, c, c}});
  }
  const int count = static_cast<int>(tiles.size());
  const int keep = std::min(count, options_.eval_crops);
  for (int k = 0; k < keep; ++k)
    eval_samples_.push_back(tiles[static_cast<std::size_t>((static_cast<long>(k) * count) / keep)]);
}

// The held-out split of loaded scenes (see the header).
void JointData::split_scenes(const std::string& source) {
  std::vector<int> order(scenes_.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  Rng split_rng(options_.seed ^ 0x5851F42D4C957F2Dull);
  std::shuffle(order.begin(), order.end(), split_rng);
  const int n = static_cast<int>(order.size());
  const int held =
      std::clamp(static_cast<int>(std::lround(options_.holdout_fraction * n)), 1, n - 1);
  eval_.assign(order.begin(), order.begin() + held);
  train_.assign(order.begin() + held, order.end());
  std::sort(eval_.begin(), eval_.end());
  std::sort(train_.begin(), train_.end());
  std::string held_names;
  for (int i : eval_) held_names += (held_names.empty() ? "" : ", ") + scenes_[i].name;
  notes_.push_back(fmt::format("{} images from {}; held out: {}", n, source, held_names));
}

void JointData::load_detection_dataset() {
  const std::filesystem::path json = options_.annotations;
  ClassMap user_classes;
  if (!options_.classes.empty()) user_classes = read_class_map(options_.classes);
  const DetectionDataset dataset =
      read_detection_dataset(json, options_.classes.empty() ? nullptr : &user_classes);
  category_map_ = lensopt::category_map(dataset);
  for (const std::string& note : dataset.notes) notes_.push_back(note);
  std::filesystem::path dir = options_.images_dir;
  if (dir.empty()) {
    dir = json.parent_path() / "images";
    if (!std::filesystem::is_directory(dir)) dir = json.parent_path();
  }
  const int c = options_.crop_px;
  int boxes = 0;
  for (const DetectionImage& image : dataset.images) {
    const std::filesystem::path file = dir / image.file_name;
    try {
      FloatImage pixels = to_rgb(read_image(file).image);
      if ((image.width > 0 && pixels.width != image.width) ||
          (image.height > 0 && pixels.height != image.height)) {
        notes_.push_back(fmt::format("skipped {}: {}x{}, but {} says {}x{}", file.string(),
                                     pixels.width, pixels.height, json.string(), image.width,
                                     image.height));
        continue;
      }
      if (pixels.width < c || pixels.height < c) {
        notes_.push_back(fmt::format("skipped {}: {}x{} is smaller than a {} px crop",
                                     file.string(), pixels.width, pixels.height, c));
        continue;
      }
      Scene scene{image.file_name, std::move(pixels), {}, dataset.annotations_of(image.id)};
      to_class_indices(scene.boxes, category_map_);
      for (GroundTruth& g : scene.boxes) g.image = static_cast<int>(scenes_.size());
      boxes += static_cast<int>(scene.boxes.size());
      scenes_.push_back(std::move(scene));
    } catch (const Error& e) {
      notes_.push_back(fmt::format("skipped: {}", e.what()));
    }
  }
  if (scenes_.size() < 2)
    throw Error(SourceLocation{json.string()},
                fmt::format("{} usable images of at least {} x {} px in {}; the joint "
                            "optimization needs at least 2 (one is held out for evaluation)",
                            scenes_.size(), c, c, dir.string()));
  notes_.push_back(fmt::format("detection dataset {}: {} images, {} boxes, {} categories",
                               json.string(), scenes_.size(), boxes, category_map_.class_count()));
  std::string classes;
  for (int k = 1; k <= category_map_.class_count(); ++k)
    classes += fmt::format("{}{} {} (id {})", k == 1 ? "" : ", ", k,
                           category_map_.classes[k - 1].name, category_map_.category_of(k));
  notes_.push_back("detector classes: " + classes);
  split_scenes(dir.string());
}

std::vector<Sample> JointData::next_batch() {
  std::vector<Sample> batch;
  const int c = options_.crop_px;
  for (int b = 0; b < options_.batch_size; ++b) {
    // Integer draws from the raw generator (uniform_int_distribution's algorithm is fixed by
    // libstdc++, but a modulo of 64 random bits is simpler to reproduce anywhere).
    const int s = train_[rng_() % train_.size()];
    const FloatImage& im = scenes_[s].image;
    const int x0 = static_cast<int>(rng_() % static_cast<std::uint64_t>(im.width - c + 1));
    const int y0 = static_cast<int>(rng_() % static_cast<std::uint64_t>(im.height - c + 1));
    batch.push_back({s, CropWindow{x0, y0, c, c}});
  }
  return batch;
}

FloatImage JointData::crop(const Sample& sample) const {
  return crop_image(scenes_.at(sample.scene).image, sample.crop);
}

std::string JointData::rng_state() const {
  std::ostringstream out;
  out << rng_;
  return out.str();
}

void JointData::set_rng_state(const std::string& state) {
  std::istringstream in(state);
  in >> rng_;
  if (!in) throw Error("corrupt random-generator state in the checkpoint");
}

}  // namespace lensopt
