// The optics of one prepare(x) (joint/imaging.h, src/joint/imaging_detail.h). The variables x
// are seeded as Jets of width N >= param.size() (the narrowest of 8, 12, 16, 24, 32,
// core/jet_width.h), so one traced system carries dP_h/dx, dR_h/dx, dy_ref,h/dx and
// dybar_h/dx; they are stored as values plus derivative rows (for a PSF only the bins inside its
// support box); no Jet outlives prepare(). Without derivatives the same code runs in double.
#include <fmt/format.h>
#include <omp.h>

#include <type_traits>

#include "imaging_detail.h"
#include "lensopt/analysis/field_optics.h"
#include "lensopt/core/error.h"
#include "lensopt/core/jet_width.h"
#include "lensopt/core/threads.h"

namespace lensopt::imaging_detail {
namespace {

// The value and derivative parts of a double (no derivatives) or a Jet.
inline double value_part(double v) {
  return v;
}
template <int N>
double value_part(const ceres::Jet<double, N>& v) {
  return v.a;
}
inline void derivative_part(double, int, double*) {}
template <int N>
void derivative_part(const ceres::Jet<double, N>& v, int n, double* out) {
  for (int j = 0; j < n; ++j) out[j] = v.v[j];
}
inline double seed_variable(double x, int, double*) {
  return x;
}
template <int N>
ceres::Jet<double, N> seed_variable(double x, int j, ceres::Jet<double, N>*) {
  return ceres::Jet<double, N>(x, j);
}

// J = double samples the values only (o.derivatives = 0), a Jet also the derivatives.
template <typename J>
Optics sample_optics_as(const LensParameterization& param, GlassMode mode,
                        const std::vector<int>& fixed_glasses,
                        const DifferentiableImagingOptions& options, const std::vector<double>& x,
                        ImagingTimings& timings) {
  constexpr bool kJets = !std::is_same_v<J, double>;
  const int n = kJets ? param.size() : 0;  // derivatives stored per value
  Specs specs = param.structure().specs;
  specs.mode = SpecMode::kPaper;  // the paper's sampling in every spec mode
  auto start = Clock::now();
  std::vector<J> xj(x.size());
  for (std::size_t j = 0; j < x.size(); ++j)
    xj[j] = seed_variable(x[j], static_cast<int>(j), static_cast<J*>(nullptr));
  const TraceLens<J> lens = param.to_trace_lens(xj.data(), mode, fixed_glasses);
  const TraceSystem<J> sys = prepare_system(lens, specs, options.sampling);
  const int trace_threads =
      options.sampling.threads > 0 ? options.sampling.threads : options.threads;
  // One trace for the field maps and the PSFs (analysis/field_optics.h): the centroid that
  // centres each PSF is the one the distortion is measured with, as in `lensopt render`.
  FieldOpticsOptions field_options;
  field_options.threads = trace_threads;
  PsfRayCollector<J> rays(sys);
  const FieldOptics<J> measured = measure_fields(sys, field_options, rays);
  const std::vector<J>& y_ref = measured.reference_y_mm;
  const std::vector<J>& ri = measured.relative_illumination;
  timings.trace_s = seconds_since(start);

  start = Clock::now();
  const PsfSet<J> psfs = psfs_from_rays(sys, measured.spots, rays, specs.wavelength_channels,
                                        options.psf, trace_threads);
  Optics o;
  o.variables = n;  // 0: values only
  o.fields_deg = sys.fields_deg;
  const int fields = static_cast<int>(sys.fields_deg.size());
  auto store = [n](const J& v, std::vector<double>& values, std::vector<double>& derivatives) {
    values.push_back(value_part(v));
    derivatives.resize(derivatives.size() + n);
    derivative_part(v, n, derivatives.data() + derivatives.size() - n);
  };
  for (int h = 0; h < fields; ++h) {
    store(y_ref[h], o.reference_y_mm, o.d_reference);
    store(psfs.fields[h].centroid_y_mm, o.centroid_y_mm, o.d_centroid);
    store(ri[h], o.illumination, o.d_illumination);
  }
  o.psf.resize(fields);
  o.d_psf.resize(fields);
  o.support.resize(fields);
  for (int h = 0; h < fields; ++h) o.support[h] = psfs.fields[h].support;
  const int g = options.psf.grid_size;
  const std::size_t cells = static_cast<std::size_t>(options.psf.grid_size) * options.psf.grid_size;
#pragma omp parallel for collapse(2) num_threads(thread_count(options.threads))
  for (int h = 0; h < fields; ++h) {
    for (int c = 0; c < kColourChannels; ++c) {
      const std::vector<J>& grid = psfs.fields[h].psf[c];
      const std::array<int, 4>& box = o.support[h][c];
      std::vector<double>& values = o.psf[h][c];
      std::vector<double>& derivatives = o.d_psf[h][c];
      values.assign(cells, 0.0);
      derivatives.resize(static_cast<std::size_t>(box[1] - box[0]) * (box[3] - box[2]) * n);
      double* d = derivatives.data();
      for (int r = box[0]; r < box[1]; ++r) {
        for (int i = box[2]; i < box[3]; ++i, d += n) {
          const J& v = grid[static_cast<std::size_t>(r) * g + i];
          values[static_cast<std::size_t>(r) * g + i] = value_part(v);
          derivative_part(v, n, d);
        }
      }
    }
  }
  for (int h = 0; h < fields; ++h) {
    const FieldPsf<J>& f = psfs.fields[h];
    o.ray_failures += f.failed_rays;
    if (f.traced_rays[0] + f.traced_rays[1] + f.traced_rays[2] == 0) {
      throw Error(fmt::format("cannot render: no ray of field {:.2f} deg reaches the image",
                              sys.fields_deg[h]));
    }
  }
  timings.psf_s = seconds_since(start);
  return o;
}

}  // namespace

Optics sample_optics(const LensParameterization& param, GlassMode mode,
                     const std::vector<int>& fixed_glasses,
                     const DifferentiableImagingOptions& options, const std::vector<double>& x,
                     bool derivatives, ImagingTimings& timings) {
  if (!derivatives)
    return sample_optics_as<double>(param, mode, fixed_glasses, options, x, timings);
  constexpr int kCap = kJetWidthCap;
  const int n = param.size();
  if (n > kCap)
    throw Error(
        fmt::format("joint imaging supports up to {} lens variables, the lens has {}", kCap, n));
  return with_jet_width(n, [&](auto width) {
    return sample_optics_as<ceres::Jet<double, decltype(width)::value>>(param, mode, fixed_glasses,
                                                                        options, x, timings);
  });
}

}  // namespace lensopt::imaging_detail
