// The lens layout: the meridional (y-z) cross-section of the traced (scaled) lens, as data in mm
// before anything is drawn, so tests can check it against the tracer.
//
// z runs along the axis from the first vertex (z = 0); surface k's vertex is at
// z_k = t_0 + ... + t_{k-1}; the image plane is at the total track z_K. Surface k's profile is
//   z(y) = z_k + sag_k(y),   sag(y) = c y^2 / (1 + sqrt(1 - c^2 y^2)).
// Clear semi-diameter of surface k: the largest ray height sqrt(x^2 + y^2) at the surface over
// every field (21), wavelength and aimed pupil-edge ray (azimuths -90..90 deg on the aimed pupil
// ellipse), times (1 + margin_fraction) plus margin_mm (and below 1/|c|). Where two surfaces
// across an air space (or a surface and the stop plane) would meet inside that margin, both are
// drawn only up to where they meet (never below their own ray heights): the elements touch there.
// Elements: a glass space between surfaces k and k+1; consecutive glass spaces (a cemented group)
// share an edge radius E = the largest clear semi-diameter of the group's surfaces. A surface
// drawn to a smaller radius d < E ends in a flat annulus at z_k + sag_k(d) from d to E (a cemented
// interface is instead continued along its sphere to E where it can be); the rims y = +-E join the
// ends of front and back surfaces. The stop is drawn at its vertex from the real stop radius
// outward (from the largest ray height there). Rays: `rays_per_field` meridional rays over the
// aimed pupil (y_p from -1 to 1) of each drawn field at 587.6 nm, from a start plane before the
// lens to the image plane.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "lensopt/plot/axes.h"
#include "lensopt/plot/plot_data.h"

namespace lensopt::plot {

struct LayoutOptions {
  std::vector<double> field_fractions{0.0, 0.7, 1.0};  // of the half field
  int rays_per_field = 7;
  double margin_fraction = 0.02;
  double margin_mm = 0.05;
  int edge_azimuths = 17;  // pupil-edge rays per field and wavelength for the clear apertures
  void validate() const;
};

// A profile is a polyline of (z, y) points in mm: Point::x is z, Point::y is y.
struct SurfaceDrawing {
  int surface = 0;  // 0-based
  double vertex_z_mm = 0;
  double curvature_per_mm = 0;
  double conic = 0;                   // profile (lens/lens.h): conic constant k
  std::array<double, 8> asphere{};    // a2, a4, ..., a16 (mm^(1-2i))
  double clear_semi_diameter_mm = 0;  // largest ray height (+ margin)
  double drawn_semi_diameter_mm = 0;  // how far the sphere is drawn
  double edge_semi_diameter_mm = 0;   // how far the drawn curve reaches (annulus included)
  bool in_element = false;
  bool is_stop = false;
  std::vector<Point> profile;  // the sphere, from +drawn to -drawn semi-diameter
  std::vector<Point> curve;    // profile with its annuli, top to bottom: what is drawn

  // z of the drawn curve at height y (|y| <= edge), from the sag formula; nullopt outside.
  std::optional<double> z_at(double y) const;
  // z of the profile (sphere, conic or even asphere) at height y (inside the conic's domain).
  double sag_z(double y) const;
};

struct ElementDrawing {
  int front_surface = 0;  // glass between front_surface and front_surface + 1
  int back_surface = 0;
  std::string glass;
  double edge_semi_diameter_mm = 0;
  std::vector<Point>
      outline;  // closed polygon: front curve top to bottom, back curve bottom to top
  std::array<Point, 2> upper_rim{};  // front surface's top end -> back surface's top end
  std::array<Point, 2> lower_rim{};
};

struct RayDrawing {
  int field = 0;  // index into LayoutGeometry::field_deg
  double pupil_y = 0;
  std::vector<Point> points;  // start, each surface, image plane
  bool complete = false;      // reached the image plane
};

struct LayoutGeometry {
  std::string lens_name;
  double scale = 1;
  double efl_mm = 0;
  double f_number = 0;
  double half_field_deg = 0;
  std::vector<SurfaceDrawing> surfaces;  // every surface, the stop included
  std::vector<ElementDrawing> elements;
  int stop_surface = 0;
  double stop_z_mm = 0;
  double stop_radius_mm = 0;  // the real stop radius (on-axis marginal ray, 587.6 nm)
  // The stop's marks reach from stop_clear_mm to stop_outer_mm. The clear radius is the largest
  // ray height at the stop: one-step ray aiming leaves the off-axis bundles a little (up to a few
  // percent) larger than the real stop radius, and no drawn ray may cross the marks.
  double stop_clear_mm = 0;
  double stop_outer_mm = 0;
  double image_z_mm = 0;  // total track
  double image_half_height_mm = 0;
  std::vector<double> field_deg;          // drawn fields
  std::vector<std::string> field_labels;  // their field_label
  std::vector<RayDrawing> rays;
  double start_z_mm = 0;           // rays start here
  std::vector<double> min_gap_mm;  // per space k (surfaces k, k+1): smallest drawn gap
  std::vector<std::string> warnings;
  // Bounding box of everything drawn (mm).
  double z_lo = 0, z_hi = 0, y_lo = 0, y_hi = 0;
};

LayoutGeometry compute_layout(const PlotContext& ctx, const LayoutOptions& options = {});

// What a drawing of a layout (and a compared one) spans, in mm: the compared lens is shifted by
// compare_shift_mm along z so the image planes coincide; every ray starts at ray_start_z_mm.
struct LayoutExtent {
  double z_lo = 0, z_hi = 0, y_lo = 0, y_hi = 0;
  double compare_shift_mm = 0;
  double ray_start_z_mm = 0;
};
LayoutExtent layout_extent(const LayoutGeometry& geometry, const LayoutGeometry* compare);

// Draws the layout (and a second lens dashed, image planes aligned) into `area`.
void draw_layout(Canvas& canvas, Rect area, const LayoutGeometry& geometry,
                 const LayoutGeometry* compare = nullptr, double font_px = 12);

}  // namespace lensopt::plot
