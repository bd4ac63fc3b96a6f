// Training data of the joint optimization: sharp scene images cut into random crops.
//
// Scenes. A directory of images (PNG, JPEG, TIFF, EXR; sorted by file name; corrupt files are
// reported and skipped), each converted to RGB (grey replicated, alpha dropped). Without a
// directory, the built-in scenes: the project's test chart (render/chart.h, without text) and
// `builtin_scenes - 1` "dead leaves" scenes (occluding discs of random colour and log-uniform
// radii, the image-quality community's model of natural-image statistics: edges at every scale and
// orientation), all at builtin_width x builtin_height, generated from the seed. One chart is too
// little to train a restorer and gives no held-out image; the dead-leaves scenes add both.
// Every scene is rendered as a full sensor image: its own size fixes the pixel pitch
// (render/render.h), and a crop keeps its CropWindow so it sees the PSFs of where it lies.
//
// Split. Built-in: the last dead-leaves scene is held out. Directory: the scenes are shuffled
// with the seed and the first round(holdout_fraction N) (at least 1) are held out; at least two
// images are needed.
//
// Crops. A training batch is batch_size crops of crop_px x crop_px: per crop a training scene
// uniformly, then x0 uniform in [0, W - crop_px], y0 in [0, H - crop_px] (std::mt19937_64 seeded
// with the seed; its state is saved in checkpoints so a resumed run draws the same crops). A scene
// smaller than the crop is rejected. Evaluation crops are fixed: on each held-out scene, the
// floor(W / crop_px) x floor(H / crop_px) tiles, centred, at most eval_crops in all (evenly spread
// over the tiles in raster order).
//
// Detection datasets (`annotations`: a COCO or BDD100K JSON, detection/dataset.h; with `classes`
// a user's [classes] map gathers the categories of either, else BDD100K's go through the paper's
// six-class map and COCO's stay as written): the boxes' categories become the classes 1..K of
// category_map() (in order of id; COCO's ids 1, 3, 18 are classes 1, 2, 3), which the detector
// trains on; evaluations report the dataset's ids. The scenes are the annotated images, read from
// `images_dir` (default: the folder `images` beside the JSON if it exists, else the JSON's own
// folder) by their file names; an image that is missing, corrupt, smaller than a crop, or whose
// size differs from the one the JSON states is reported and skipped, and so are bad annotations.
// Each scene keeps its boxes (scene pixels; detection/crop_boxes.h moves them with the crops).
// The split is the directory's (shuffled with the seed, round(holdout_fraction N) held out).
//
// Targets (for user tasks): beside IMAGE.ext, an optional IMAGE.targets.txt: numbers separated by
// white space or commas, '#' starts a comment to the end of the line. The numbers are passed as
// they are (no crop transform): a task that needs image coordinates should use crops of the whole
// image (crop_px = the image size).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "lensopt/core/random.h"
#include "lensopt/detection/dataset.h"
#include "lensopt/joint/imaging.h"
#include "lensopt/render/image.h"

namespace lensopt {

struct DataOptions {
  std::filesystem::path images_dir;   // empty: the built-in scenes (or, with annotations, the
                                      // folder beside the JSON)
  std::filesystem::path annotations;  // a COCO or BDD100K JSON: a detection dataset
  std::filesystem::path classes;      // a TOML file with a [classes] map (empty: none)
  int batch_size = 4;
  int crop_px = 256;
  double holdout_fraction = 0.2;  // directory: share of images held out for evaluation
  int eval_crops = 8;             // evaluation crops over the held-out scenes
  std::uint64_t seed = 1;
  int builtin_scenes = 6;  // chart + 5 dead-leaves scenes
  int builtin_width = 1280;
  int builtin_height = 720;

  void validate() const;  // throws Error naming the bad value
};

struct Scene {
  std::string name;
  FloatImage image;                // RGB, [0, 1]
  std::filesystem::path targets;   // IMAGE.targets.txt, or empty
  std::vector<GroundTruth> boxes;  // detection datasets: the image's boxes (scene pixels)
};

// One crop of one scene.
struct Sample {
  int scene = 0;
  CropWindow crop;
};

class JointData {
 public:
  // Loads or generates the scenes. Throws Error for a missing directory, too few usable images,
  // or images smaller than a crop.
  explicit JointData(const DataOptions& options);

  const DataOptions& options() const { return options_; }
  const std::vector<Scene>& scenes() const { return scenes_; }
  const std::vector<int>& train_scenes() const { return train_; }
  const std::vector<int>& eval_scenes() const { return eval_; }
  // Notes for the log: skipped files, what the built-in scenes are.
  const std::vector<std::string>& notes() const { return notes_; }
  // Whether the scenes carry boxes (a detection dataset), and its classes: Scene::boxes hold
  // class indices 1..K of this map, which also leads back to the dataset's category ids.
  bool detection() const { return !options_.annotations.empty(); }
  const std::vector<DetectionCategory>& categories() const { return category_map_.classes; }
  const CategoryMap& category_map() const { return category_map_; }

  // The next training batch (advances the generator).
  std::vector<Sample> next_batch();
  // Restarts the generator from the seed (each setting sees the same crops).
  void restart() { rng_.seed(options_.seed); }
  // The fixed evaluation crops.
  const std::vector<Sample>& eval_samples() const { return eval_samples_; }

  // The sharp pixels of a sample.
  FloatImage crop(const Sample& sample) const;

  // The generator's state as text (std::mt19937_64's stream form), and back.
  std::string rng_state() const;
  void set_rng_state(const std::string& state);

 private:
  DataOptions options_;
  std::vector<Scene> scenes_;
  std::vector<int> train_, eval_;
  std::vector<Sample> eval_samples_;
  std::vector<std::string> notes_;
  CategoryMap category_map_;
  Rng rng_;

  void load_detection_dataset();
  void split_scenes(const std::string& source);
};

// The dead-leaves scene of a seed (RGB, [0, 1], 2 x 2 supersampled).
FloatImage make_dead_leaves(int width, int height, std::uint64_t seed);

// The sharp crop of an image.
FloatImage crop_image(const FloatImage& image, const CropWindow& crop);

// Reads a targets file (format above). Throws Error with file:line:column for a bad number.
std::vector<double> read_targets_file(const std::filesystem::path& path);

}  // namespace lensopt
