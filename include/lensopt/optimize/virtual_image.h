// A diverging lens in the optimizer (issue 31, item 3): its image is virtual, before the last
// surface, and its merit (RMS spot, wavefront, design targets) is measured there, as OpticStudio
// measures a negative lens's spot: the last thickness is negative (the paraxial image solve puts
// the plane at BFL + defocus, BFL < 0) and the rays are traced back to the plane along their
// lines (trace/kernel.h). The variables are normalized by |f| with the last curvature solved for
// EFL = -|f| (optimize/variables.h); efl_mm targets of the lens's own sign scale it.
//
// The image-space bound of a virtual image (DesignLossOptions::min/max_virtual_image_mm): every
// ray's image-space travel dz is negative, and the distance -dz is held within bounds derived
// from the start at full sampling (analysis sampling, every ray that traces):
//   d_near = -max dz, d_far = -min dz over the start's rays,
//   min_virtual_image_mm = 0.5 d_near (0 when a ray reaches the plane forwards),
//   max_virtual_image_mm = 2 d_far,
// so the image stays virtual and within twice the start's back distance (a thin negative
// lens's |BFL| is about |f|; a bending that would push the principal planes out by more than
// that is no longer the lens that was asked for).
#pragma once

#include <string>

#include "lensopt/lens/lens.h"
#include "lensopt/optimize/design_loss.h"

namespace lensopt {

// `loss` with the virtual-image bounds of the header derived from `start` when the start has a
// virtual image and `loss` has none yet; else `loss` unchanged. `why` (may be null) receives the
// line the optimizer logs ("image: virtual, ...").
DesignLossOptions with_virtual_image_bounds(const Lens& start, DesignLossOptions loss,
                                            std::string* why = nullptr);

}  // namespace lensopt
