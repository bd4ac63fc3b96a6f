// prepare_system on double (the system setup of every double trace: paraxial solves, stop radius,
// ray aiming, field solves), declared extern in trace/system.h, so that it is compiled here once
// instead of in each object that prepares a system (as the Jet widths,
// src/trace/system_jet.cpp.in). Not start_rays: its ray loop inlined into a caller's field loop
// is faster (tolerance's Monte-Carlo trial: 6 % more CPU with it out of line).
#include "lensopt/trace/system.h"

namespace lensopt {

template TraceSystem<double> prepare_system<double>(const TraceLens<double>&, const SystemSetup&,
                                                    const TraceOptions&);

}  // namespace lensopt
