// Lens layouts for the search: taking a lens apart into elements, moving the stop, cementing and
// splitting neighbours, generated starts and seeded glasses (equations in search.h).
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "lensopt/core/error.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/search/search.h"
#include "search_detail.h"

namespace lensopt {
namespace {

// Air between a split cemented pair (mm), and where a moved stop goes, as fractions of f.
constexpr double kSplitAirMm = 0.2;
constexpr double kFrontStopFraction = 0.1;   // stop 0.1 f before the first vertex
constexpr double kRearStopFraction = 0.06;   // stop 0.06 f after the last vertex (about 1 mm)
constexpr double kGeneratedAirMm = 1.0;      // generated gaps (f = 17.156 mm), scaled with f
constexpr double kGeneratedStopGapMm = 2.0;  // generated gap holding the stop
constexpr double kPositiveThicknessMm = 3.0;
constexpr double kNegativeThicknessMm = 1.2;
// Seed-0 glasses of generated starts: the paper's baselines' crown and flint (Ohara S-LAH96,
// S-TIM1), or the nearest of another catalog.
constexpr double kCrownNd = 1.7639, kCrownVd = 48.49;
constexpr double kFlintNd = 1.6259, kFlintVd = 35.70;

Error form_error(const Lens& lens, const std::string& message) {
  return Error(SourceLocation{lens.source_path}, message);
}

// Thin-lens power sign of an element: (nd - 1)(c_front - c_rear).
bool is_positive(const ElementForm& e) {
  return (e.glass.nd - 1.0) * (e.front_curvature_per_mm - e.rear_curvature_per_mm) >= 0.0;
}

const Glass& nearest_glass(const Catalog& catalog, double nd, double vd) {
  const Glass* best = nullptr;
  double best_d = std::numeric_limits<double>::infinity();
  for (const Glass& g : catalog.glasses) {
    if (!(g.nd > 1.0 && g.vd > 0.0)) continue;
    // Distance in (nd, vd) with vd weighted to an index scale (1 Abbe unit ~ 0.01 in nd).
    const double d = std::hypot(g.nd - nd, (g.vd - vd) * 0.01);
    if (d < best_d) {
      best_d = d;
      best = &g;
    }
  }
  if (!best) throw Error(fmt::format("catalog {} has no usable glass", catalog.name));
  return *best;
}

}  // namespace

std::string LensLayout::code() const {
  std::string out;
  for (int i = 0; i <= elements; ++i) {
    if (stop_gap == i) out += i == 0 ? "S" : "-S";
    if (i == elements) break;
    if (!out.empty()) {
      const bool joint = i > 0 && stop_gap != i && cemented[i - 1];
      out += joint ? "=" : "-";
    }
    out += "E";
  }
  return out;
}

bool LensLayout::stop_in_cement() const {
  return stop_gap > 0 && stop_gap < elements && cemented[stop_gap - 1];
}

LensLayout parse_layout(const std::string& code) {
  auto bad = [&](const char* why) { return Error(fmt::format("layout '{}': {}", code, why)); };
  if (code.empty() || code.size() % 2 == 0) throw bad("expected E or S separated by '-' or '='");
  LensLayout layout;
  layout.stop_gap = -1;
  char previous = 0;
  for (std::size_t i = 0; i < code.size(); i += 2) {
    const char token = code[i];
    const char separator = i > 0 ? code[i - 1] : '-';
    if (separator != '-' && separator != '=')
      throw bad("separators are '-' (air) or '=' (cemented)");
    if (separator == '=' && (previous != 'E' || token != 'E'))
      throw bad("'=' joins two elements only");
    if (token == 'E') {
      if (layout.elements > 0) layout.cemented.push_back(separator == '=');
      ++layout.elements;
    } else if (token == 'S') {
      if (layout.stop_gap >= 0) throw bad("one stop only");
      layout.stop_gap = layout.elements;
    } else {
      throw bad("expected E or S separated by '-' or '='");
    }
    previous = token;
  }
  if (layout.elements == 0 || layout.stop_gap < 0) throw bad("needs elements E and one stop S");
  return layout;
}

LensForm decompose_lens(const Lens& lens) {
  lens.validate();
  LensForm form;
  const auto& s = lens.surfaces;
  const int k_count = static_cast<int>(s.size());
  const int stop = lens.stop_index();
  if (stop < 0) throw form_error(lens, "the lens has no stop");
  if (!s[stop].material.is_air() || (stop > 0 && !s[stop - 1].material.is_air()))
    throw form_error(lens,
                     fmt::format("surface {}: the stop must be in air to be moved", stop + 1));
  int k = 0;
  bool stop_seen = false;
  if (stop == 0) {
    form.layout.stop_gap = 0;
    form.front_stop_mm = s[0].thickness_mm;
    stop_seen = true;
    k = 1;
  }
  while (k < k_count) {
    if (s[k].material.is_air()) {
      throw form_error(lens, fmt::format("surface {}: an air-to-air surface that is not the stop "
                                         "(the search handles elements, gaps and one stop)",
                                         k + 1));
    }
    // Element: surface k (front) to k + 1 (rear, or the joint with the next element).
    ElementForm e;
    e.front_curvature_per_mm = s[k].curvature_per_mm;
    e.thickness_mm = s[k].thickness_mm;
    e.glass = s[k].material;
    if (k + 1 >= k_count) throw form_error(lens, "the last glass has no rear surface");
    e.rear_curvature_per_mm = s[k + 1].curvature_per_mm;
    form.elements.push_back(e);
    if (!s[k + 1].material.is_air()) {
      // Cemented: surface k + 1 is the next element's front.
      form.layout.cemented.push_back(true);
      form.gap_mm.push_back(0.0);
      k += 1;
      continue;
    }
    const int rear = k + 1;
    if (rear == k_count - 1) {
      form.image_mm = s[rear].thickness_mm;
      k = k_count;
    } else if (rear + 1 == stop) {
      stop_seen = true;
      form.layout.stop_gap = static_cast<int>(form.elements.size());
      if (stop == k_count - 1) {
        form.rear_stop_mm = s[rear].thickness_mm;
        form.image_mm = s[stop].thickness_mm;
        k = k_count;
      } else {
        const double gap = s[rear].thickness_mm + s[stop].thickness_mm;
        form.gap_mm.push_back(gap);
        form.layout.cemented.push_back(false);
        form.stop_fraction = gap > 0 ? s[rear].thickness_mm / gap : 0.5;
        k = stop + 1;
      }
    } else {
      form.gap_mm.push_back(s[rear].thickness_mm);
      form.layout.cemented.push_back(false);
      k = rear + 1;
    }
  }
  if (!stop_seen) throw form_error(lens, "the stop is not between elements");
  form.layout.elements = static_cast<int>(form.elements.size());
  const double efl = paraxial_data(make_trace_lens(lens), lens.specs.primary_wavelength_nm).efl_mm;
  form.focal_length_mm = std::isfinite(efl) && efl > 0 ? efl : lens.specs.focal_length_mm();
  return form;
}

Lens compose_lens(const LensForm& form, const Lens& like) {
  const LensLayout& layout = form.layout;
  const int n = layout.elements;
  if (n < 1 || static_cast<int>(form.elements.size()) != n ||
      static_cast<int>(layout.cemented.size()) != n - 1 ||
      static_cast<int>(form.gap_mm.size()) != n - 1)
    throw Error("compose_lens: the form's element, gap and layout counts disagree");
  if (layout.stop_in_cement())
    throw Error(fmt::format("layout {}: the stop sits in a cemented joint", layout.code()));
  Lens lens = like;
  lens.surfaces.clear();
  auto add = [&](double c, double t, const Material& m, bool stop) {
    Surface surface;
    surface.curvature_per_mm = c;
    surface.thickness_mm = t;
    surface.material = m;
    surface.is_stop = stop;
    surface.written_as_radius = true;
    lens.surfaces.push_back(surface);
  };
  if (layout.stop_gap == 0) add(0.0, form.front_stop_mm, Material::air(), true);
  for (int i = 0; i < n; ++i) {
    const ElementForm& e = form.elements[i];
    if (i == 0 || !layout.cemented[i - 1])
      add(e.front_curvature_per_mm, e.thickness_mm, e.glass, false);
    if (i < n - 1 && layout.cemented[i]) {
      const ElementForm& next = form.elements[i + 1];
      add(e.rear_curvature_per_mm, next.thickness_mm, next.glass, false);
    } else if (i < n - 1) {
      const double gap = form.gap_mm[i];
      if (layout.stop_gap == i + 1) {
        add(e.rear_curvature_per_mm, gap * form.stop_fraction, Material::air(), false);
        add(0.0, gap * (1.0 - form.stop_fraction), Material::air(), true);
      } else {
        add(e.rear_curvature_per_mm, gap, Material::air(), false);
      }
    } else if (layout.stop_gap == n) {
      add(e.rear_curvature_per_mm, form.rear_stop_mm, Material::air(), false);
      add(0.0, form.image_mm, Material::air(), true);
    } else {
      add(e.rear_curvature_per_mm, form.image_mm, Material::air(), false);
    }
  }
  return lens;
}

LensForm with_layout(const LensForm& form, const LensLayout& layout) {
  if (layout.elements != form.layout.elements)
    throw Error(fmt::format("layout {} has {} elements, the lens {}", layout.code(),
                            layout.elements, form.layout.elements));
  if (layout.stop_in_cement())
    throw Error(fmt::format("layout {}: the stop sits in a cemented joint", layout.code()));
  LensForm out = form;
  const int n = layout.elements;
  // The stop's old gap keeps its total length; a new stop gap is split in halves.
  if (layout.stop_gap != form.layout.stop_gap) out.stop_fraction = 0.5;
  for (int i = 0; i + 1 < n; ++i) {
    const bool was = form.layout.cemented[i], is = layout.cemented[i];
    ElementForm& a = out.elements[i];
    ElementForm& b = out.elements[i + 1];
    if (!was && is) {
      // Cement: one joint surface with the mean curvature.
      const double c = 0.5 * (a.rear_curvature_per_mm + b.front_curvature_per_mm);
      a.rear_curvature_per_mm = c;
      b.front_curvature_per_mm = c;
      out.gap_mm[i] = 0.0;
    } else if (was && !is) {
      out.gap_mm[i] = kSplitAirMm;
    }
  }
  const double f = form.focal_length_mm;
  if (layout.stop_gap == 0 && form.layout.stop_gap != 0) out.front_stop_mm = kFrontStopFraction * f;
  if (layout.stop_gap == n && form.layout.stop_gap != n) out.rear_stop_mm = kRearStopFraction * f;
  out.layout = layout;
  return out;
}

std::vector<LensLayout> layout_variants(const LensLayout& given, bool vary_stop, bool vary_cement,
                                        const StopPlaces& places) {
  std::vector<LensLayout> out{given};
  const int n = given.elements;
  const int pairs = n - 1;
  std::vector<std::vector<bool>> patterns;
  if (vary_cement) {
    for (int bits = 0; bits < (1 << pairs); ++bits) {
      std::vector<bool> p(static_cast<std::size_t>(pairs));
      for (int j = 0; j < pairs; ++j) p[j] = (bits >> (pairs - 1 - j)) & 1;  // first pair: top bit
      patterns.push_back(p);
    }
  } else {
    patterns.push_back(given.cemented);
  }
  for (const auto& pattern : patterns) {
    std::vector<int> gaps;
    if (vary_stop) {
      for (int g = 0; g <= n; ++g) {
        const bool allowed = g == 0 ? places.front : g == n ? places.rear : places.between;
        if (allowed) gaps.push_back(g);
      }
    } else {
      gaps.push_back(given.stop_gap);
    }
    for (int g : gaps) {
      LensLayout l;
      l.elements = n;
      l.stop_gap = g;
      l.cemented = pattern;
      if (l.stop_in_cement()) continue;
      if (std::find(out.begin(), out.end(), l) == out.end()) out.push_back(l);
    }
  }
  return out;
}

LensLayout default_layout(int elements) {
  LensLayout l;
  l.elements = elements;
  l.stop_gap = elements == 1 ? 0 : (elements + 1) / 2;
  l.cemented.assign(static_cast<std::size_t>(std::max(0, elements - 1)), false);
  return l;
}

LensForm generated_form(const LensLayout& layout, const Catalog& catalog, double focal_length_mm) {
  static const std::vector<std::vector<double>> kPowers = {
      {1.0}, {0.5, 0.5}, {1.25, -1.7, 1.4}, {1.1, -1.8, 2.6, -1.0}};
  const int n = layout.elements;
  if (n < 1 || n > static_cast<int>(kPowers.size()))
    throw Error(fmt::format("generated starts have 1 to {} elements, not {}", kPowers.size(), n));
  const double f = focal_length_mm;
  const double scale = f / 17.156;
  const Glass& crown = nearest_glass(catalog, kCrownNd, kCrownVd);
  const Glass& flint = nearest_glass(catalog, kFlintNd, kFlintVd);
  LensForm form;
  form.layout = default_layout(n);
  for (int i = 0; i < n; ++i) {
    const double phi = kPowers[n - 1][i] / f;  // 1/mm
    ElementForm e;
    e.glass = Material::from_catalog(phi > 0 ? crown : flint);
    // Equi-convex / equi-concave: c_front = -c_rear = phi / (2 (nd - 1)).
    const double c = phi / (2.0 * (e.glass.nd - 1.0));
    e.front_curvature_per_mm = c;
    e.rear_curvature_per_mm = -c;
    e.thickness_mm = (phi > 0 ? kPositiveThicknessMm : kNegativeThicknessMm) * scale;
    form.elements.push_back(e);
  }
  for (int i = 0; i + 1 < n; ++i)
    form.gap_mm.push_back((form.layout.stop_gap == i + 1 ? kGeneratedStopGapMm : kGeneratedAirMm) *
                          scale);
  form.front_stop_mm = kFrontStopFraction * f;
  form.rear_stop_mm = kRearStopFraction * f;
  form.image_mm = f;  // replaced by the paraxial focus when the lens is built
  form.focal_length_mm = f;
  return with_layout(form, layout);
}

void seed_glasses(LensForm& form, int seed, const Catalog& catalog) {
  if (seed <= 0) return;
  std::vector<const Glass*> usable;
  for (const Glass& g : catalog.glasses)
    if (g.nd > 1.0 && g.vd > 0.0) usable.push_back(&g);
  if (usable.empty()) throw Error(fmt::format("catalog {} has no usable glass", catalog.name));
  std::vector<double> vds;
  for (const Glass* g : usable) vds.push_back(g->vd);
  std::sort(vds.begin(), vds.end());
  const double median_vd = vds[vds.size() / 2];
  std::vector<const Glass*> crowns, flints;
  for (const Glass* g : usable) (g->vd >= median_vd ? crowns : flints).push_back(g);
  if (flints.empty()) flints = crowns;
  for (std::size_t e = 0; e < form.elements.size(); ++e) {
    ElementForm& element = form.elements[e];
    const auto& pool = is_positive(element) ? crowns : flints;
    const uint64_t h = splitmix64(splitmix64(static_cast<uint64_t>(seed)) ^ (e + 1));
    element.glass = Material::from_catalog(*pool[h % pool.size()]);
  }
}

namespace detail {

double rebuilt_image_mm(const Lens& rebuilt, double old_defocus_mm) {
  const TraceLens<double> tl = make_trace_lens(rebuilt);
  const ParaxialData<double> par = paraxial_data(tl, tl.reference_nm());
  return std::isfinite(par.bfl_mm) ? image_distance_for_defocus_mm(par, old_defocus_mm)
                                   : rebuilt.surfaces.back().thickness_mm;
}

double lens_defocus_mm(const Lens& lens) {
  const TraceLens<double> tl = make_trace_lens(lens);
  const ParaxialData<double> par = paraxial_data(tl, tl.reference_nm());
  return std::isfinite(par.bfl_mm) ? paraxial_defocus_mm(tl, par) : 0.0;
}

}  // namespace detail

}  // namespace lensopt
