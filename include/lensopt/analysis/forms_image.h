// Whether an analysis report describes a lens that forms an image.
#pragma once

#include "lensopt/analysis/analyze.h"

namespace lensopt {

// Throws Error (file: "the lens does not form an image: ...") if the report has no field, a
// focal length, pupil or scale that is not finite (or zero), a field no ray reaches, or a
// non-finite spot, distortion or illumination. `lensopt analyze` calls it after analyze_lens.
void check_forms_image(const AnalysisReport& report);

}  // namespace lensopt
