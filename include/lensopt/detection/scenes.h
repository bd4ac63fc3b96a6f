// Generated driving-like scenes with exactly known boxes: the embedded detection dataset of the
// main job and the tests (`lensopt chart --detection -o DIR --count N`).
//
// A scene is a view along a road with a horizon at 40-48 % of the height: sky (vertical gradient
// with value noise), buildings and trees on both sides (textured boxes), a road (perspective
// trapezoid, asphalt value noise, dashed lane marks) and pavements. Objects of the paper's six
// classes (detection/dataset.h: car, bus/truck/tram, bike, person, traffic light, traffic sign)
// stand on the ground plane at depth z, log-uniform in [1, 12]: their image size is s / z (so
// the scale range is 12:1, from boxes of about 8 px to a third of the image at 1280 x 720, as in
// BDD100K), their foot point at horizon + g / z. They are painted back to front, so near objects
// occlude far ones. Every pixel remembers which object painted it last: an object's box is the
// bounding box of its visible pixels (COCO's and BDD100K's convention: the visible extent), and
// an object less than 30 % visible, or whose visible box is under 4 px on a side, gets no box
// (it is still painted: clutter the detector must not be punished for).
// Rendering: 2 x 2 supersampling; a box in output pixels is the supersampled one divided by 2
// (continuous coordinates of detection/boxes.h). Deterministic in the seed.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "lensopt/detection/dataset.h"
#include "lensopt/render/image.h"

namespace lensopt {

struct DetectionScene {
  FloatImage image;                // RGB in [0, 1]
  std::vector<GroundTruth> boxes;  // image id 0; categories of paper_class_map()
};

DetectionScene make_detection_scene(int width, int height, std::uint64_t seed);

struct SceneSetOptions {
  int count = 32;
  int width = 640;
  int height = 360;
  std::uint64_t seed = 1;
  void validate() const;  // throws Error naming the bad value
};

// Writes DIR/images/scene_NNNN.png and DIR/annotations.json (COCO; file names relative to
// DIR/images). Returns the dataset written.
DetectionDataset write_detection_scenes(const std::filesystem::path& dir,
                                        const SceneSetOptions& options);

}  // namespace lensopt
