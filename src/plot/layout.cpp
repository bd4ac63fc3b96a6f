#include "lensopt/plot/layout.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "lensopt/core/error.h"
#include "lensopt/lens/profile_sag.h"
#include "lensopt/plot/style.h"
#include "lensopt/trace/kernel.h"

namespace lensopt::plot {
namespace {

constexpr int kProfilePoints = 49;
constexpr double kSphereLimit = 0.995;  // |c| y stays below this on a drawn sphere

// The profile's sag (lens/profile_sag.h): conic plus even-asphere terms a[0..7] = a2..a16, q
// clamped at 0 beyond the conic's domain (not reached: sphere_limit stops short of it).
double sag(double c, double k, const std::array<double, 8>& a, double y) {
  const double rho = y * y;
  const double q = std::sqrt(std::max(0.0, profile_q2(c, 1.0 + k, rho)));
  return profile_sag_at_q(c, a.data(), rho, q);
}

// How far a profile is drawn: short of the conic's domain edge (1 + k) c^2 r^2 = 1.
double sphere_limit(double c, double k = 0.0) {
  return c == 0.0 || 1.0 + k <= 0.0 ? 1e30 : kSphereLimit / (std::abs(c) * std::sqrt(1.0 + k));
}

}  // namespace

double SurfaceDrawing::sag_z(double y) const {
  return vertex_z_mm + sag(curvature_per_mm, conic, asphere, y);
}

std::optional<double> SurfaceDrawing::z_at(double y) const {
  const double a = std::abs(y);
  if (a > edge_semi_diameter_mm * (1 + 1e-12)) return std::nullopt;
  if (a <= drawn_semi_diameter_mm) return sag_z(a);
  return sag_z(drawn_semi_diameter_mm);  // on the flat annulus
}

void LayoutOptions::validate() const {
  if (field_fractions.empty()) throw Error("layout: no field fractions given");
  for (double f : field_fractions)
    if (!(f >= 0.0 && f <= 1.0))
      throw Error(fmt::format("layout: field fraction {} is outside [0, 1]", f));
  if (rays_per_field < 1 || rays_per_field > 101)
    throw Error(fmt::format("layout: rays_per_field = {} must be in 1..101", rays_per_field));
  if (!(margin_fraction >= 0 && margin_fraction < 1) || !(margin_mm >= 0))
    throw Error("layout: aperture margins must be >= 0 (fraction < 1)");
  if (edge_azimuths < 3) throw Error("layout: edge_azimuths must be >= 3");
}

namespace {

// Largest ray height (mm) at every surface over fields, wavelengths and aimed pupil-edge rays
// (`edge_azimuths` of them per field).
std::vector<double> ray_heights(const TraceSystem<double>& sys, const LayoutOptions& options) {
  const TraceLens<double>& lens = sys.lens;
  const int k_count = lens.surface_count();
  std::vector<double> max_height(k_count, 0.0);
  RayBundle<double> start, rays;
  const int field_count = static_cast<int>(sys.fields_deg.size());
  const int az = options.edge_azimuths;
  for (int w = 0; w <= sys.wavelength_count; ++w) {
    start.resize(static_cast<std::size_t>(field_count) * az);
    for (int h = 0; h < field_count; ++h) {
      const PupilMap<double>& map = sys.pupil_map(h, w);
      for (int a = 0; a < az; ++a) {
        const double phi = kPi * (-0.5 + static_cast<double>(a) / (az - 1));
        set_pupil_ray(sys, h, map.scale_x * std::cos(phi),
                      map.offset_y + map.scale_y * std::sin(phi), start,
                      static_cast<std::size_t>(h) * az + a);
      }
    }
    for (int k = 0; k < k_count; ++k) {
      rays = start;
      trace_bundle(lens, w, k + 1, false, rays, static_cast<RayRecord<double>*>(nullptr));
      for (std::size_t i = 0; i < rays.size(); ++i)
        if (ray_ok(rays, i))
          max_height[k] = std::max(max_height[k], std::hypot(rays.x[i], rays.y[i]));
    }
  }
  return max_height;
}

// Surfaces: clear apertures (ray height plus margins, short of a conic's domain edge).
void add_surfaces(LayoutGeometry& g, const TraceLens<double>& lens,
                  const std::vector<double>& vertex, const std::vector<double>& max_height,
                  const LayoutOptions& options) {
  const int k_count = lens.surface_count();
  g.surfaces.resize(k_count);
  for (int k = 0; k < k_count; ++k) {
    SurfaceDrawing& s = g.surfaces[k];
    s.surface = k;
    s.vertex_z_mm = vertex[k];
    s.curvature_per_mm = lens.curvature_per_mm[k];
    if (lens.has_profiles()) {
      s.conic = lens.conic[k];
      for (int j = 0; j < kAsphereTerms; ++j) s.asphere[j] = lens.asphere_term(k, j);
    }
    s.is_stop = k == lens.stop;
    s.clear_semi_diameter_mm =
        std::min(max_height[k] * (1 + options.margin_fraction) + options.margin_mm,
                 sphere_limit(s.curvature_per_mm, s.conic));
    s.drawn_semi_diameter_mm = s.clear_semi_diameter_mm;
    s.edge_semi_diameter_mm = s.clear_semi_diameter_mm;
  }
}

// Where two surfaces across an air space meet inside their clear apertures (elements touching
// at the edge), the margin is given up: both are drawn only up to the meeting height (never
// below their ray heights).
// The stop counts as a flat surface here: a surface that reaches past the stop plane is drawn
// up to the plane (the diaphragm then rests on the element's flat rim).
void trim_where_surfaces_meet(LayoutGeometry& g, const TraceLens<double>& lens,
                              const std::vector<double>& max_height) {
  const int k_count = lens.surface_count();
  for (int k = 0; k + 1 < k_count; ++k) {
    if (lens.is_glass[k]) continue;
    SurfaceDrawing& a = g.surfaces[k];
    SurfaceDrawing& b = g.surfaces[k + 1];
    const double reach = std::min(a.clear_semi_diameter_mm, b.clear_semi_diameter_mm);
    auto gap = [&](double y) { return b.sag_z(y) - a.sag_z(y); };
    const int steps = 400;
    double lo = -1;
    for (int i = 1; i <= steps; ++i) {
      if (gap(reach * i / steps) <= 0) {
        lo = reach * (i - 1) / steps;
        double hi = reach * i / steps;
        for (int it = 0; it < 60; ++it) {
          const double mid = 0.5 * (lo + hi);
          (gap(mid) > 0 ? lo : hi) = mid;
        }
        break;
      }
    }
    if (lo < 0) continue;
    const double meet = lo;  // gap > 0 below this height
    if (!a.is_stop)
      a.clear_semi_diameter_mm = std::min(a.clear_semi_diameter_mm, std::max(max_height[k], meet));
    if (!b.is_stop)
      b.clear_semi_diameter_mm =
          std::min(b.clear_semi_diameter_mm, std::max(max_height[k + 1], meet));
    if (max_height[k] > meet || max_height[k + 1] > meet)
      g.warnings.push_back(
          fmt::format("surfaces {} and {} meet at height {:.3f} mm, inside the rays' height there",
                      k + 1, k + 2, meet));
  }
  for (SurfaceDrawing& s : g.surfaces) {
    s.drawn_semi_diameter_mm = s.clear_semi_diameter_mm;
    s.edge_semi_diameter_mm = s.clear_semi_diameter_mm;
  }
}

// Glass spaces [first, last]: the elements, cemented ones as one group.
std::vector<std::pair<int, int>> element_groups(const TraceLens<double>& lens) {
  const int k_count = lens.surface_count();
  std::vector<std::pair<int, int>> groups;  // glass spaces [first, last]
  for (int k = 0; k < k_count - 1; ++k) {
    if (!lens.is_glass[k]) continue;
    if (!groups.empty() && groups.back().second == k - 1)
      groups.back().second = k;
    else
      groups.push_back({k, k});
  }
  return groups;
}

// An element's surfaces share its edge (the largest clear aperture among them); interior
// (cemented) surfaces are drawn out to it.
void set_element_edges(LayoutGeometry& g, const std::vector<std::pair<int, int>>& groups) {
  for (const auto& [first, last] : groups) {
    double edge = 0;
    for (int s = first; s <= last + 1; ++s)
      edge = std::max(edge, g.surfaces[s].clear_semi_diameter_mm);
    for (int s = first; s <= last + 1; ++s) {
      SurfaceDrawing& d = g.surfaces[s];
      d.in_element = true;
      d.edge_semi_diameter_mm = edge;
      const bool interior = s != first && s != last + 1;
      if (interior && edge <= sphere_limit(d.curvature_per_mm, d.conic))
        d.drawn_semi_diameter_mm = edge;
    }
  }
}

// The stop: from its clear radius outward, short of its neighbours' drawn curves.
void set_stop(LayoutGeometry& g, const TraceLens<double>& lens) {
  const int k_count = lens.surface_count();
  SurfaceDrawing& stop = g.surfaces[lens.stop];
  const double inner = g.stop_clear_mm;
  double outer = std::max(inner * 1.3, inner + 0.3);
  const int steps = 200;
  for (int side : {-1, 1}) {
    const int k = lens.stop + side;
    if (k < 0 || k >= k_count) continue;
    const SurfaceDrawing& n = g.surfaces[k];
    for (int i = 0; i <= steps; ++i) {
      const double y = inner + (outer - inner) * i / steps;
      const auto z = n.z_at(y);
      if (z && (side < 0 ? *z >= g.stop_z_mm : *z <= g.stop_z_mm)) {
        outer = std::max(inner * 1.02, y - (outer - inner) / steps);
        break;
      }
    }
  }
  g.stop_outer_mm = outer;
  if (!stop.in_element) {
    stop.drawn_semi_diameter_mm = outer;
    stop.edge_semi_diameter_mm = outer;
  }
}

// Each surface's profile out to its drawn semi-diameter, and its curve with the flat annulus out
// to the element's edge.
void set_profiles(LayoutGeometry& g) {
  for (SurfaceDrawing& s : g.surfaces) {
    const double d = s.drawn_semi_diameter_mm;
    for (int i = 0; i < kProfilePoints; ++i) {
      const double y = d * (1.0 - 2.0 * i / (kProfilePoints - 1));
      s.profile.push_back({s.sag_z(y), y});
    }
    s.curve = s.profile;
    if (s.edge_semi_diameter_mm > d * (1 + 1e-12)) {
      const double z_end = s.sag_z(d);
      s.curve.insert(s.curve.begin(), Point{z_end, s.edge_semi_diameter_mm});
      s.curve.push_back({z_end, -s.edge_semi_diameter_mm});
    }
  }
}

// The elements' outlines and rims, with a warning for a negative edge thickness.
void add_elements(LayoutGeometry& g, const PlotContext& ctx,
                  const std::vector<std::pair<int, int>>& groups) {
  for (const auto& [first, last] : groups) {
    for (int k = first; k <= last; ++k) {
      ElementDrawing e;
      e.front_surface = k;
      e.back_surface = k + 1;
      e.glass = glass_label(ctx.lens.surfaces[k].material);
      const SurfaceDrawing& front = g.surfaces[k];
      const SurfaceDrawing& back = g.surfaces[k + 1];
      e.edge_semi_diameter_mm = front.edge_semi_diameter_mm;
      e.outline = front.curve;
      e.outline.insert(e.outline.end(), back.curve.rbegin(), back.curve.rend());
      e.upper_rim = {front.curve.front(), back.curve.front()};
      e.lower_rim = {front.curve.back(), back.curve.back()};
      const double edge_thickness = e.upper_rim[1].x - e.upper_rim[0].x;
      if (edge_thickness <= 0)
        g.warnings.push_back(fmt::format(
            "element of surfaces {}-{}: edge thickness {:.3f} mm at semi-diameter {:.3f} mm", k + 1,
            k + 2, edge_thickness, e.edge_semi_diameter_mm));
      g.elements.push_back(std::move(e));
    }
  }
}

// Smallest drawn gap between consecutive surfaces, with a warning where they cross.
void find_gaps(LayoutGeometry& g) {
  const int k_count = static_cast<int>(g.surfaces.size());
  for (int k = 0; k + 1 < k_count; ++k) {
    const SurfaceDrawing& a = g.surfaces[k];
    const SurfaceDrawing& b = g.surfaces[k + 1];
    const double reach = std::min(a.edge_semi_diameter_mm, b.edge_semi_diameter_mm);
    double gap = 1e30, at = 0;
    for (int i = 0; i <= 400; ++i) {
      const double y = reach * i / 400.0;
      const double d = *b.z_at(y) - *a.z_at(y);
      if (d < gap) {
        gap = d;
        at = y;
      }
    }
    g.min_gap_mm.push_back(gap);
    if (gap < 0)
      g.warnings.push_back(fmt::format(
          "surfaces {} and {} cross at height {:.3f} mm (by {:.3f} mm)", k + 1, k + 2, at, -gap));
  }
}

// Ray bundles at the reference wavelength: `rays_per_field` meridional rays per drawn field,
// from before the first surface to the image.
void add_ray_bundles(LayoutGeometry& g, const PlotContext& ctx, const LayoutOptions& options,
                     const std::vector<double>& vertex) {
  const TraceSystem<double>& sys = ctx.sys;
  const TraceLens<double>& lens = sys.lens;
  const int k_count = lens.surface_count();
  RayBundle<double> start, rays;
  const int ref = sys.wavelength_count;
  const std::vector<int> fields = field_indices(ctx, options.field_fractions);
  double z_first = 0;
  for (const Point& p : g.surfaces[0].curve) z_first = std::min(z_first, p.x);
  g.start_z_mm = z_first - std::max(1.0, 0.12 * g.image_z_mm);
  const int n = options.rays_per_field;
  for (std::size_t j = 0; j < fields.size(); ++j) {
    const int h = fields[j];
    g.field_deg.push_back(sys.fields_deg[h]);
    g.field_labels.push_back(field_label(sys, h));
    const PupilMap<double>& map = sys.pupil_map(h, ref);
    const double theta = sys.fields_deg[h] * kPi / 180.0;
    start.resize(n);
    std::vector<RayDrawing> drawn(n);
    std::vector<char> alive(n, 1);
    for (int i = 0; i < n; ++i) {
      const double py = n == 1 ? 0.0 : -1.0 + 2.0 * i / (n - 1);
      set_pupil_ray(sys, h, 0.0, map.offset_y + map.scale_y * py, start, i);
      drawn[i].field = static_cast<int>(j);
      drawn[i].pupil_y = py;
      const Point first{g.start_z_mm, start.y[i] + std::tan(theta) * (g.start_z_mm - start.z[i])};
      alive[i] = std::isfinite(first.y);
      if (alive[i]) drawn[i].points.push_back(first);
    }
    for (int k = 0; k < k_count; ++k) {
      rays = start;
      trace_bundle(lens, ref, k + 1, false, rays, static_cast<RayRecord<double>*>(nullptr));
      for (int i = 0; i < n; ++i) {
        alive[i] = alive[i] && ray_ok(rays, i);
        if (alive[i]) drawn[i].points.push_back({vertex[k] + rays.z[i], rays.y[i]});
      }
    }
    rays = start;
    trace_bundle(lens, ref, k_count, true, rays, static_cast<RayRecord<double>*>(nullptr));
    int failed = 0;
    for (int i = 0; i < n; ++i) {
      drawn[i].complete = alive[i] && ray_ok(rays, i);
      failed += drawn[i].complete ? 0 : 1;
      if (drawn[i].complete) {
        drawn[i].points.push_back({g.image_z_mm, rays.y[i]});
        g.image_half_height_mm = std::max(g.image_half_height_mm, std::abs(rays.y[i]));
      }
    }
    if (failed > 0)
      g.warnings.push_back(fmt::format("{} of the {} drawn rays of field {:.2f} deg fail", failed,
                                       n, sys.fields_deg[h]));
    for (RayDrawing& r : drawn) g.rays.push_back(std::move(r));
  }
}

// The image's half height and the drawing's bounds.
void set_bounds(LayoutGeometry& g) {
  double widest = 0;
  for (const SurfaceDrawing& s : g.surfaces) widest = std::max(widest, s.edge_semi_diameter_mm);
  g.image_half_height_mm = std::max(g.image_half_height_mm * 1.08, 0.5 * widest);

  g.z_lo = g.start_z_mm;
  g.z_hi = g.image_z_mm;
  double y_max = std::max({widest, g.image_half_height_mm, g.stop_outer_mm});
  for (const RayDrawing& r : g.rays)
    for (const Point& p : r.points) y_max = std::max(y_max, std::abs(p.y));
  g.y_lo = -y_max;
  g.y_hi = y_max;
}

}  // namespace

LayoutGeometry compute_layout(const PlotContext& ctx, const LayoutOptions& options) {
  options.validate();
  const TraceSystem<double>& sys = ctx.sys;
  const TraceLens<double>& lens = sys.lens;
  // The drawing is the y-z section of a centred system: rays of a lens with coordinate breaks,
  // tilts, decenters or decentred apertures (issue 32) sit in each surface's own frame.
  if (lens.geometry.placed())
    throw Error(SourceLocation{ctx.lens.source_path},
                "the layout of a lens with coordinate breaks, tilts, decenters or decentred "
                "apertures is not drawn yet; plot --kind spot, fan, field or psf work");
  const int k_count = lens.surface_count();
  LayoutGeometry g;
  g.lens_name = ctx.lens.name;
  g.scale = sys.scale;
  g.efl_mm = sys.efl_mm;
  g.f_number = sys.efl_mm / sys.epd_mm;
  g.half_field_deg = sys.fields_deg.back();
  g.stop_surface = lens.stop;

  std::vector<double> vertex(k_count, 0.0);
  for (int k = 1; k < k_count; ++k) vertex[k] = vertex[k - 1] + lens.thickness_mm[k - 1];
  g.image_z_mm = vertex[k_count - 1] + lens.thickness_mm[k_count - 1];
  g.stop_z_mm = vertex[lens.stop];

  const std::vector<double> max_height = ray_heights(sys, options);
  g.stop_radius_mm = sys.stop_radius_mm;  // the real marginal ray's height (the aperture)
  g.stop_clear_mm = std::max(g.stop_radius_mm, max_height[lens.stop]);

  add_surfaces(g, lens, vertex, max_height, options);
  trim_where_surfaces_meet(g, lens, max_height);
  const std::vector<std::pair<int, int>> groups = element_groups(lens);
  set_element_edges(g, groups);
  set_stop(g, lens);
  set_profiles(g);
  add_elements(g, ctx, groups);
  find_gaps(g);
  add_ray_bundles(g, ctx, options, vertex);
  set_bounds(g);
  return g;
}

namespace {

// A ray's points, extended back along its first segment to start at `start_z` (drawing
// coordinates, i.e. after `shift`).
std::vector<Point> ray_points_from(const RayDrawing& r, double shift, double start_z) {
  std::vector<Point> pts = r.points;
  if (pts.size() >= 2 && pts[0].x + shift > start_z + 1e-9) {
    const double slope = (pts[1].y - pts[0].y) / (pts[1].x - pts[0].x);
    const double z = start_z - shift;
    pts.insert(pts.begin(), Point{z, pts[0].y + slope * (z - pts[0].x)});
  }
  return pts;
}

}  // namespace

LayoutExtent layout_extent(const LayoutGeometry& g, const LayoutGeometry* cmp) {
  LayoutExtent e;
  e.compare_shift_mm = cmp ? g.image_z_mm - cmp->image_z_mm : 0.0;
  e.ray_start_z_mm =
      cmp ? std::min(g.start_z_mm, cmp->start_z_mm + e.compare_shift_mm) : g.start_z_mm;
  e.z_lo = g.z_lo;
  e.z_hi = g.z_hi;
  e.y_lo = g.y_lo;
  e.y_hi = g.y_hi;
  auto take = [&](const LayoutGeometry& l, double shift) {
    e.z_lo = std::min(e.z_lo, l.z_lo + shift);
    e.z_hi = std::max(e.z_hi, l.z_hi + shift);
    e.y_lo = std::min(e.y_lo, l.y_lo);
    e.y_hi = std::max(e.y_hi, l.y_hi);
    for (const RayDrawing& r : l.rays)
      for (const Point& p : ray_points_from(r, shift, e.ray_start_z_mm)) {
        e.y_lo = std::min(e.y_lo, p.y);
        e.y_hi = std::max(e.y_hi, p.y);
      }
  };
  take(g, 0.0);
  if (cmp) take(*cmp, e.compare_shift_mm);
  // Rays of a broken design can fly far off: they are clipped, not fitted.
  double lens_y = 0;
  for (const LayoutGeometry* l : {&g, cmp})
    if (l) {
      lens_y = std::max(lens_y, l->image_half_height_mm);
      for (const SurfaceDrawing& s : l->surfaces)
        lens_y = std::max(lens_y, s.edge_semi_diameter_mm);
    }
  e.y_lo = std::max(e.y_lo, -2.5 * lens_y);
  e.y_hi = std::min(e.y_hi, 2.5 * lens_y);
  const double y = std::max(-e.y_lo, e.y_hi);  // keep the axis in the middle
  e.y_lo = -y;
  e.y_hi = y;
  return e;
}

void draw_layout(Canvas& canvas, Rect area, const LayoutGeometry& g, const LayoutGeometry* cmp,
                 double font_px) {
  const LayoutExtent extent = layout_extent(g, cmp);
  const double dz = extent.compare_shift_mm;
  const double z_lo = extent.z_lo, z_hi = extent.z_hi;
  const double pad_z = 0.04 * (z_hi - z_lo);
  std::vector<LegendEntry> entries;
  const int nf = static_cast<int>(g.field_deg.size());
  for (int j = 0; j < nf; ++j)
    entries.push_back({"field " + g.field_labels[j], field_colour(j, nf)});
  if (cmp) {
    entries.push_back({g.lens_name + " (solid)", kLensStroke});
    entries.push_back({cmp->lens_name + " (dashed)", kCompareStroke, "6 4"});
  }
  const double legend_w = area.width - 16;
  const double legend_band = legend_size(entries, font_px * 0.9, true, legend_w).y + font_px;
  const double label_band = font_px * 4.2;
  const Rect frame = area.inset(8, legend_band, 8, label_band);
  const Axes ax = Axes::equal_aspect(frame, z_lo - pad_z, z_hi + pad_z, extent.y_lo, extent.y_hi);
  auto px = [&](Point p, double shift = 0.0) { return ax.to_px(p.x + shift, p.y); };
  // Every ray starts at the common left edge (a compared lens may start further left).
  auto ray_points = [&](const RayDrawing& r, double shift) {
    return ray_points_from(r, shift, extent.ray_start_z_mm);
  };
  auto px_all = [&](const std::vector<Point>& pts, double shift = 0.0) {
    std::vector<Point> out;
    out.reserve(pts.size());
    for (const Point& p : pts) out.push_back(px(p, shift));
    return out;
  };

  // Optical axis.
  Style axis{"#9a9a9a", 0.8};
  axis.dash = "12 4 2 4";
  canvas.line(ax.to_px(z_lo - pad_z / 2, 0), ax.to_px(z_hi + pad_z / 2, 0), axis);

  // Glass, then rays, then outlines on top.
  for (const ElementDrawing& e : g.elements)
    canvas.polygon(px_all(e.outline), Style{"none", 0, kGlassFill});
  canvas.set_clip(frame.x, frame.y - legend_band * 0.3, frame.width,
                  frame.height + legend_band * 0.3);
  for (const RayDrawing& r : g.rays)
    canvas.polyline(px_all(ray_points(r, 0.0)), Style{field_colour(r.field, nf), 1.0});
  canvas.clear_clip();
  const Style outline{kLensStroke, 1.4};
  for (const ElementDrawing& e : g.elements) canvas.polygon(px_all(e.outline), outline);
  for (const SurfaceDrawing& s : g.surfaces)
    if (!s.in_element && !s.is_stop) canvas.polyline(px_all(s.curve), outline);

  auto draw_stop_and_image = [&](const LayoutGeometry& l, double shift, const std::string& dash) {
    Style stop{dash.empty() ? "#111111" : kCompareStroke, 3.0};
    stop.dash = dash;
    for (double side : {1.0, -1.0})
      canvas.line(px({l.stop_z_mm, side * l.stop_clear_mm}, shift),
                  px({l.stop_z_mm, side * l.stop_outer_mm}, shift), stop);
    Style image{"#333333", 2.0};
    image.dash = dash;
    canvas.line(px({l.image_z_mm, -l.image_half_height_mm}, shift),
                px({l.image_z_mm, l.image_half_height_mm}, shift), image);
  };
  draw_stop_and_image(g, 0.0, "");
  const TextStyle small{font_px * 0.85, Anchor::kMiddle, "#333333"};
  canvas.text({px({g.stop_z_mm, g.stop_outer_mm}).x, px({g.stop_z_mm, g.stop_outer_mm}).y - 5},
              "stop", small);
  canvas.text({px({g.image_z_mm, g.image_half_height_mm}).x,
               px({g.image_z_mm, g.image_half_height_mm}).y - 5},
              "image", small);

  if (cmp) {
    Style dashed{kCompareStroke, 1.3};
    dashed.dash = "6 4";
    const int nc = static_cast<int>(cmp->field_deg.size());
    canvas.set_clip(frame.x, frame.y - legend_band * 0.3, frame.width,
                    frame.height + legend_band * 0.3);
    for (const RayDrawing& r : cmp->rays) {
      Style s{field_colour(r.field, nc), 0.8, "none", 0.75};
      s.dash = "5 4";
      canvas.polyline(px_all(ray_points(r, dz), dz), s);
    }
    canvas.clear_clip();
    for (const ElementDrawing& e : cmp->elements) canvas.polygon(px_all(e.outline, dz), dashed);
    for (const SurfaceDrawing& s : cmp->surfaces)
      if (!s.in_element && !s.is_stop) canvas.polyline(px_all(s.curve, dz), dashed);
    draw_stop_and_image(*cmp, dz, "4 3");
  }

  // Glass names under the elements, staggered when they would overlap.
  const TextStyle glass_text{font_px * 0.8, Anchor::kMiddle, "#1b2a3a"};
  double last_right = -1e30;
  int row = 0;
  double lowest = 0;
  for (const ElementDrawing& e : g.elements) lowest = std::max(lowest, e.edge_semi_diameter_mm);
  for (const ElementDrawing& e : g.elements) {
    const double zc =
        0.5 * (g.surfaces[e.front_surface].vertex_z_mm + g.surfaces[e.back_surface].vertex_z_mm);
    const Point at = px({zc, -lowest});
    const double w = text_width_px(e.glass, glass_text.size_px);
    row = (at.x - w / 2 < last_right + 4) ? 1 - row : 0;
    const double y = at.y + glass_text.size_px * (1.4 + 1.15 * row);
    canvas.line({at.x, px({zc, -e.edge_semi_diameter_mm}).y + 2}, {at.x, y - glass_text.size_px},
                Style{"#b0b0b0", 0.6});
    canvas.text({at.x, y}, e.glass, glass_text);
    last_right = at.x + w / 2;
  }

  // Problems of the design itself (surfaces crossing, failing rays), on the page.
  if (!g.warnings.empty()) {
    const std::string more =
        g.warnings.size() > 1 ? fmt::format(" (and {} more)", g.warnings.size() - 1) : "";
    canvas.text({area.right() - 8, area.bottom() - 8}, "warning: " + g.warnings[0] + more,
                TextStyle{font_px * 0.85, Anchor::kEnd, "#b03a2e"});
  }

  // Legend (fields; the compared lens) and a scale bar.
  draw_legend(canvas, {area.x + 8, area.y + 2}, entries, font_px * 0.9, true, legend_w);
  const double bar_mm = nice_ceil((z_hi - z_lo) / 8.0);
  draw_scale_bar(canvas, {frame.x + 6, area.bottom() - 8}, bar_mm * ax.px_per_x(),
                 format_tick(bar_mm, bar_mm) + " mm", font_px * 0.85);
}

}  // namespace lensopt::plot
