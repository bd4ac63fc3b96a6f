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
// Classes. A detector trains on contiguous class indices 1..K; a dataset's category ids need not
// be contiguous (COCO's official ids run 1..90 with gaps: person 1, bicycle 2, car 3, dog 18).
// category_map() numbers a dataset's categories 1..K in order of id, keeps their names, and maps
// class indices back to the dataset's ids, in which evaluations are reported. A user's class map
// (`[classes]` in a TOML file, read_class_map; `--classes FILE` of `optimize --joint` and
// `render`) gathers categories by name, for BDD100K and COCO alike: the dataset's categories are
// then the map's classes (ids 1..K, in the file's order) and a category the map does not list is
// skipped and counted in `notes`.
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

// COCO; with `classes`, the categories are mapped by name into the map's classes (see above).
DetectionDataset read_coco(const std::filesystem::path& path, const ClassMap* classes = nullptr);
DetectionDataset read_bdd100k(const std::filesystem::path& path, const ClassMap& map);
// By content: a JSON object with "images" is COCO, a JSON list is BDD100K. `classes` (a user's
// map) applies to both; nullptr: BDD100K takes paper_class_map() and COCO keeps its categories
// and ids as written.
DetectionDataset read_detection_dataset(const std::filesystem::path& path,
                                        const ClassMap* classes = nullptr);

// A dataset's categories as a detector's classes 1..K (see above).
struct CategoryMap {
  std::vector<DetectionCategory> classes;  // index k at k - 1, named as the category
  std::map<int, int> class_of_category;    // the dataset's category id -> class index
  std::vector<int> category_of_class;      // class index k (at k - 1) -> the dataset's id

  int class_count() const { return static_cast<int>(classes.size()); }
  // The class index of a category id; 0 if the dataset has no such category.
  int class_of(int category_id) const;
  // The dataset's id of class index k; throws Error for an index outside 1..K.
  int category_of(int class_index) const;
};

// The categories listed, plus any id the annotations use that is not listed (a COCO file without
// "categories"; named "category N"), numbered 1..K in order of id.
CategoryMap category_map(const DetectionDataset& dataset);

// Ground truths (or detections) from category ids to class indices, and back; evaluation results
// (CocoStats::categories) from class indices to the dataset's ids.
void to_class_indices(std::vector<GroundTruth>& boxes, const CategoryMap& map);
void to_category_ids(std::vector<Detection>& detections, const CategoryMap& map);
void to_category_ids(CocoStats& stats, const CategoryMap& map);

// COCO JSON text (atomic write by the caller's output layer: write_file_atomic).
std::string coco_json(const DetectionDataset& dataset);
void write_coco(const DetectionDataset& dataset, const std::filesystem::path& path);

}  // namespace lensopt
