// COCO and BDD100K detection annotations (formats in detection/dataset.h).
#include "lensopt/detection/dataset.h"

#include <fmt/format.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <nlohmann/json.hpp>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"

namespace lensopt {
namespace {

using nlohmann::json;

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

json parse_json(const std::filesystem::path& path) {
  const std::string text = read_file(path);
  try {
    return json::parse(text);
  } catch (const json::parse_error& e) {
    throw Error(SourceLocation{path.string(), 0, 0},
                fmt::format("not valid JSON (byte {}): {}", e.byte, e.what()));
  }
}

// A number of a JSON object, or NaN if absent or not a number.
double number(const json& j, const char* key) {
  const auto it = j.find(key);
  return it != j.end() && it->is_number() ? it->get<double>() : NAN;
}

bool valid_box(const Box& b) {
  return std::isfinite(b.x0) && std::isfinite(b.y0) && std::isfinite(b.x1) && std::isfinite(b.y1) &&
         b.x1 > b.x0 && b.y1 > b.y0;
}

}  // namespace

std::vector<GroundTruth> DetectionDataset::annotations_of(int image_id) const {
  std::vector<GroundTruth> out;
  for (const GroundTruth& g : annotations)
    if (g.image == image_id) out.push_back(g);
  return out;
}

const DetectionImage* DetectionDataset::find_image(int id) const {
  for (const DetectionImage& i : images)
    if (i.id == id) return &i;
  return nullptr;
}

const DetectionImage* DetectionDataset::find_image(const std::string& file_name) const {
  for (const DetectionImage& i : images)
    if (i.file_name == file_name) return &i;
  return nullptr;
}

ClassMap paper_class_map() {
  ClassMap m;
  const std::vector<std::pair<std::string, std::vector<std::string>>> classes = {
      {"car", {"car", "van", "suv"}},
      {"bus/truck/tram", {"bus", "truck", "train", "tram"}},
      {"bike", {"bike", "bicycle", "motor", "motorcycle"}},
      {"person", {"person", "pedestrian", "rider"}},
      {"traffic light", {"traffic light"}},
      {"traffic sign", {"traffic sign"}}};
  for (std::size_t k = 0; k < classes.size(); ++k) {
    const int id = static_cast<int>(k) + 1;
    m.classes.push_back({id, classes[k].first});
    for (const std::string& s : classes[k].second) m.class_of_name[s] = id;
  }
  return m;
}

ClassMap read_class_map(const std::filesystem::path& path) {
  toml::table t;
  try {
    t = toml::parse_file(path.string());
  } catch (const toml::parse_error& e) {
    const auto& b = e.source().begin;
    throw Error(SourceLocation{path.string(), static_cast<int>(b.line), static_cast<int>(b.column)},
                std::string(e.description()));
  }
  const toml::table* classes = t["classes"].as_table();
  if (!classes || classes->empty())
    throw Error(SourceLocation{path.string(), 0, 0},
                "needs a [classes] table with one entry per class");
  // toml++ keeps a table's keys sorted; the classes take their ids in the file's order.
  std::vector<std::pair<std::string, const toml::node*>> entries;
  for (const auto& [name, value] : *classes) entries.push_back({std::string(name.str()), &value});
  std::stable_sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) {
    const auto& pa = a.second->source().begin;
    const auto& pb = b.second->source().begin;
    return pa.line != pb.line ? pa.line < pb.line : pa.column < pb.column;
  });
  ClassMap m;
  int id = 0;
  for (const auto& [name, node] : entries) {
    const toml::node& value = *node;
    ++id;
    m.classes.push_back({id, name});
    const toml::array* sources = value.as_array();
    const auto& where = value.source().begin;
    if (!sources || sources->empty())
      throw Error(SourceLocation{path.string(), static_cast<int>(where.line),
                                 static_cast<int>(where.column)},
                  fmt::format("class '{}' needs a list of source category names", name));
    for (const auto& s : *sources) {
      const auto text = s.value<std::string>();
      if (!text)
        throw Error(SourceLocation{path.string(), static_cast<int>(where.line),
                                   static_cast<int>(where.column)},
                    fmt::format("class '{}': source names must be strings", name));
      const std::string key = lower(*text);
      if (m.class_of_name.count(key))
        throw Error(SourceLocation{path.string(), static_cast<int>(where.line),
                                   static_cast<int>(where.column)},
                    fmt::format("source category '{}' is mapped twice", *text));
      m.class_of_name[key] = id;
    }
  }
  return m;
}

DetectionDataset read_coco(const std::filesystem::path& path, const ClassMap* classes) {
  const json j = parse_json(path);
  const SourceLocation where{path.string(), 0, 0};
  if (!j.is_object() || !j.contains("images") || !j["images"].is_array())
    throw Error(where, "not a COCO annotation file: no \"images\" list");
  DetectionDataset d;
  for (const json& im : j["images"]) {
    if (!im.is_object() || !im.contains("id") || !im["id"].is_number_integer() ||
        !im.contains("file_name") || !im["file_name"].is_string()) {
      d.notes.push_back("an image entry without an integer id or a file_name: skipped");
      continue;
    }
    DetectionImage image;
    image.id = im["id"].get<int>();
    image.file_name = im["file_name"].get<std::string>();
    image.width = im.value("width", 0);
    image.height = im.value("height", 0);
    if (d.find_image(image.id)) {
      d.notes.push_back(fmt::format("image id {} listed twice: the second skipped", image.id));
      continue;
    }
    d.images.push_back(image);
  }
  if (j.contains("categories") && j["categories"].is_array())
    for (const json& c : j["categories"])
      if (c.is_object() && c.contains("id") && c["id"].is_number_integer())
        d.categories.push_back({c["id"].get<int>(), c.value("name", std::string())});
  // A user's class map: the file's category ids -> the map's classes, by name.
  std::map<int, int> class_of_id;
  std::map<std::string, int> unmapped;
  if (classes) {
    for (const DetectionCategory& c : d.categories) {
      const auto it = classes->class_of_name.find(lower(c.name));
      if (it != classes->class_of_name.end()) class_of_id[c.id] = it->second;
    }
  }
  auto has_category = [&](int id) {
    return std::any_of(d.categories.begin(), d.categories.end(),
                       [&](const DetectionCategory& c) { return c.id == id; });
  };
  if (j.contains("annotations") && j["annotations"].is_array()) {
    int index = 0;
    for (const json& a : j["annotations"]) {
      ++index;
      const std::string label = a.is_object() && a.contains("id")
                                    ? fmt::format("annotation id {}", a["id"].dump())
                                    : fmt::format("annotation #{}", index);
      if (!a.is_object() || !a.contains("image_id") || !a["image_id"].is_number_integer() ||
          !a.contains("category_id") || !a["category_id"].is_number_integer() ||
          !a.contains("bbox") || !a["bbox"].is_array() || a["bbox"].size() != 4) {
        d.notes.push_back(label + ": needs image_id, category_id and bbox [x, y, w, h]: skipped");
        continue;
      }
      GroundTruth g;
      g.image = a["image_id"].get<int>();
      g.category = a["category_id"].get<int>();
      const json& b = a["bbox"];
      if (!b[0].is_number() || !b[1].is_number() || !b[2].is_number() || !b[3].is_number()) {
        d.notes.push_back(label + ": bbox entries must be numbers: skipped");
        continue;
      }
      const double x = b[0].get<double>(), y = b[1].get<double>(), w = b[2].get<double>(),
                   h = b[3].get<double>();
      g.box = {x, y, x + w, y + h};
      g.area = number(a, "area");
      if (!std::isfinite(g.area) || g.area < 0) g.area = -1;
      g.crowd = a.value("iscrowd", 0) != 0;
      if (!d.find_image(g.image)) {
        d.notes.push_back(fmt::format("{}: image id {} is not listed: skipped", label, g.image));
        continue;
      }
      if (!d.categories.empty() && !has_category(g.category)) {
        d.notes.push_back(
            fmt::format("{}: category id {} is not listed: skipped", label, g.category));
        continue;
      }
      if (!valid_box(g.box)) {
        d.notes.push_back(fmt::format("{}: empty or non-finite box [{}, {}, {}, {}]: skipped",
                                      label, x, y, w, h));
        continue;
      }
      if (classes) {
        const auto it = class_of_id.find(g.category);
        if (it == class_of_id.end()) {
          std::string name = fmt::format("id {}", g.category);
          for (const DetectionCategory& c : d.categories)
            if (c.id == g.category) name = fmt::format("'{}' (id {})", c.name, c.id);
          ++unmapped[name];
          continue;
        }
        g.category = it->second;
      }
      d.annotations.push_back(g);
    }
  }
  if (classes) {
    d.categories = classes->classes;
    for (const auto& [name, count] : unmapped)
      d.notes.push_back(
          fmt::format("{} annotation(s) of category {} are in no class: skipped", count, name));
  }
  return d;
}

DetectionDataset read_bdd100k(const std::filesystem::path& path, const ClassMap& map) {
  const json j = parse_json(path);
  const json* frames = &j;
  if (j.is_object() && j.contains("frames") && j["frames"].is_array()) frames = &j["frames"];
  if (!frames->is_array())
    throw Error(SourceLocation{path.string(), 0, 0},
                "not a BDD100K label file: expected a list of frames {name, labels}");
  DetectionDataset d;
  d.categories = map.classes;
  std::map<std::string, int> unmapped;
  int next_id = 1;
  for (const json& f : *frames) {
    if (!f.is_object() || !f.contains("name") || !f["name"].is_string()) {
      d.notes.push_back("a frame without a name: skipped");
      continue;
    }
    DetectionImage image;
    image.id = next_id++;
    image.file_name = f["name"].get<std::string>();
    d.images.push_back(image);
    if (!f.contains("labels") || !f["labels"].is_array()) continue;  // an image with no object
    for (const json& l : f["labels"]) {
      if (!l.is_object() || !l.contains("box2d") || !l["box2d"].is_object()) continue;
      const std::string category = l.value("category", std::string());
      const auto it = map.class_of_name.find(lower(category));
      if (it == map.class_of_name.end()) {
        ++unmapped[category];
        continue;
      }
      const json& b = l["box2d"];
      GroundTruth g;
      g.image = image.id;
      g.category = it->second;
      // Inclusive pixel indices of the last pixel: the box ends one pixel further.
      g.box = {number(b, "x1"), number(b, "y1"), number(b, "x2") + 1.0, number(b, "y2") + 1.0};
      if (l.contains("attributes") && l["attributes"].is_object())
        g.crowd = l["attributes"].value("crowd", false);
      if (!valid_box(g.box)) {
        d.notes.push_back(fmt::format("{}: a '{}' box that is empty or not finite: skipped",
                                      image.file_name, category));
        continue;
      }
      d.annotations.push_back(g);
    }
  }
  for (const auto& [name, count] : unmapped)
    d.notes.push_back(fmt::format("{} label(s) of category '{}' are in no class: skipped", count,
                                  name.empty() ? "(none)" : name));
  return d;
}

DetectionDataset read_detection_dataset(const std::filesystem::path& path,
                                        const ClassMap* classes) {
  const json j = parse_json(path);
  if (j.is_object() && j.contains("images")) return read_coco(path, classes);
  if (j.is_array() || (j.is_object() && j.contains("frames")))
    return read_bdd100k(path, classes ? *classes : paper_class_map());
  throw Error(SourceLocation{path.string(), 0, 0},
              "neither COCO (an object with \"images\") nor BDD100K (a list of frames)");
}

int CategoryMap::class_of(int category_id) const {
  const auto it = class_of_category.find(category_id);
  return it == class_of_category.end() ? 0 : it->second;
}

int CategoryMap::category_of(int class_index) const {
  if (class_index < 1 || class_index > class_count())
    throw Error(fmt::format("class index {} is outside the dataset's classes 1..{}", class_index,
                            class_count()));
  return category_of_class[static_cast<std::size_t>(class_index - 1)];
}

CategoryMap category_map(const DetectionDataset& dataset) {
  std::map<int, std::string> by_id;
  for (const DetectionCategory& c : dataset.categories) by_id.emplace(c.id, c.name);
  for (const GroundTruth& g : dataset.annotations)
    by_id.emplace(g.category, fmt::format("category {}", g.category));
  CategoryMap m;
  for (const auto& [id, name] : by_id) {
    const int k = m.class_count() + 1;
    m.classes.push_back({k, name});
    m.class_of_category[id] = k;
    m.category_of_class.push_back(id);
  }
  return m;
}

void to_class_indices(std::vector<GroundTruth>& boxes, const CategoryMap& map) {
  for (GroundTruth& g : boxes) {
    const int k = map.class_of(g.category);
    if (k == 0)
      throw Error(fmt::format("category id {} is not one of the dataset's categories", g.category));
    g.category = k;
  }
}

void to_category_ids(std::vector<Detection>& detections, const CategoryMap& map) {
  for (Detection& d : detections) d.category = map.category_of(d.category);
}

void to_category_ids(CocoStats& stats, const CategoryMap& map) {
  for (int& c : stats.categories) c = map.category_of(c);
}

std::string coco_json(const DetectionDataset& dataset) {
  json j;
  j["images"] = json::array();
  for (const DetectionImage& i : dataset.images)
    j["images"].push_back(
        {{"id", i.id}, {"file_name", i.file_name}, {"width", i.width}, {"height", i.height}});
  j["categories"] = json::array();
  for (const DetectionCategory& c : dataset.categories)
    j["categories"].push_back({{"id", c.id}, {"name", c.name}});
  j["annotations"] = json::array();
  int id = 0;
  for (const GroundTruth& g : dataset.annotations) {
    const Box& b = g.box;
    j["annotations"].push_back({{"id", ++id},
                                {"image_id", g.image},
                                {"category_id", g.category},
                                {"bbox", {b.x0, b.y0, b.width(), b.height()}},
                                {"area", g.area >= 0 ? g.area : b.area()},
                                {"iscrowd", g.crowd ? 1 : 0}});
  }
  // Invalid UTF-8 in a name (a Latin-1 file name) is replaced, never a throw.
  return j.dump(1, ' ', false, json::error_handler_t::replace) + "\n";
}

void write_coco(const DetectionDataset& dataset, const std::filesystem::path& path) {
  write_file_atomic(path, coco_json(dataset));
}

}  // namespace lensopt
