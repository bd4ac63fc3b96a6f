// prepare_system and start_rays on double (the system setup of every double trace: paraxial
// solves, stop radius, ray aiming, field solves; the pupil rays), declared extern in
// trace/system.h, so that they are compiled here once instead of in each object that prepares a
// system (as the Jet widths, src/trace/system_jet.cpp.in).
#include "lensopt/trace/system.h"

namespace lensopt {

template TraceSystem<double> prepare_system<double>(const TraceLens<double>&, const SystemSetup&,
                                                    const TraceOptions&);
template void start_rays<double>(const TraceSystem<double>&, int, int, RayBundle<double>&,
                                 const PupilSamples*);

}  // namespace lensopt
