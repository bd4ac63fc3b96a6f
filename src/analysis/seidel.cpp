#include "lensopt/analysis/seidel.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>

#include "core/json_number.h"
#include "lensopt/core/error.h"
#include "lensopt/paraxial/paraxial.h"

namespace lensopt {
namespace {

// The paraxial ray (y, w) at the first vertex plane of the marginal ray (from the axial object
// point through the entrance-pupil rim) and of the chief ray (from field h's object point through
// the pupil centre), object space n = 1.
void start_rays_paraxial(const TraceSystem<double>& sys, int h, ParaxialRay<double>& marginal,
                         ParaxialRay<double>& chief) {
  const double r_ep = 0.5 * sys.epd_mm;
  const double z_ep = sys.entrance_pupil_z_mm;
  if (sys.object_at_infinity()) {
    const double t = std::tan(sys.fields_deg[h] * kPi / 180.0);
    marginal = {r_ep, 0.0};
    chief = {-z_ep * t, t};
    return;
  }
  const double d = sys.object_distance_mm;
  const double u = r_ep / (z_ep + d);
  marginal = {u * d, u};
  const double object_y = sys.field_object_y_mm.empty() ? 0.0 : sys.field_object_y_mm[h];
  const double ub = -object_y / (z_ep + d);
  chief = {object_y + ub * d, ub};
}

// Both rays after the last surface (y at the last vertex, w in image space) at one wavelength.
void trace_both(const TraceLens<double>& lens, double wavelength_nm, ParaxialRay<double>& marginal,
                ParaxialRay<double>& chief) {
  const int k_count = lens.surface_count();
  marginal = paraxial_trace(lens, marginal, k_count, wavelength_nm);
  chief = paraxial_trace(lens, chief, k_count, wavelength_nm);
}

}  // namespace

SeidelReport seidel_report(const TraceSystem<double>& sys) {
  const TraceLens<double>& lens = sys.lens;
  const int k_count = lens.surface_count();
  const double lambda = lens.reference_nm();
  SeidelReport out;
  FirstOrderData& fo = out.first_order;
  // The largest field (by its chief-ray angle).
  int h_max = 0;
  for (int h = 0; h < static_cast<int>(sys.fields_deg.size()); ++h)
    if (std::abs(sys.fields_deg[h]) > std::abs(sys.fields_deg[h_max])) h_max = h;
  fo.max_field_deg = sys.fields_deg.empty() ? 0.0 : sys.fields_deg[h_max];
  ParaxialRay<double> m0, c0;
  start_rays_paraxial(sys, h_max, m0, c0);
  // The chromatic band: the shortest and longest spec wavelengths.
  fo.short_nm = fo.long_nm = lens.wavelengths_nm[0];
  for (int w = 0; w < sys.wavelength_count; ++w) {
    fo.short_nm = std::min(fo.short_nm, lens.wavelengths_nm[w]);
    fo.long_nm = std::max(fo.long_nm, lens.wavelengths_nm[w]);
  }
  out.surfaces.assign(k_count, SurfaceSeidel{});
  ParaxialRay<double> m = m0, c = c0;
  double petzval_sum = 0.0;  // sum c Delta(1/n)
  for (int k = 0; k < k_count; ++k) {
    if (k > 0) {
      const double n_medium = lens.index_at_nm(k - 1, lambda);
      m.y += lens.thickness_mm[k - 1] * m.w / n_medium;
      c.y += lens.thickness_mm[k - 1] * c.w / n_medium;
    }
    const double n = lens.index_at_nm(k - 1, lambda), n1 = lens.index_at_nm(k, lambda);
    const double curv = lens.paraxial_curvature(k);
    const double a = m.w + n * m.y * curv;   // A
    const double ab = c.w + n * c.y * curv;  // Abar
    const double w1 = m.w - m.y * curv * (n1 - n);
    const double wb1 = c.w - c.y * curv * (n1 - n);
    const double d_inv_n = 1.0 / n1 - 1.0 / n;
    const double d_inv_n2 = 1.0 / (n1 * n1) - 1.0 / (n * n);
    const double d_u_n = w1 / (n1 * n1) - m.w / (n * n);
    const double h_inv = ab * m.y - a * c.y;
    SurfaceSeidel& s = out.surfaces[k];
    s.s1 = -a * a * m.y * d_u_n;
    s.s2 = -a * ab * m.y * d_u_n;
    s.s3 = -ab * ab * m.y * d_u_n;
    s.s4 = -h_inv * h_inv * curv * d_inv_n;
    s.s5 = ab * (curv * c.y * d_inv_n * (2.0 * ab * m.y - a * c.y) - ab * ab * m.y * d_inv_n2);
    petzval_sum += curv * d_inv_n;
    // The fourth-order sag beyond the paraxial sphere (conic, a4; a2 is in the paraxial curvature).
    const double cs = lens.curvature_per_mm[k];
    const double conic = lens.conic.empty() ? 0.0 : lens.conic[k];
    const double delta4 =
        (1.0 + conic) * cs * cs * cs / 8.0 + lens.asphere_term(k, 1) - curv * curv * curv / 8.0;
    if (delta4 != 0.0) {
      const double g = 8.0 * delta4 * (n1 - n);
      const double y = m.y, yb = c.y;
      s.s1 += g * y * y * y * y;
      s.s2 += g * y * y * y * yb;
      s.s3 += g * y * y * yb * yb;
      s.s5 += g * y * yb * yb * yb;
    }
    // Primary colour: Delta(dn / n), dn = n(short) - n(long) of each medium.
    const double dn0 = lens.index_at_nm(k - 1, fo.short_nm) - lens.index_at_nm(k - 1, fo.long_nm);
    const double dn1 = lens.index_at_nm(k, fo.short_nm) - lens.index_at_nm(k, fo.long_nm);
    const double d_dn_n = dn1 / n1 - dn0 / n;
    s.c1 = a * m.y * d_dn_n;
    s.c2 = ab * m.y * d_dn_n;
    out.sums.s1 += s.s1;
    out.sums.s2 += s.s2;
    out.sums.s3 += s.s3;
    out.sums.s4 += s.s4;
    out.sums.s5 += s.s5;
    out.sums.c1 += s.c1;
    out.sums.c2 += s.c2;
    m.w = w1;
    c.w = wb1;
    if (k == 0) fo.lagrange_invariant = h_inv;
  }
  const double n_image = lens.index_at_nm(k_count - 1, lambda);
  out.marginal_final_w = m.w;
  const ParaxialData<double> par = paraxial_data(lens, lambda);
  fo.efl_mm = par.efl_mm;
  fo.bfl_mm = par.bfl_mm;
  fo.epd_mm = sys.epd_mm;
  fo.entrance_pupil_z_mm = sys.entrance_pupil_z_mm;
  fo.image_distance_mm = -m.y * n_image / m.w;
  const double last_t = lens.thickness_mm[k_count - 1];
  // The exit pupil: where the chief ray crosses the axis in image space; its rim the marginal
  // ray's height there.
  // The pupil's place does not depend on the field (the trace is linear): a lens whose fields
  // are all on axis has a chief ray of zero height and slope, so a chief ray of slope 0.01
  // through the entrance pupil's centre locates it instead.
  ParaxialRay<double> chief = c;
  if (chief.w == 0.0 && chief.y == 0.0) {
    const double u = 0.01;
    chief =
        paraxial_trace(lens, ParaxialRay<double>{-sys.entrance_pupil_z_mm * u, u}, k_count, lambda);
  }
  const double z_xp = -chief.y * n_image / chief.w;  // from the last vertex
  fo.exit_pupil_z_mm = z_xp - last_t;
  fo.exit_pupil_diameter_mm = 2.0 * std::abs(m.y + z_xp * m.w / n_image);
  fo.image_f_number = par.efl_mm / sys.epd_mm;
  fo.working_f_number = 1.0 / (2.0 * std::abs(m.w));
  fo.magnification = sys.object_at_infinity() ? 0.0 : m0.w / m.w;
  fo.paraxial_image_height_mm = c.y + fo.image_distance_mm * c.w / n_image;
  fo.total_track_mm = 0.0;
  for (double t : lens.thickness_mm) fo.total_track_mm += t;
  out.petzval_radius_mm = petzval_sum != 0.0 ? 1.0 / (n_image * petzval_sum) : 0.0;
  // Exact paraxial colour: the two wavelengths traced through.
  ParaxialRay<double> ms = m0, cs = c0, ml = m0, cl = c0;
  trace_both(lens, fo.short_nm, ms, cs);
  trace_both(lens, fo.long_nm, ml, cl);
  const double ns = lens.index_at_nm(k_count - 1, fo.short_nm);
  const double nl = lens.index_at_nm(k_count - 1, fo.long_nm);
  out.axial_colour_mm = (-ms.y * ns / ms.w) - (-ml.y * nl / ml.w);
  out.lateral_colour_mm =
      (cs.y + fo.image_distance_mm * cs.w / ns) - (cl.y + fo.image_distance_mm * cl.w / nl);
  const double checks[] = {fo.efl_mm,   fo.image_distance_mm, out.marginal_final_w,
                           out.sums.s1, out.sums.s5,          fo.paraxial_image_height_mm};
  for (double v : checks)
    if (!std::isfinite(v) || m.w == 0.0)
      throw Error(
          "the paraxial marginal or chief ray is not finite (an afocal lens or a pupil at "
          "infinity): no first-order data or Seidel sums");
  return out;
}

namespace {

std::string radius_text(double curvature) {
  return curvature == 0.0 ? std::string("inf") : fmt::format("{:.6g}", 1.0 / curvature);
}

// -0 (a flat or dummy surface's product of a 0 with a negative) printed as 0.
double unsigned_zero(double v) {
  return v == 0.0 ? 0.0 : v;
}

std::string medium_text(const Lens& lens, int k) {
  if (k < 0 || k >= static_cast<int>(lens.surfaces.size())) return "";
  const Material& m = lens.surfaces[k].material;
  return m.is_air() ? std::string("") : m.label();
}

}  // namespace

std::string format_prescription_text(const Lens& lens, const TraceSystem<double>& sys,
                                     const SeidelReport& r) {
  const TraceLens<double>& tl = sys.lens;
  const int k_count = tl.surface_count();
  const double lambda = tl.reference_nm();
  std::string out;
  auto line = [&](const std::string& s) { out += s + "\n"; };
  line(fmt::format("Prescription{} (mm; indices at {} nm):",
                   sys.scale != 1.0 ? fmt::format(" scaled by {:.6f}", sys.scale) : std::string(),
                   lambda));
  line(fmt::format("  {:>4}  {:>12}  {:>11}  {:>14}  {:>9}  {:>8}  {:>9}  {:>8}", "surf", "radius",
                   "thickness", "glass", "index", "Abbe", "semi-diam", "conic"));
  for (int k = 0; k < k_count; ++k) {
    const bool stop = k == tl.stop;
    const double sd = tl.semi_diameter_mm.empty() ? 0.0 : tl.semi_diameter_mm[k];
    const bool glass = tl.is_glass.empty() ? false : tl.is_glass[k];
    line(fmt::format("  {:>4}  {:>12}  {:11.4f}  {:>14}  {:9.6f}  {:>8}  {:>9}  {:8.4g}",
                     fmt::format("{}{}", k + 1, stop ? "*" : ""),
                     radius_text(tl.curvature_per_mm[k]), tl.thickness_mm[k], medium_text(lens, k),
                     tl.index_at_nm(k, lambda),
                     glass ? fmt::format("{:.3f}", tl.vd[k]) : std::string(""),
                     sd > 0 ? fmt::format("{:.4f}", sd) : std::string("-"),
                     tl.conic.empty() ? 0.0 : tl.conic[k]));
  }
  line("  (* the aperture stop; semi-diameters as written, - where none is set)");
  const FirstOrderData& f = r.first_order;
  line("");
  line("First-order data (paraxial, primary wavelength):");
  line(fmt::format("  effective focal length     {:12.6f}", f.efl_mm));
  line(fmt::format("  back focal length          {:12.6f}", f.bfl_mm));
  line(fmt::format("  paraxial image distance    {:12.6f}   (last vertex to the paraxial image)",
                   f.image_distance_mm));
  line(fmt::format("  image-space F/#            {:12.6f}", f.image_f_number));
  line(fmt::format("  working F/#                {:12.6f}", f.working_f_number));
  line(fmt::format("  magnification              {:12.6f}", f.magnification));
  line(fmt::format("  entrance pupil             {:12.6f} dia. at {:.6f} from the first vertex",
                   f.epd_mm, f.entrance_pupil_z_mm));
  line(fmt::format("  exit pupil                 {:12.6f} dia. at {:.6f} from the image plane",
                   f.exit_pupil_diameter_mm, f.exit_pupil_z_mm));
  line(fmt::format("  Lagrange invariant         {:12.6f}   (at {:.4f} deg)", f.lagrange_invariant,
                   f.max_field_deg));
  line(fmt::format("  paraxial image height      {:12.6f}", f.paraxial_image_height_mm));
  line(fmt::format("  total track                {:12.6f}", f.total_track_mm));
  line("");
  line(fmt::format("Seidel sums (mm; chromatic over {} - {} nm):", f.short_nm, f.long_nm));
  line(fmt::format("  {:>4}  {:>12}  {:>12}  {:>12}  {:>12}  {:>12}  {:>12}  {:>12}", "surf",
                   "S_I sph", "S_II coma", "S_III ast", "S_IV ptz", "S_V dist", "C_I axial",
                   "C_II lat"));
  auto row = [&](const std::string& name, const SurfaceSeidel& s) {
    const auto z = unsigned_zero;
    line(
        fmt::format("  {:>4}  {:12.6g}  {:12.6g}  {:12.6g}  {:12.6g}  {:12.6g}  {:12.6g}  {:12.6g}",
                    name, z(s.s1), z(s.s2), z(s.s3), z(s.s4), z(s.s5), z(s.c1), z(s.c2)));
  };
  for (int k = 0; k < k_count; ++k) row(std::to_string(k + 1), r.surfaces[k]);
  row("sum", r.sums);
  const double w = r.marginal_final_w;
  line(fmt::format(
      "  third-order transverse aberrations at full aperture and field (mm): spherical {:.6g}, "
      "tangential coma {:.6g}, astigmatism + field curvature (tangential) {:.6g}, distortion "
      "{:.6g}",
      r.sums.s1 / (2 * w), 3 * r.sums.s2 / (2 * w), (3 * r.sums.s3 + r.sums.s4) / (2 * w),
      r.sums.s5 / (2 * w)));
  line(
      fmt::format("  Petzval radius {}; axial colour {:.6g} mm, lateral colour {:.6g} mm "
                  "(paraxial, {} nm less {} nm)",
                  r.petzval_radius_mm != 0.0 ? fmt::format("{:.6g} mm", r.petzval_radius_mm)
                                             : std::string("inf"),
                  r.axial_colour_mm, r.lateral_colour_mm, f.short_nm, f.long_nm));
  return out;
}

std::string format_prescription_json(const Lens& lens, const TraceSystem<double>& sys,
                                     const SeidelReport& r) {
  using nlohmann::json;
  const TraceLens<double>& tl = sys.lens;
  const double lambda = tl.reference_nm();
  json surfaces = json::array();
  for (int k = 0; k < tl.surface_count(); ++k) {
    const SurfaceSeidel& s = r.surfaces[k];
    json j;
    j["surface"] = k + 1;
    j["stop"] = k == tl.stop;
    j["curvature_per_mm"] = finite_or_null(tl.curvature_per_mm[k]);
    j["thickness_mm"] = finite_or_null(tl.thickness_mm[k]);
    j["medium"] = medium_text(lens, k);
    j["index"] = finite_or_null(tl.index_at_nm(k, lambda));
    j["semi_diameter_mm"] =
        finite_or_null(tl.semi_diameter_mm.empty() ? 0.0 : tl.semi_diameter_mm[k]);
    j["conic"] = finite_or_null(tl.conic.empty() ? 0.0 : tl.conic[k]);
    const auto z = unsigned_zero;
    j["seidel"] = {{"S_I", finite_or_null(z(s.s1))},   {"S_II", finite_or_null(z(s.s2))},
                   {"S_III", finite_or_null(z(s.s3))}, {"S_IV", finite_or_null(z(s.s4))},
                   {"S_V", finite_or_null(z(s.s5))},   {"C_I", finite_or_null(z(s.c1))},
                   {"C_II", finite_or_null(z(s.c2))}};
    surfaces.push_back(j);
  }
  const FirstOrderData& f = r.first_order;
  json j;
  j["scale"] = finite_or_null(sys.scale);
  j["surfaces"] = surfaces;
  j["first_order"] = {{"efl_mm", finite_or_null(f.efl_mm)},
                      {"bfl_mm", finite_or_null(f.bfl_mm)},
                      {"image_distance_mm", finite_or_null(f.image_distance_mm)},
                      {"image_f_number", finite_or_null(f.image_f_number)},
                      {"working_f_number", finite_or_null(f.working_f_number)},
                      {"magnification", finite_or_null(f.magnification)},
                      {"epd_mm", finite_or_null(f.epd_mm)},
                      {"entrance_pupil_z_mm", finite_or_null(f.entrance_pupil_z_mm)},
                      {"exit_pupil_z_mm", finite_or_null(f.exit_pupil_z_mm)},
                      {"exit_pupil_diameter_mm", finite_or_null(f.exit_pupil_diameter_mm)},
                      {"lagrange_invariant", finite_or_null(f.lagrange_invariant)},
                      {"paraxial_image_height_mm", finite_or_null(f.paraxial_image_height_mm)},
                      {"total_track_mm", finite_or_null(f.total_track_mm)},
                      {"max_field_deg", finite_or_null(f.max_field_deg)}};
  j["seidel_sums"] = {{"S_I", finite_or_null(r.sums.s1)},   {"S_II", finite_or_null(r.sums.s2)},
                      {"S_III", finite_or_null(r.sums.s3)}, {"S_IV", finite_or_null(r.sums.s4)},
                      {"S_V", finite_or_null(r.sums.s5)},   {"C_I", finite_or_null(r.sums.c1)},
                      {"C_II", finite_or_null(r.sums.c2)}};
  j["chromatic_band_nm"] = {f.short_nm, f.long_nm};
  j["axial_colour_mm"] = finite_or_null(r.axial_colour_mm);
  j["lateral_colour_mm"] = finite_or_null(r.lateral_colour_mm);
  j["petzval_radius_mm"] = finite_or_null(r.petzval_radius_mm);
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace lensopt
