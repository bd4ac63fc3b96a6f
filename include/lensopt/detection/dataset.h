// Detection datasets as researchers have them: COCO-format JSON and BDD100K label JSON.
//
// COCO ("instances" files): {"images": [{id, file_name, width, height}], "categories": [{id,
// name}], "annotations": [{id, image_id, category_id, bbox: [x, y, w, h], area, iscrowd}]}; boxes
// in pixels with (x, y) the top-left corner (detection/boxes.h's coordinates). Other keys are
// ignored; written files carry exactly these keys.
//
// BDD100K (det_20 / "labels" files): a list of frames {"name": "IMAGE.jpg", "labels": [{"category":
// NAME, "box2d": {"x1", "y1", "x2", "y2"}, "attributes": {...}}]}; labels without box2d (lanes,
// drivable areas) are skipped silently. Categories are mapped to classes by a class map; a name
// the map does not list is skipped and counted. BDD100K's x2, y2 are inclusive pixel indices
// of the last pixel, so the box is [x1, x2 + 1) x [y1, y2 + 1) in our continuous coordinates.
//
// The paper's six aggregated classes (section "Automotive Object Detection"): car (car, van,
// suv), bus/truck/tram (bus, truck, train, tram), bike (bike, bicycle, motor, motorcycle),
// person (person, pedestrian, rider), traffic light, traffic sign: `paper_class_map()`.
//
// Bad input: a file that is not JSON, or whose top level is not the expected shape, is an Error
// naming the file (and the JSON parser's byte offset). A bad annotation (unknown image or
// category, a box with non-finite, negative or empty size) is reported in `notes` and skipped.
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "lensopt/detection/coco_eval.h"

namespace lensopt {

struct DetectionImage {
  int id = 0;
  std::string file_name;  // relative to the dataset's image folder
  int width = 0;          // 0: unknown (BDD100K label files do not say)
  int height = 0;
};

struct DetectionCategory {
  int id = 0;
  std::string name;
};

struct DetectionDataset {
  std::vector<DetectionImage> images;
  std::vector<DetectionCategory> categories;
  std::vector<GroundTruth> annotations;  // GroundTruth::image is an image id
  std::vector<std::string> notes;        // skipped annotations and why (for the log)

  // The annotations of one image id.
  std::vector<GroundTruth> annotations_of(int image_id) const;
  const DetectionImage* find_image(int id) const;
  const DetectionImage* find_image(const std::string& file_name) const;
};

// Source category name -> (class id, class name).
struct ClassMap {
  std::vector<DetectionCategory> classes;    // the output categories, ids 1..K
  std::map<std::string, int> class_of_name;  // lower-case source name -> class id
};

ClassMap paper_class_map();
// A class map from a TOML file: `[classes]` with `NAME = ["source", ...]` in order (ids 1..K).
ClassMap read_class_map(const std::filesystem::path& path);

DetectionDataset read_coco(const std::filesystem::path& path);
DetectionDataset read_bdd100k(const std::filesystem::path& path, const ClassMap& map);
// By content: a JSON object with "images" is COCO, a JSON list is BDD100K.
DetectionDataset read_detection_dataset(const std::filesystem::path& path, const ClassMap& map);

// COCO JSON text (atomic write by the caller's output layer: write_file_atomic).
std::string coco_json(const DetectionDataset& dataset);
void write_coco(const DetectionDataset& dataset, const std::filesystem::path& path);

}  // namespace lensopt
