// Detection: COCO average precision against hand-computed worked examples, boxes through crops and
// the lens's distortion (checked against rendered images), COCO and BDD100K annotation files.
#include <doctest/doctest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <random>
#include <set>

#include "lensopt/core/error.h"
#include "lensopt/detection/boxes.h"
#include "lensopt/detection/coco_eval.h"
#include "lensopt/detection/dataset.h"
#include "lensopt/detection/scenes.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "test_support.h"

namespace test_detection {

using namespace lensopt;

namespace {

GroundTruth gt(int image, int category, Box b, bool crowd = false) {
  GroundTruth g;
  g.image = image;
  g.category = category;
  g.box = b;
  g.crowd = crowd;
  return g;
}

Detection det(int image, int category, Box b, double score) {
  return {image, category, b, score};
}

std::filesystem::path temp_file(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lensopt-test-detection-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return dir / name;
}

}  // namespace

TEST_CASE("coco ap: perfect predictions give 1") {
  std::vector<GroundTruth> g;
  std::vector<Detection> d;
  for (int i = 0; i < 3; ++i)
    for (int c = 1; c <= 2; ++c) {
      const Box b{10.0 * i, 5.0 * c, 10.0 * i + 40 + c, 5.0 * c + 50};
      g.push_back(gt(i, c, b));
      d.push_back(det(i, c, b, 0.5 + 0.1 * c));
    }
  const CocoStats s = evaluate_coco(g, d);
  CHECK(s.ap == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(s.ap50 == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(s.ap75 == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(s.ar100 == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(s.ap_per_category.size() == 2);
  // Boxes of 40-42 x 45 px (area 1800-1890): medium only.
  CHECK(s.ap_small == -1);
  CHECK(s.ap_large == -1);
  CHECK(s.ap_medium == doctest::Approx(1.0));
}

TEST_CASE("coco ap: a box at IoU 0.62 counts at 3 of the 10 thresholds") {
  // Ground truth 10 x 10; the detection covers 6.2 of its 10 rows: IoU 62/100.
  const CocoStats s = evaluate_coco({gt(1, 1, {0, 0, 10, 10})}, {det(1, 1, {0, 0, 10, 6.2}, 0.9)});
  // Matched at 0.50, 0.55, 0.60: AP 1 there, 0 above.
  CHECK(s.ap == doctest::Approx(0.3).epsilon(1e-12));
  CHECK(s.ap50 == doctest::Approx(1.0));
  CHECK(s.ap75 == doctest::Approx(0.0));
  CHECK(s.ap_small == doctest::Approx(0.3).epsilon(1e-12));  // area 100 px^2 is small
}

TEST_CASE("coco ap: a false positive between two hits, and a miss") {
  // Two ground truths; detections by score: hit, false positive, hit.
  // Precision/recall: (1, 0.5), (0.5, 0.5), (2/3, 1); made non-increasing: 1, 2/3, 2/3.
  // Recall points 0..0.50 (51 of them) take precision 1, 0.51..1 (50) take 2/3.
  const std::vector<GroundTruth> g = {gt(7, 3, {0, 0, 20, 20}), gt(7, 3, {50, 50, 80, 90})};
  std::vector<Detection> d = {det(7, 3, {0, 0, 20, 20}, 0.9), det(7, 3, {200, 200, 230, 230}, 0.8),
                              det(7, 3, {50, 50, 80, 90}, 0.7)};
  CocoStats s = evaluate_coco(g, d);
  CHECK(s.ap == doctest::Approx((51.0 + 50.0 * 2.0 / 3.0) / 101.0).epsilon(1e-12));
  CHECK(s.ar100 == doctest::Approx(1.0));
  CHECK(s.ar1 == doctest::Approx(0.5));  // one detection per image: the first hit only
  // Without the last detection the second object is missed: recall stops at 0.5.
  d.pop_back();
  s = evaluate_coco(g, d);
  CHECK(s.ap == doctest::Approx(51.0 / 101.0).epsilon(1e-12));
  CHECK(s.ar100 == doctest::Approx(0.5));
}

TEST_CASE("coco ap: crowd regions and other categories") {
  // A detection inside a crowd region is ignored (neither hit nor false positive); one crowd
  // region absorbs any number of detections.
  const std::vector<GroundTruth> g = {gt(1, 1, {0, 0, 10, 10}), gt(1, 1, {100, 0, 200, 100}, true)};
  const std::vector<Detection> d = {det(1, 1, {0, 0, 10, 10}, 0.5),
                                    det(1, 1, {110, 10, 130, 30}, 0.9),
                                    det(1, 1, {150, 50, 170, 70}, 0.8)};
  CHECK(evaluate_coco(g, d).ap == doctest::Approx(1.0));
  // A detection of the right box but another category is a false positive of that category
  // (which has no ground truth, so no AP) and leaves the first category's object missed.
  const CocoStats s = evaluate_coco({gt(1, 1, {0, 0, 10, 10})}, {det(1, 2, {0, 0, 10, 10}, 0.9)});
  CHECK(s.ap == doctest::Approx(0.0));
  REQUIRE(s.ap_per_category.size() == 2);
  CHECK(s.ap_per_category[1] == -1);
}

TEST_CASE("coco ap: the detection limit per image") {
  // 3 objects, 3 exact detections whose scores rank the third first: with max 1 detection per
  // image only it is kept, recall 1/3, precision 1 up to there.
  std::vector<GroundTruth> g;
  std::vector<Detection> d;
  for (int k = 0; k < 3; ++k) {
    const Box b{40.0 * k, 0, 40.0 * k + 30, 30};
    g.push_back(gt(1, 1, b));
    d.push_back(det(1, 1, b, 0.1 * (k + 1)));
  }
  CocoEvalOptions o;
  o.max_detections = 1;
  const CocoStats s = evaluate_coco(g, d, o);
  // Recall points 0 .. 0.33 (34 of them) have precision 1.
  CHECK(s.ap == doctest::Approx(34.0 / 101.0).epsilon(1e-12));
}

TEST_CASE("boxes: a crop moves and clips exactly, and drops slivers") {
  const Box b{10, 20, 50, 60};  // 40 x 40
  const auto inside = crop_box(b, 5, 10, 100, 100);
  REQUIRE(inside);
  CHECK(inside->x0 == 5);
  CHECK(inside->y0 == 10);
  CHECK(inside->x1 == 45);
  CHECK(inside->y1 == 50);
  // Crop from (30, 30): the box keeps [30, 50] x [30, 60] = 20 x 30 = 600 of 1600 px^2 (37.5 %).
  const auto clipped = crop_box(b, 30, 30, 100, 100);
  REQUIRE(clipped);
  CHECK(clipped->x0 == 0);
  CHECK(clipped->y0 == 0);
  CHECK(clipped->x1 == 20);
  CHECK(clipped->y1 == 30);
  // Crop from (45, 0): 5 x 40 = 200 of 1600 (12.5 % < 25 %): dropped.
  CHECK_FALSE(crop_box(b, 45, 0, 100, 100));
  // A 1.5 px sliver on the right edge of a crop of width 11.5: dropped by the side rule.
  CropRule loose;
  loose.min_visible_fraction = 0;
  CHECK_FALSE(crop_box(b, 0, 0, 11.5, 100, loose));
  CHECK(crop_box(b, 0, 0, 12.5, 100, loose));
  CHECK(scale_box(b, 2).x1 == 100);
}

TEST_CASE("boxes: distorted ground truth contains the rendered squares' centroids") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  TraceOptions trace;
  trace.rings = 8;
  const ImagingModel model = build_imaging_model(lens, trace);
  for (int res : {1, 2}) {
    const int width = 320, height = 180;
    RenderOptions ro;
    ro.res_factor = res;
    ro.relative_illumination = false;
    const Renderer renderer(model, ro);
    // Small bright squares (5 x 5 px) on black, spread over the image.
    FloatImage scene(width, height, 3, 0.0f);
    std::vector<Box> squares;
    for (int gy = 0; gy < 3; ++gy)
      for (int gx = 0; gx < 5; ++gx) {
        const int x0 = 20 + gx * 65, y0 = 15 + gy * 65;
        squares.push_back({double(x0), double(y0), x0 + 5.0, y0 + 5.0});
        for (int y = y0; y < y0 + 5; ++y)
          for (int x = x0; x < x0 + 5; ++x)
            for (int c = 0; c < 3; ++c) scene.at(x, y, c) = 1.0f;
      }
    const FloatImage rendered = renderer.render(scene).image;
    const BoxDistortion distortion(model, width, height, res);
    for (const Box& sq : squares) {
      const Box moved = distortion.distort_box(sq);
      // The rendered square's centroid, over a window around the moved box.
      const int wx0 = std::max(0, int(moved.x0) - 8), wx1 = std::min(width, int(moved.x1) + 9);
      const int wy0 = std::max(0, int(moved.y0) - 8), wy1 = std::min(height, int(moved.y1) + 9);
      double sum = 0, sx = 0, sy = 0;
      for (int y = wy0; y < wy1; ++y)
        for (int x = wx0; x < wx1; ++x) {
          const double v = rendered.at(x, y, 1);
          sum += v;
          sx += v * (x + 0.5);
          sy += v * (y + 0.5);
        }
      REQUIRE(sum > 0);
      const double cx = sx / sum, cy = sy / sum;
      INFO("res " << res << " square at " << sq.x0 << "," << sq.y0 << " -> box " << moved.x0 << ","
                  << moved.y0 << "," << moved.x1 << "," << moved.y1 << " centroid " << cx << ","
                  << cy);
      CHECK(cx >= moved.x0 - 1.0);
      CHECK(cx <= moved.x1 + 1.0);
      CHECK(cy >= moved.y0 - 1.0);
      CHECK(cy <= moved.y1 + 1.0);
      // The distortion moves the square's centre where the rendered centroid is (1 px).
      double mx, my;
      distortion.distort(0.5 * (sq.x0 + sq.x1), 0.5 * (sq.y0 + sq.y1), mx, my);
      CHECK(std::abs(mx - cx) < 1.0);
      CHECK(std::abs(my - cy) < 1.0);
    }
  }
}

TEST_CASE("boxes: the predicted-box correction inverts the ground-truth distortion") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  TraceOptions trace;
  trace.rings = 8;
  const ImagingModel model = build_imaging_model(lens, trace);
  const BoxDistortion distortion(model, 1280, 720, 1);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double worst = 0;
  for (int k = 0; k < 500; ++k) {
    const double w = 8 + 200 * u(rng), h = 8 + 150 * u(rng);
    const double x0 = u(rng) * (1280 - w), y0 = u(rng) * (720 - h);
    const Box b{x0, y0, x0 + w, y0 + h};
    const Box back = distortion.undistort_box(distortion.distort_box(b));
    worst = std::max({worst, std::abs(back.x0 - b.x0), std::abs(back.y0 - b.y0),
                      std::abs(back.x1 - b.x1), std::abs(back.y1 - b.y1)});
    double px, py, qx, qy;
    distortion.distort(x0, y0, px, py);
    distortion.undistort(px, py, qx, qy);
    CHECK(std::abs(qx - x0) < 1e-9);
    CHECK(std::abs(qy - y0) < 1e-9);
  }
  MESSAGE("largest corner error of undistort(distort(box)) over 500 boxes: " << worst << " px");
  CHECK(worst < 0.5);
}

TEST_CASE("dataset: COCO round trip, bad annotations reported and skipped") {
  const auto path = temp_file("coco.json");
  {
    std::ofstream f(path);
    f << R"({"images": [{"id": 1, "file_name": "a.png", "width": 64, "height": 48},
                        {"id": 2, "file_name": "b.png", "width": 64, "height": 48}],
             "categories": [{"id": 1, "name": "car"}, {"id": 5, "name": "person"}],
             "annotations": [
               {"id": 10, "image_id": 1, "category_id": 1, "bbox": [1, 2, 10, 20], "area": 150, "iscrowd": 0},
               {"id": 11, "image_id": 2, "category_id": 5, "bbox": [3, 4, 5, 6]},
               {"id": 12, "image_id": 9, "category_id": 1, "bbox": [1, 1, 2, 2]},
               {"id": 13, "image_id": 1, "category_id": 7, "bbox": [1, 1, 2, 2]},
               {"id": 14, "image_id": 1, "category_id": 1, "bbox": [1, 1, -2, 2]},
               {"id": 15, "image_id": 1, "category_id": 1}]})";
  }
  const DetectionDataset d = read_coco(path);
  CHECK(d.images.size() == 2);
  REQUIRE(d.annotations.size() == 2);
  CHECK(d.notes.size() == 4);
  CHECK(d.annotations[0].box.x1 == 11);
  CHECK(d.annotations[0].box.y1 == 22);
  CHECK(d.annotations[0].area == 150);
  CHECK(d.annotations[1].area == -1);
  const auto out = temp_file("coco-out.json");
  write_coco(d, out);
  const DetectionDataset again = read_coco(out);
  REQUIRE(again.annotations.size() == 2);
  CHECK(again.annotations[1].box.x0 == 3);
  CHECK(again.annotations[1].box.y1 == 10);
  CHECK(again.annotations[1].area == 30);  // written from the box
  CHECK(again.notes.empty());
  // Not JSON: an error naming the file.
  std::ofstream(temp_file("bad.json")) << "{\"images\": [";
  CHECK_THROWS_WITH_AS(read_coco(temp_file("bad.json")), doctest::Contains("bad.json"), Error);
}

// Issue 29: official COCO ids (person 1, car 3, dog 18) are not class indices. The loader keeps
// them; category_map numbers them 1..K in order of id; evaluation reports the file's ids.
TEST_CASE("dataset: COCO ids 1, 3, 18 become classes 1, 2, 3 and evaluate back to their ids") {
  const auto path = temp_file("coco-ids.json");
  {
    std::ofstream f(path);
    f << R"({"images": [{"id": 7, "file_name": "a.png", "width": 64, "height": 48}],
             "categories": [{"id": 18, "name": "dog"}, {"id": 1, "name": "person"},
                            {"id": 3, "name": "car"}],
             "annotations": [
               {"id": 1, "image_id": 7, "category_id": 18, "bbox": [1, 2, 10, 20]},
               {"id": 2, "image_id": 7, "category_id": 1, "bbox": [30, 4, 8, 16]},
               {"id": 3, "image_id": 7, "category_id": 3, "bbox": [40, 30, 20, 12]}]})";
  }
  const DetectionDataset d = read_coco(path);
  REQUIRE(d.annotations.size() == 3);
  CHECK(d.annotations[0].category == 18);  // the file's ids, as written
  const CategoryMap map = category_map(d);
  REQUIRE(map.class_count() == 3);
  CHECK(map.classes[0].name == "person");
  CHECK(map.classes[1].name == "car");
  CHECK(map.classes[2].name == "dog");
  CHECK(map.class_of(1) == 1);
  CHECK(map.class_of(3) == 2);
  CHECK(map.class_of(18) == 3);
  CHECK(map.class_of(2) == 0);
  CHECK(map.category_of(3) == 18);
  CHECK_THROWS_AS(map.category_of(4), Error);
  std::vector<GroundTruth> truths = d.annotations;
  to_class_indices(truths, map);
  CHECK(truths[0].category == 3);  // dog
  CHECK(truths[1].category == 1);  // person
  CHECK(truths[2].category == 2);  // car

  // A detector in class indices: the person and the dog found exactly, and the car called a dog
  // with a higher score than the dog.
  std::vector<Detection> found = {det(7, 1, truths[1].box, 0.9), det(7, 3, truths[0].box, 0.8),
                                  det(7, 3, truths[2].box, 0.95)};
  CocoStats stats = evaluate_coco(truths, found);
  REQUIRE(stats.categories == std::vector<int>{1, 2, 3});
  to_category_ids(stats, map);
  CHECK(stats.categories == std::vector<int>{1, 3, 18});
  REQUIRE(stats.ap_per_category.size() == 3);
  CHECK(stats.ap_per_category[0] == doctest::Approx(1.0));  // person (id 1)
  CHECK(stats.ap_per_category[1] == doctest::Approx(0.0));  // car (id 3): never found
  CHECK(stats.ap_per_category[2] == doctest::Approx(0.5));  // dog (id 18): a false positive first
  // The same evaluation in the file's ids gives the same figures (ids are only labels).
  to_category_ids(found, map);
  CHECK(found[1].category == 18);
  const CocoStats direct = evaluate_coco(d.annotations, found);
  CHECK(direct.categories == stats.categories);
  CHECK(direct.ap == doctest::Approx(stats.ap));
  CHECK(direct.ap_per_category == stats.ap_per_category);

  // A user's [classes] map gathers COCO categories by name; one it does not list is skipped.
  const auto classes = temp_file("classes.toml");
  std::ofstream(classes) << "[classes]\n\"animal\" = [\"dog\", \"cat\"]\n"
                            "\"human\" = [\"Person\"]\n";
  const ClassMap user = read_class_map(classes);
  const DetectionDataset mapped = read_detection_dataset(path, &user);
  REQUIRE(mapped.categories.size() == 2);
  CHECK(mapped.categories[0].name == "animal");
  REQUIRE(mapped.annotations.size() == 2);
  CHECK(mapped.annotations[0].category == 1);  // dog -> animal
  CHECK(mapped.annotations[1].category == 2);  // person -> human
  REQUIRE(mapped.notes.size() == 1);
  CHECK(mapped.notes[0].find("'car' (id 3)") != std::string::npos);
  // Without "categories": the ids the annotations use, named by number.
  const auto bare = temp_file("coco-bare.json");
  std::ofstream(bare) << R"({"images": [{"id": 1, "file_name": "a.png"}], "annotations": [
      {"image_id": 1, "category_id": 90, "bbox": [1, 1, 4, 4]},
      {"image_id": 1, "category_id": 5, "bbox": [1, 1, 4, 4]}]})";
  const CategoryMap bare_map = category_map(read_coco(bare));
  REQUIRE(bare_map.class_count() == 2);
  CHECK(bare_map.category_of(1) == 5);
  CHECK(bare_map.category_of(2) == 90);
  CHECK(bare_map.classes[1].name == "category 90");
}

TEST_CASE("dataset: BDD100K labels through the paper's six classes") {
  const auto path = temp_file("bdd.json");
  {
    std::ofstream f(path);
    f << R"([{"name": "x.jpg", "labels": [
               {"category": "car", "box2d": {"x1": 10, "y1": 20, "x2": 29, "y2": 39}},
               {"category": "truck", "box2d": {"x1": 0, "y1": 0, "x2": 9, "y2": 9}},
               {"category": "rider", "box2d": {"x1": 0, "y1": 0, "x2": 9, "y2": 9}},
               {"category": "drivable area", "poly2d": []},
               {"category": "train", "box2d": {"x1": 5, "y1": 5, "x2": 1, "y2": 9}},
               {"category": "unicorn", "box2d": {"x1": 0, "y1": 0, "x2": 9, "y2": 9}}]},
             {"name": "y.jpg"}])";
  }
  const DetectionDataset d = read_detection_dataset(path);  // BDD100K: the paper's six classes
  CHECK(d.images.size() == 2);
  CHECK(d.categories.size() == 6);
  REQUIRE(d.annotations.size() == 3);
  CHECK(d.annotations[0].category == 1);
  CHECK(d.annotations[0].box.x1 == 30);  // inclusive x2 = 29: 20 px wide
  CHECK(d.annotations[1].category == 2);
  CHECK(d.annotations[2].category == 4);
  CHECK(d.notes.size() == 2);  // the empty train box and the unmapped unicorn
}

TEST_CASE("scenes: deterministic, boxes inside the image and on painted objects") {
  const DetectionScene a = make_detection_scene(320, 180, 5);
  const DetectionScene b = make_detection_scene(320, 180, 5);
  CHECK(a.image.pixels == b.image.pixels);
  REQUIRE(a.boxes.size() == b.boxes.size());
  REQUIRE(!a.boxes.empty());
  std::set<int> classes;
  int scenes_with_objects = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    const DetectionScene s = make_detection_scene(320, 180, seed);
    scenes_with_objects += !s.boxes.empty();
    for (const GroundTruth& g : s.boxes) {
      classes.insert(g.category);
      CHECK(g.box.x0 >= 0);
      CHECK(g.box.y0 >= 0);
      CHECK(g.box.x1 <= 320);
      CHECK(g.box.y1 <= 180);
      CHECK(g.box.width() >= 4);
      CHECK(g.box.height() >= 4);
    }
  }
  CHECK(scenes_with_objects == 20);
  CHECK(classes.size() == 6);  // every class of the paper appears
}

TEST_CASE("dataset: the shipped class map file is the built-in one; bad maps are refused") {
  const ClassMap file =
      read_class_map(test::source_dir() / "examples" / "bdd100k-six-classes.toml");
  const ClassMap built_in = paper_class_map();
  REQUIRE(file.classes.size() == built_in.classes.size());
  for (std::size_t k = 0; k < file.classes.size(); ++k) {
    CHECK(file.classes[k].id == built_in.classes[k].id);
    CHECK(file.classes[k].name == built_in.classes[k].name);
  }
  CHECK(file.class_of_name == built_in.class_of_name);
  std::ofstream(temp_file("twice.toml")) << "[classes]\na = [\"car\"]\nb = [\"Car\"]\n";
  CHECK_THROWS_WITH_AS(read_class_map(temp_file("twice.toml")), doctest::Contains("twice"), Error);
}

}  // namespace test_detection
