// Generated driving-like scenes with exact boxes (the model is in detection/scenes.h).
#include "lensopt/detection/scenes.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "lensopt/core/error.h"
#include "lensopt/core/random.h"

namespace lensopt {
namespace {

constexpr int kSuper = 2;
constexpr double kMinVisible = 0.3;
constexpr double kMinSidePx = 4.0;

using Rgb = std::array<float, 3>;

// The supersampled canvas: colours and, per pixel, the object that painted it last (-1: none).
struct Canvas {
  int w = 0, h = 0;
  std::vector<Rgb> rgb;
  std::vector<int> owner;
  int current = -1;           // the object being painted, -1 for the background
  std::vector<long> painted;  // per object: pixels painted (visible or not)

  Canvas(int width, int height)
      : w(width), h(height), rgb(width * height), owner(width * height, -1) {}

  void put(int x, int y, Rgb c) {
    if (x < 0 || y < 0 || x >= w || y >= h) return;
    const std::size_t i = static_cast<std::size_t>(y) * w + x;
    rgb[i] = c;
    owner[i] = current;
    if (current >= 0) ++painted[current];
  }
  void rect(double x0, double y0, double x1, double y1, Rgb c) {
    for (int y = std::max(0, int(std::ceil(y0))); y < std::min(h, int(std::ceil(y1))); ++y)
      for (int x = std::max(0, int(std::ceil(x0))); x < std::min(w, int(std::ceil(x1))); ++x)
        put(x, y, c);
  }
  void ellipse(double cx, double cy, double rx, double ry, Rgb c) {
    for (int y = std::max(0, int(cy - ry)); y <= std::min(h - 1, int(cy + ry) + 1); ++y)
      for (int x = std::max(0, int(cx - rx)); x <= std::min(w - 1, int(cx + rx) + 1); ++x) {
        const double u = (x + 0.5 - cx) / rx, v = (y + 0.5 - cy) / ry;
        if (u * u + v * v <= 1.0) put(x, y, c);
      }
  }
  // A ring (wheel of a bike): radius r, thickness t.
  void ring(double cx, double cy, double r, double t, Rgb c) {
    for (int y = std::max(0, int(cy - r)); y <= std::min(h - 1, int(cy + r) + 1); ++y)
      for (int x = std::max(0, int(cx - r)); x <= std::min(w - 1, int(cx + r) + 1); ++x) {
        const double d = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
        if (d <= r && d >= r - t) put(x, y, c);
      }
  }
  // A thick line segment.
  void line(double xa, double ya, double xb, double yb, double t, Rgb c) {
    const double len = std::hypot(xb - xa, yb - ya);
    const int steps = std::max(1, int(len * 2));
    for (int k = 0; k <= steps; ++k) {
      const double s = double(k) / steps;
      const double x = xa + s * (xb - xa), y = ya + s * (yb - ya);
      rect(x - t / 2, y - t / 2, x + t / 2, y + t / 2, c);
    }
  }
};

// Smooth value noise in [-1, 1] on a lattice of `cell` pixels (bilinear between random values).
class ValueNoise {
 public:
  ValueNoise(Rng& rng, int width, int height, double cell)
      : cell_(cell), nx_(int(width / cell) + 2), ny_(int(height / cell) + 2), v_(nx_ * ny_) {
    const UniformReal u{-1.0, 1.0};
    for (double& x : v_) x = u(rng);
  }
  double at(double x, double y) const {
    const double fx = x / cell_, fy = y / cell_;
    const int ix = std::clamp(int(fx), 0, nx_ - 2), iy = std::clamp(int(fy), 0, ny_ - 2);
    const double tx = fx - ix, ty = fy - iy;
    auto v = [&](int i, int j) { return v_[j * nx_ + i]; };
    return (1 - ty) * ((1 - tx) * v(ix, iy) + tx * v(ix + 1, iy)) +
           ty * ((1 - tx) * v(ix, iy + 1) + tx * v(ix + 1, iy + 1));
  }

 private:
  double cell_;
  int nx_, ny_;
  std::vector<double> v_;
};

Rgb scale(Rgb c, double f) {
  return {float(std::clamp(c[0] * f, 0.0, 1.0)), float(std::clamp(c[1] * f, 0.0, 1.0)),
          float(std::clamp(c[2] * f, 0.0, 1.0))};
}

Rgb random_colour(Rng& rng) {
  const UniformReal u{0.05, 0.95};
  return {float(u(rng)), float(u(rng)), float(u(rng))};
}

void paint_background(Canvas& cv, Rng& rng, double horizon) {
  const ValueNoise coarse(rng, cv.w, cv.h, cv.h / 6.0), fine(rng, cv.w, cv.h, 3.0);
  const UniformReal u{0.0, 1.0};
  const Rgb sky_top{0.35f, 0.5f, 0.8f}, sky_low{0.75f, 0.8f, 0.88f};
  const double road_half_bottom = 0.55 * cv.w * (0.8 + 0.4 * u(rng));
  const double vanish_x = cv.w * (0.4 + 0.2 * u(rng));
  for (int y = 0; y < cv.h; ++y)
    for (int x = 0; x < cv.w; ++x) {
      Rgb c;
      if (y < horizon) {
        const double t = y / horizon;
        for (int k = 0; k < 3; ++k) c[k] = float((1 - t) * sky_top[k] + t * sky_low[k]);
        c = scale(c, 1.0 + 0.05 * coarse.at(x, y));
      } else {
        // Road between the two lines from the vanishing point; pavement outside.
        const double depth = (y - horizon) / (cv.h - horizon);  // 0 at the horizon
        const double half = road_half_bottom * depth;
        const bool road = std::abs(x - vanish_x) < half;
        const double n = 0.12 * fine.at(x, y) + 0.08 * coarse.at(x, y);
        c = road ? Rgb{0.32f, 0.32f, 0.34f} : Rgb{0.55f, 0.52f, 0.47f};
        c = scale(c, 1.0 + n);
        // Dashed centre line: dashes of equal length in 1/depth.
        if (road && std::abs(x - vanish_x) < 0.012 * half + 0.5 &&
            std::fmod(8.0 / std::max(depth, 1e-3), 2.0) < 1.0)
          c = {0.9f, 0.88f, 0.75f};
      }
      cv.put(x, y, c);
    }
  // Buildings and trees along the horizon on both sides (background: owner -1).
  const UniformInt count{6, 14};
  const int buildings = count(rng);
  for (int b = 0; b < buildings; ++b) {
    const bool left = u(rng) < 0.5;
    const double bw = cv.w * (0.04 + 0.1 * u(rng)), bh = cv.h * (0.08 + 0.3 * u(rng));
    const double x0 =
        left ? u(rng) * (vanish_x - bw) * 0.8
             : vanish_x + 0.2 * (cv.w - vanish_x) + u(rng) * 0.8 * (cv.w - vanish_x - bw);
    const Rgb wall = scale(random_colour(rng), 0.8);
    cv.rect(x0, horizon - bh, x0 + bw, horizon + 2, wall);
    // Windows.
    const double wx = std::max(3.0, bw / 8), wy = std::max(3.0, bh / 10);
    for (double y = horizon - bh + wy; y + wy < horizon - wy; y += 2 * wy)
      for (double x = x0 + wx; x + wx < x0 + bw; x += 2 * wx)
        cv.rect(x, y, x + wx, y + wy, scale(wall, u(rng) < 0.3 ? 1.4 : 0.45));
  }
  const int trees = count(rng);
  for (int t = 0; t < trees; ++t) {
    const double x = u(rng) * cv.w, r = cv.h * (0.02 + 0.05 * u(rng));
    cv.rect(x - r / 6, horizon - r, x + r / 6, horizon + 1, {0.3f, 0.22f, 0.12f});
    cv.ellipse(x, horizon - 1.6 * r, r, 1.2 * r, scale({0.2f, 0.45f, 0.18f}, 0.8 + 0.4 * u(rng)));
  }
}

// One object of class `category` (paper_class_map ids) with its foot at (fx, fy) and scale s
// (supersampled pixels per metre-like unit).
void paint_object(Canvas& cv, Rng& rng, int category, double fx, double fy, double s) {
  const UniformReal u{0.0, 1.0};
  const Rgb body = random_colour(rng);
  switch (category) {
    case 1: {  // car: body, cabin, windows, wheels
      const double w = s * (1.7 + 0.4 * u(rng)), h = s * (1.3 + 0.2 * u(rng));
      cv.rect(fx - w / 2, fy - 0.55 * h, fx + w / 2, fy - 0.1 * h, body);
      cv.rect(fx - 0.38 * w, fy - h, fx + 0.38 * w, fy - 0.5 * h, scale(body, 0.9));
      cv.rect(fx - 0.32 * w, fy - 0.93 * h, fx + 0.32 * w, fy - 0.6 * h, {0.15f, 0.18f, 0.22f});
      cv.rect(fx - 0.45 * w, fy - 0.15 * h, fx - 0.25 * w, fy, {0.05f, 0.05f, 0.05f});
      cv.rect(fx + 0.25 * w, fy - 0.15 * h, fx + 0.45 * w, fy, {0.05f, 0.05f, 0.05f});
      cv.rect(fx - 0.46 * w, fy - 0.5 * h, fx - 0.36 * w, fy - 0.42 * h, {1.0f, 0.9f, 0.6f});
      cv.rect(fx + 0.36 * w, fy - 0.5 * h, fx + 0.46 * w, fy - 0.42 * h, {1.0f, 0.9f, 0.6f});
      break;
    }
    case 2: {  // bus / truck: a tall box with a row of windows
      const double w = s * (2.4 + 0.6 * u(rng)), h = s * (2.8 + 0.8 * u(rng));
      cv.rect(fx - w / 2, fy - h, fx + w / 2, fy - 0.08 * h, body);
      const bool bus = u(rng) < 0.5;
      if (bus)
        cv.rect(fx - 0.45 * w, fy - 0.92 * h, fx + 0.45 * w, fy - 0.6 * h, {0.15f, 0.2f, 0.25f});
      else
        cv.rect(fx - 0.4 * w, fy - 0.95 * h, fx + 0.4 * w, fy - 0.75 * h, {0.15f, 0.2f, 0.25f});
      cv.rect(fx - 0.45 * w, fy - 0.1 * h, fx - 0.25 * w, fy, {0.05f, 0.05f, 0.05f});
      cv.rect(fx + 0.25 * w, fy - 0.1 * h, fx + 0.45 * w, fy, {0.05f, 0.05f, 0.05f});
      break;
    }
    case 3: {  // bike (with rider's legs left out): two wheels and a frame
      const double r = s * 0.33, t = std::max(1.5, s * 0.06);
      const double xa = fx - 0.5 * s, xb = fx + 0.5 * s, yc = fy - r;
      const Rgb dark = scale(body, 0.5);
      cv.ring(xa, yc, r, t, {0.05f, 0.05f, 0.05f});
      cv.ring(xb, yc, r, t, {0.05f, 0.05f, 0.05f});
      cv.line(xa, yc, fx, yc - 0.7 * r, t, dark);
      cv.line(fx, yc - 0.7 * r, xb, yc, t, dark);
      cv.line(fx, yc - 0.7 * r, fx - 0.1 * s, yc - 1.6 * r, t, dark);
      cv.line(xb, yc, xb - 0.1 * s, yc - 1.6 * r, t, dark);
      break;
    }
    case 4: {  // person: legs, torso, head
      const double h = s * (1.6 + 0.3 * u(rng)), w = 0.28 * h;
      const Rgb skin{0.85f * float(0.6 + 0.4 * u(rng)), 0.65f * float(0.6 + 0.4 * u(rng)), 0.5f};
      cv.rect(fx - w / 2, fy - 0.48 * h, fx - w / 12, fy, scale(body, 0.4));
      cv.rect(fx + w / 12, fy - 0.48 * h, fx + w / 2, fy, scale(body, 0.4));
      cv.rect(fx - w / 2 - 0.05 * h, fy - 0.85 * h, fx + w / 2 + 0.05 * h, fy - 0.45 * h, body);
      cv.ellipse(fx, fy - 0.93 * h, 0.08 * h, 0.075 * h, skin);
      break;
    }
    case 5: {  // traffic light on a pole: housing and three lamps, one lit
      const double h = s * 3.2, w = s * 0.35;
      cv.rect(fx - w / 8, fy - h, fx + w / 8, fy, {0.25f, 0.25f, 0.25f});
      const double top = fy - h - 0.9 * s;
      cv.rect(fx - w / 2, top, fx + w / 2, fy - h, {0.08f, 0.08f, 0.08f});
      const UniformInt lit{0, 2};
      const int on = lit(rng);
      const Rgb lamps[3] = {{1.0f, 0.15f, 0.1f}, {1.0f, 0.8f, 0.1f}, {0.2f, 1.0f, 0.4f}};
      for (int k = 0; k < 3; ++k)
        cv.ellipse(fx, top + (k + 0.5) * 0.3 * s, 0.12 * s, 0.12 * s,
                   k == on ? lamps[k] : scale(lamps[k], 0.25));
      break;
    }
    default: {  // traffic sign on a pole: a disc or a triangle
      const double h = s * 2.2, r = s * 0.35;
      cv.rect(fx - r / 8, fy - h, fx + r / 8, fy, {0.45f, 0.45f, 0.45f});
      const double cy = fy - h - r;
      if (u(rng) < 0.5) {
        cv.ellipse(fx, cy, r, r, {0.85f, 0.1f, 0.1f});
        cv.ellipse(fx, cy, 0.75 * r, 0.75 * r, {0.95f, 0.95f, 0.95f});
      } else {
        for (int y = int(cy - r); y <= int(cy + r); ++y) {
          const double half = r * (y - (cy - r)) / (2 * r);
          cv.rect(fx - half, y, fx + half, y + 1,
                  y > cy + 0.8 * r ? Rgb{0.8f, 0.1f, 0.1f} : Rgb{0.95f, 0.85f, 0.1f});
        }
      }
      break;
    }
  }
}

}  // namespace

void SceneSetOptions::validate() const {
  if (count < 1 || count > 1000000)
    throw Error(fmt::format("--count {} must be in [1, 1000000]", count));
  if (width < 64 || height < 64 || width > 8192 || height > 8192)
    throw Error(
        fmt::format("scene size {}x{} must be within 64 .. 8192 pixels a side", width, height));
}

DetectionScene make_detection_scene(int width, int height, std::uint64_t seed) {
  if (width < 64 || height < 64 || width > 8192 || height > 8192)
    throw Error(
        fmt::format("scene size {}x{} must be within 64 .. 8192 pixels a side", width, height));
  Rng rng(seed * 0x9E3779B97F4A7C15ull + 777);
  const UniformReal u{0.0, 1.0};
  Canvas cv(width * kSuper, height * kSuper);
  const double horizon = cv.h * (0.40 + 0.08 * u(rng));
  paint_background(cv, rng, horizon);

  // Objects on the ground plane: depth log-uniform in [1, 12], sorted far to near.
  struct Object {
    int category;
    double z, x_ground;  // x_ground: lateral position, -1 .. 1 of the view at that depth
  };
  const UniformInt how_many{6, 18};
  std::vector<Object> objects(how_many(rng));
  // Class frequencies like a street: cars most, then people and signs.
  const double weights[6] = {0.38, 0.1, 0.07, 0.2, 0.1, 0.15};
  std::discrete_distribution<int> pick(weights, weights + 6);
  for (Object& o : objects) {
    o.category = pick(rng) + 1;
    o.z = std::exp(u(rng) * std::log(12.0));
    // Vehicles on the road, the rest mostly beside it.
    const bool on_road = o.category <= 3;
    o.x_ground = on_road ? (u(rng) - 0.5) * 1.2 : (u(rng) < 0.5 ? -1 : 1) * (0.7 + 0.5 * u(rng));
  }
  std::sort(objects.begin(), objects.end(),
            [](const Object& a, const Object& b) { return a.z > b.z; });
  cv.painted.assign(objects.size(), 0);
  const double unit = 0.16 * cv.h;  // image size of one unit at depth 1
  const double ground = cv.h - horizon;
  for (std::size_t k = 0; k < objects.size(); ++k) {
    const Object& o = objects[k];
    const double fy = horizon + 0.95 * ground / o.z;
    const double fx = cv.w * 0.5 + o.x_ground * 1.2 * cv.w / o.z * 0.5;
    cv.current = static_cast<int>(k);
    paint_object(cv, rng, o.category, fx, fy, unit / o.z);
  }
  cv.current = -1;

  // Visible boxes from the owner buffer.
  const std::size_t n = objects.size();
  std::vector<long> visible(n, 0);
  std::vector<int> bx0(n, cv.w), by0(n, cv.h), bx1(n, -1), by1(n, -1);
  for (int y = 0; y < cv.h; ++y)
    for (int x = 0; x < cv.w; ++x) {
      const int o = cv.owner[static_cast<std::size_t>(y) * cv.w + x];
      if (o < 0) continue;
      ++visible[o];
      bx0[o] = std::min(bx0[o], x);
      by0[o] = std::min(by0[o], y);
      bx1[o] = std::max(bx1[o], x);
      by1[o] = std::max(by1[o], y);
    }
  DetectionScene scene;
  for (std::size_t k = 0; k < n; ++k) {
    if (visible[k] == 0 || visible[k] < kMinVisible * cv.painted[k]) continue;
    const Box b{double(bx0[k]) / kSuper, double(by0[k]) / kSuper, double(bx1[k] + 1) / kSuper,
                double(by1[k] + 1) / kSuper};
    if (b.width() < kMinSidePx || b.height() < kMinSidePx) continue;
    GroundTruth g;
    g.image = 0;
    g.category = objects[k].category;
    g.box = b;
    scene.boxes.push_back(g);
  }
  // Downsample 2 x 2.
  scene.image = FloatImage(width, height, 3, 0.0f);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c) {
        float s = 0;
        for (int dy = 0; dy < kSuper; ++dy)
          for (int dx = 0; dx < kSuper; ++dx)
            s += cv.rgb[static_cast<std::size_t>(y * kSuper + dy) * cv.w + x * kSuper + dx][c];
        scene.image.at(x, y, c) = s / (kSuper * kSuper);
      }
  return scene;
}

DetectionDataset write_detection_scenes(const std::filesystem::path& dir,
                                        const SceneSetOptions& options) {
  options.validate();
  std::filesystem::create_directories(dir / "images");
  DetectionDataset d;
  d.categories = paper_class_map().classes;
  for (int i = 0; i < options.count; ++i) {
    DetectionScene s =
        make_detection_scene(options.width, options.height, options.seed * 100003 + i);
    DetectionImage image;
    image.id = i + 1;
    image.file_name = fmt::format("scene_{:04d}.png", i);
    image.width = options.width;
    image.height = options.height;
    write_image(dir / "images" / image.file_name, s.image);
    for (GroundTruth& g : s.boxes) {
      g.image = image.id;
      d.annotations.push_back(g);
    }
    d.images.push_back(image);
  }
  write_coco(d, dir / "annotations.json");
  return d;
}

}  // namespace lensopt
