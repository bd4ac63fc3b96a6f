// compute_wavefront on double, declared extern in analysis/wavefront.h, so that it is compiled
// here once instead of in each object that measures a wavefront.
#include "lensopt/analysis/wavefront.h"

namespace lensopt {

template Wavefront<double> compute_wavefront<double>(const TraceSystem<double>&, int, int,
                                                     const PupilGrid&,
                                                     const ReferenceSphere<double>&, double,
                                                     RayBundle<double>&, RayRecord<double>&);

}  // namespace lensopt
