// COCO average precision (the definition is in detection/coco_eval.h).
#include "lensopt/detection/coco_eval.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <optional>
#include <set>
#include <utility>

namespace lensopt {
namespace {

constexpr int kRecallPoints = 101;

struct AreaRange {
  double lo, hi;
};
constexpr AreaRange kAreaAll{0.0, 1e10};
constexpr AreaRange kAreaSmall{0.0, 32.0 * 32.0};
constexpr AreaRange kAreaMedium{32.0 * 32.0, 96.0 * 96.0};
constexpr AreaRange kAreaLarge{96.0 * 96.0, 1e10};

double gt_area(const GroundTruth& g) {
  return g.area >= 0 ? g.area : g.box.area();
}

// The matching result of one image and category at one area range and detection limit, for
// every IoU threshold.
struct ImageResult {
  std::vector<double> scores;              // kept detections, score order
  std::vector<std::vector<char>> matched;  // [t][d]
  std::vector<std::vector<char>> ignored;  // [t][d]
  int non_ignored_gt = 0;
};

ImageResult evaluate_image(const std::vector<const GroundTruth*>& gts_in,
                           const std::vector<const Detection*>& dts_in,
                           const std::vector<double>& thresholds, AreaRange range,
                           int max_detections) {
  // Ground truths: non-ignored first (stable), as the matching prefers them.
  std::vector<const GroundTruth*> gts = gts_in;
  auto gt_ignored = [&](const GroundTruth* g) {
    const double a = gt_area(*g);
    return g->crowd || a < range.lo || a > range.hi;
  };
  std::stable_sort(gts.begin(), gts.end(), [&](const GroundTruth* a, const GroundTruth* b) {
    return !gt_ignored(a) && gt_ignored(b);
  });
  std::vector<const Detection*> dts = dts_in;
  std::stable_sort(dts.begin(), dts.end(),
                   [](const Detection* a, const Detection* b) { return a->score > b->score; });
  if (static_cast<int>(dts.size()) > max_detections) dts.resize(max_detections);

  const std::size_t ng = gts.size(), nd = dts.size(), nt = thresholds.size();
  std::vector<char> g_ignored(ng);
  ImageResult r;
  for (std::size_t g = 0; g < ng; ++g) {
    g_ignored[g] = gt_ignored(gts[g]);
    if (!g_ignored[g]) ++r.non_ignored_gt;
  }
  // Overlaps [d][g]: IoU, or intersection over the detection's area for a crowd ground truth.
  std::vector<double> overlap(nd * ng);
  for (std::size_t d = 0; d < nd; ++d)
    for (std::size_t g = 0; g < ng; ++g)
      overlap[d * ng + g] = gts[g]->crowd ? intersection_over_second(gts[g]->box, dts[d]->box)
                                          : iou(dts[d]->box, gts[g]->box);
  r.scores.resize(nd);
  for (std::size_t d = 0; d < nd; ++d) r.scores[d] = dts[d]->score;
  r.matched.assign(nt, std::vector<char>(nd, 0));
  r.ignored.assign(nt, std::vector<char>(nd, 0));
  for (std::size_t t = 0; t < nt; ++t) {
    std::vector<char> g_taken(ng, 0);
    for (std::size_t d = 0; d < nd; ++d) {
      double best = std::min(thresholds[t], 1.0 - 1e-10);
      int m = -1;
      for (std::size_t g = 0; g < ng; ++g) {
        if (g_taken[g] && !gts[g]->crowd) continue;
        if (m > -1 && !g_ignored[m] && g_ignored[g]) break;  // non-ignored ones come first
        if (overlap[d * ng + g] < best) continue;
        best = overlap[d * ng + g];
        m = static_cast<int>(g);
      }
      if (m == -1) {
        const double a = dts[d]->box.area();
        r.ignored[t][d] = a < range.lo || a > range.hi;
        continue;
      }
      r.matched[t][d] = 1;
      r.ignored[t][d] = g_ignored[m];
      g_taken[m] = 1;
    }
  }
  return r;
}

struct Curve {
  double ap = -1;      // mean over thresholds and categories, -1 if none
  double recall = -1;  // likewise
};

// Accumulates precision at the 101 recall points (and final recall) per threshold and category.
Curve accumulate(const std::map<int, std::vector<ImageResult>>& per_category, std::size_t nt) {
  double ap_sum = 0, recall_sum = 0;
  int count = 0;
  for (const auto& [category, images] : per_category) {
    int n_gt = 0;
    for (const ImageResult& r : images) n_gt += r.non_ignored_gt;
    if (n_gt == 0) continue;
    // All detections of the category, by score (stable over the image order).
    std::vector<std::pair<double, std::pair<int, int>>> order;  // score, (image, detection)
    for (std::size_t i = 0; i < images.size(); ++i)
      for (std::size_t d = 0; d < images[i].scores.size(); ++d)
        order.push_back({images[i].scores[d], {static_cast<int>(i), static_cast<int>(d)}});
    std::stable_sort(order.begin(), order.end(),
                     [](const auto& a, const auto& b) { return a.first > b.first; });
    for (std::size_t t = 0; t < nt; ++t) {
      std::vector<double> recall, precision;
      double tp = 0, fp = 0;
      for (const auto& [score, id] : order) {
        const ImageResult& r = images[id.first];
        if (r.ignored[t][id.second]) continue;
        (r.matched[t][id.second] ? tp : fp) += 1;
        recall.push_back(tp / n_gt);
        precision.push_back(tp / (tp + fp));
      }
      for (std::size_t k = precision.size(); k-- > 1;)
        precision[k - 1] = std::max(precision[k - 1], precision[k]);
      double ap = 0;
      for (int q = 0; q < kRecallPoints; ++q) {
        // As numpy's linspace(0, 1, 101): q * 0.01, the last one exactly 1.
        const double r_threshold = q == kRecallPoints - 1 ? 1.0 : q * 0.01;
        const auto it = std::lower_bound(recall.begin(), recall.end(), r_threshold);
        if (it != recall.end()) ap += precision[it - recall.begin()];
      }
      ap_sum += ap / kRecallPoints;
      recall_sum += recall.empty() ? 0.0 : recall.back();
      ++count;
    }
  }
  if (count == 0) return {};
  return {ap_sum / count, recall_sum / count};
}

}  // namespace

CocoStats evaluate_coco(const std::vector<GroundTruth>& ground_truths,
                        const std::vector<Detection>& detections, const CocoEvalOptions& options) {
  std::vector<double> thresholds = options.iou_thresholds;
  if (thresholds.empty())
    for (int k = 0; k < 10; ++k) thresholds.push_back(0.5 + 0.05 * k);

  // Group by (image, category).
  std::set<int> images, categories;
  std::map<std::pair<int, int>, std::vector<const GroundTruth*>> gts;
  std::map<std::pair<int, int>, std::vector<const Detection*>> dts;
  for (const GroundTruth& g : ground_truths) {
    images.insert(g.image);
    categories.insert(g.category);
    gts[{g.image, g.category}].push_back(&g);
  }
  for (const Detection& d : detections) {
    images.insert(d.image);
    categories.insert(d.category);
    dts[{d.image, d.category}].push_back(&d);
  }

  auto run = [&](const std::vector<double>& ts, AreaRange range, int max_det,
                 std::optional<int> only_category = std::nullopt) {
    std::map<int, std::vector<ImageResult>> per_category;
    for (int c : categories) {
      if (only_category && c != *only_category) continue;
      std::vector<ImageResult>& list = per_category[c];
      for (int i : images) {
        const auto g = gts.find({i, c});
        const auto d = dts.find({i, c});
        static const std::vector<const GroundTruth*> kNoGt;
        static const std::vector<const Detection*> kNoDt;
        list.push_back(evaluate_image(g == gts.end() ? kNoGt : g->second,
                                      d == dts.end() ? kNoDt : d->second, ts, range, max_det));
      }
    }
    return accumulate(per_category, ts.size());
  };

  CocoStats s;
  s.images = static_cast<int>(images.size());
  s.ground_truths = static_cast<int>(ground_truths.size());
  s.detections = static_cast<int>(detections.size());
  const int md = options.max_detections;
  const Curve all = run(thresholds, kAreaAll, md);
  s.ap = all.ap;
  s.ar100 = all.recall;
  s.ap50 = run({0.5}, kAreaAll, md).ap;
  s.ap75 = run({0.75}, kAreaAll, md).ap;
  const Curve small = run(thresholds, kAreaSmall, md);
  const Curve medium = run(thresholds, kAreaMedium, md);
  const Curve large = run(thresholds, kAreaLarge, md);
  s.ap_small = small.ap;
  s.ap_medium = medium.ap;
  s.ap_large = large.ap;
  s.ar_small = small.recall;
  s.ar_medium = medium.recall;
  s.ar_large = large.recall;
  s.ar1 = run(thresholds, kAreaAll, 1).recall;
  s.ar10 = run(thresholds, kAreaAll, 10).recall;
  for (int c : categories) {
    s.categories.push_back(c);
    s.ap_per_category.push_back(run(thresholds, kAreaAll, md, c).ap);
  }
  return s;
}

std::string format_coco_stats(const CocoStats& s) {
  return fmt::format("AP {:.4f}  AP50 {:.4f}  AP75 {:.4f}  APs {:.4f}  APm {:.4f}  APl {:.4f}",
                     s.ap, s.ap50, s.ap75, s.ap_small, s.ap_medium, s.ap_large);
}

}  // namespace lensopt
