// Uses the installed lensopt: builds a Cooke-like triplet in memory, traces it paraxially and
// prints its EFL, which run.sh compares with the value lensopt's own analysis reports.
#include <cstdio>

#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"

int main() {
  using namespace lensopt;
  Lens lens;
  lens.name = "package test";
  // A thin-ish biconvex singlet, n = 1.5168 (N-BK7), R = +-50 mm, 4 mm thick, stop in front.
  Surface stop;
  stop.is_stop = true;
  stop.thickness_mm = 2.0;
  Surface front;
  front.curvature_per_mm = 1.0 / 50.0;
  front.thickness_mm = 4.0;
  front.material = Material::model(1.5168, 64.17);
  Surface rear;
  rear.curvature_per_mm = -1.0 / 50.0;
  rear.thickness_mm = 47.0;
  lens.surfaces = {stop, front, rear};
  lens.specs.wavelengths_nm = {587.56};
  lens.specs.wavelength_channels = {1};
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  const ParaxialData<double> par = paraxial_data(trace_lens, trace_lens.reference_nm());
  std::printf("%.6f\n", par.efl_mm);
  return par.efl_mm > 0.0 ? 0 : 1;
}
