// How the design loss (optimize/design_loss.h: optimize, joint, search) samples a lens: the one
// traced system of an evaluation, which of its fields carry the spot (the merit) and which only
// the constraint rays.
//   Paper mode (SpecMode::kPaper: the paper's lenses and its YAML): angles 0..hfov; the
//     `sampling.fields` spot fields are every stride-th of constraint_field_count(sampling.fields,
//     kConstraintFields) constraint fields (design_loss.h); EPD = f / N, object at infinity, equal
//     field weights.
//   As written (SpecMode::kAsWritten: a .zmx import, a TOML with [system]): the spot fields are
//     the lens's written fields (field type, weights, vignetting factors), with its aperture and
//     object distance; the constraint rays run at those fields and at kConstraintFields values
//     spread evenly from 0 to the largest written field (the same field type), merged in order.
//     A lens without written fields samples 0..hfov as the paper does, with its own aperture.
// The wavelengths and their weights are the lens's in both modes; no scaling (the
// parameterization's forward map gives the spec focal length itself).
#pragma once

#include <string>
#include <vector>

#include "lensopt/lens/lens.h"
#include "lensopt/trace/system.h"

namespace lensopt {

struct DesignSampling {
  SystemSetup setup;            // the traced system's fields, aperture, object (no scaling)
  std::vector<int> spot_field;  // per system field: its spot-field index, or -1
  int spot_fields = 0;          // F: the fields that carry the spot
};

// The design loss's sampling of `structure` (its specs and spec mode) with `sampling`'s fields
// (paper mode) and pupil.
DesignSampling design_sampling(const Lens& structure, const TraceOptions& sampling);

// One line naming the sampling: "design sampling (as written): wavelengths 486.1327, 587.5618,
// 656.2725 nm (weights 1, 1, 1); spot fields 0, 14, 20 deg (weights 1, 1, 1) among 23 traced".
std::string describe_design_sampling(const Lens& structure, const TraceOptions& sampling);

}  // namespace lensopt
