// Glass elements split by a dummy surface. A surface with the same glass on both sides (a stop
// or dummy surface inside an element, e.g. the flat stop the .zmx reader inserts at the vertex
// of a curved stop surface, zmx_read.cpp) refracts nothing: the spaces on either side of it are
// one element, and the optimizer's glass bounds (ray travel in [min_glass_mm, max_glass_mm],
// the edge thickness at the clear aperture) hold on the element's summed thickness. A part of
// such an element is only held to a travel >= 0 (a stop at the vertex of a curved face has 0 on
// axis), and a dummy 0 mm before the next surface keeps its 0 mm (optimizer.cpp).
#pragma once

#include <vector>

#include "lensopt/lens/lens.h"

namespace lensopt {

// True when a and b are the same glass (a surface between them refracts nothing).
inline bool same_glass(const Material& a, const Material& b) {
  return !a.is_air() && a.kind == b.kind && a.glass_name == b.glass_name && a.nd == b.nd &&
         a.vd == b.vd && a.model_glass == b.model_glass && a.dpgf == b.dpgf;
}

// For each space k of `lens` (after surface k; the last is the image space): the first space of
// the element it belongs to: k itself, or for a glass space after a dummy surface k (same glass
// before and after it, neither a mirror) the first space of the element before it.
inline std::vector<int> element_first_spaces(const Lens& lens) {
  const int k_count = static_cast<int>(lens.surfaces.size());
  std::vector<int> first(k_count);
  for (int k = 0; k < k_count; ++k) {
    const Surface& s = lens.surfaces[k];
    const bool continues = k > 0 && k + 1 < k_count && !s.mirror && !lens.surfaces[k - 1].mirror &&
                           same_glass(lens.surfaces[k - 1].material, s.material);
    first[k] = continues ? first[k - 1] : k;
  }
  return first;
}

// True when space k (after surface k) is a flat stop 0 mm before the next surface, in air: the
// stop on that surface's vertex (the flat stop the .zmx reader inserts at a curved stop surface
// that begins an element). Its rays travel from the stop plane to the surface's sag, negative
// before a concave face: no air gap, so no air bound applies to it, and its 0 mm is held
// (optimizer.cpp).
inline bool stop_at_vertex_space(const Lens& lens, int k) {
  const Surface& s = lens.surfaces[k];
  return k + 1 < static_cast<int>(lens.surfaces.size()) && s.is_stop && s.material.is_air() &&
         s.thickness_mm == 0.0;
}

// True when space k carries its element's bound (the last space of its element).
inline bool element_last_space(const std::vector<int>& first, int k) {
  return k + 1 >= static_cast<int>(first.size()) || first[k + 1] != first[k];
}

}  // namespace lensopt
